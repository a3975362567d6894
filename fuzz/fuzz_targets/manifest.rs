//! A bundle whose `manifest.json` is the fuzzer's input, beside the real
//! arrays of a small terrain bundle: opening it and reading every artifact
//! must end in a value or an error, never a panic or an abort.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relevo_core::bundle::{write_terrain_bundle, Bundle, BundleFiles, Crs};
use relevo_core::cluster::store;
use relevo_core::geo::GeoTransform;
use relevo_core::grid::HeightGrid;
use relevo_core::validation::validate;
use std::path::PathBuf;
use std::sync::OnceLock;

/// A 17×17 terrain bundle (once per process) whose manifest each input replaces.
fn bundle() -> &'static PathBuf {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let side = 17;
        let grid = HeightGrid {
            side,
            heights: (0..side * side).map(|i| ((i * 7919) % 97) as f32).collect(),
            mask: vec![1; side * side],
            geotransform: GeoTransform::north_up(0.0, 480.0, 30.0, 30.0),
        };
        let target = dir.path().join("fuzz.relevo");
        let crs = Crs {
            wkt: String::new(),
            epsg: None,
        };
        write_terrain_bundle(&target, "fuzz", &grid, 30.0, crs, false).expect("a bundle");
        (dir, target)
    })
    .1
}

fuzz_target!(|data: &[u8]| {
    let dir = bundle();
    if std::fs::write(dir.join("manifest.json"), data).is_err() {
        return;
    }
    let Ok(bundle) = Bundle::open(dir) else {
        return;
    };
    let _ = bundle.frame();
    let _ = bundle.heights();
    let _ = bundle.mask();
    if let Ok(lp) = bundle.lp() {
        let _ = lp.hierarchy();
    }
    let _ = bundle.drape();
    let _ = bundle.vegetation();
    let _ = store::read(&bundle);
    let _ = validate(&bundle);
});
