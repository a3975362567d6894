//! Where the test inputs are: this repository and the shared real-data
//! folder beside it (or `$RELEVO_SHARED_DATA`). One file, included by the
//! end-to-end tests here and the process-level tests beside the binary.

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

/// The real inputs (DEMs, imagery, tiles) shipped beside the repository.
pub fn shared(rel: &str) -> PathBuf {
    let root = std::env::var_os("RELEVO_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join("../shared/data"));
    let path = root.join(rel);
    assert!(
        path.exists(),
        "{} is missing: set RELEVO_SHARED_DATA to the shared data folder",
        path.display()
    );
    path
}
