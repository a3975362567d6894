//! Every file a command writes goes through here: outputs are checked
//! before any work (an existing file is kept unless `--force`, a missing
//! folder is named), and written as `.NAME.partial` then renamed, so a
//! reader never sees half a file.

use anyhow::{bail, Context, Result};
use std::path::Path;

/// Refuse to replace `out` without `force`, and name a missing output folder,
/// before any work is done.
pub fn check(out: &Path, force: bool) -> Result<()> {
    if out.exists() && !force {
        bail!(
            "{}: already exists (pass --force to replace it)",
            out.display()
        );
    }
    check_folder(out)
}

/// Name a missing output folder before any work is done.
pub fn check_folder(out: &Path) -> Result<()> {
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !parent.is_dir() {
        bail!(
            "{}: cannot write, folder {} does not exist",
            out.display(),
            parent.display()
        );
    }
    Ok(())
}

/// Write `bytes` to `path` through a partial file renamed into place.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    Ok(relevo_core::atomic::write_file(path, bytes)?)
}

/// The one atomic write: `write` fills a partial file beside `path`
/// (`.NAME.partial`, with `extension` added when a format needs its own,
/// e.g. `gpkg`), which is renamed onto `path` when complete and removed
/// on any failure, so `path` only ever holds a whole file.
pub fn write_through_partial(
    path: &Path,
    extension: &str,
    write: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    let mut partial = relevo_core::atomic::partial_path(path);
    if !extension.is_empty() {
        partial.set_extension(extension);
    }
    let _ = std::fs::remove_file(&partial);
    let result = write(&partial).and_then(|()| {
        std::fs::rename(&partial, path)
            .with_context(|| format!("{}: cannot move into place", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&partial);
    }
    result
}
