//! Every file a command writes goes through here: outputs are checked
//! before any work (an existing file is kept unless `--force`, a missing
//! folder is named, two outputs on one path are refused), and written as `.NAME.partial` then renamed, so a
//! reader never sees half a file.

use anyhow::{Context, Result};
use std::path::Path;

/// Refuse, before any work, outputs that cannot all be written: an existing
/// file without `force`, a missing folder, two outputs on one path
/// (relevo-core's check, which the viewer uses too).
pub fn check(outputs: &[&Path], force: bool) -> Result<()> {
    Ok(relevo_core::atomic::check_outputs(outputs, force)?)
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
