//! An OBJ model (with whatever material library it names) loaded as the
//! cluster bake and the placement do.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relevo_core::cluster::model::Model;
use std::path::PathBuf;
use std::sync::OnceLock;

fn folder() -> &'static PathBuf {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let path = dir.path().to_path_buf();
        (dir, path)
    })
    .1
}

fuzz_target!(|data: &[u8]| {
    let path = folder().join("model.obj");
    if std::fs::write(&path, data).is_err() {
        return;
    }
    if let Ok(model) = Model::load_obj(&path) {
        let _ = model.bounds();
    }
});
