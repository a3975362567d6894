//! Whole files or nothing: every file Relevo writes outside a bundle goes
//! to a partial file beside its path (`.NAME.partial`) that is renamed onto
//! the path only when complete, so a reader never sees half a file.

use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// `DIR/.NAME.partial` beside `path`.
pub fn partial_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.partial"))
}

/// Write `bytes` to `path` through a partial file renamed into place.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    let partial = partial_path(path);
    let written = std::fs::write(&partial, bytes)
        .and_then(|()| std::fs::rename(&partial, path))
        .map_err(|e| Error::invalid(path, format!("cannot write ({e})")));
    if written.is_err() {
        let _ = std::fs::remove_file(&partial);
    }
    written
}

/// Write several files that belong together (a mesh, its material and
/// its texture): all partial files first, then all renamed; when one
/// cannot be written, none of them is left, partial or whole.
pub fn write_files(files: &[(&Path, &[u8])]) -> Result<()> {
    let mut written = Vec::new();
    for &(path, bytes) in files {
        let partial = partial_path(path);
        if let Err(e) = std::fs::write(&partial, bytes) {
            let _ = std::fs::remove_file(&partial);
            for p in &written {
                let _ = std::fs::remove_file(p);
            }
            return Err(Error::invalid(path, format!("cannot write ({e})")));
        }
        written.push(partial);
    }
    for (&(path, _), partial) in files.iter().zip(&written) {
        std::fs::rename(partial, path)
            .map_err(|e| Error::invalid(path, format!("cannot write ({e})")))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_appear_whole_and_failures_leave_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("shot.png");
        write_file(&path, b"one").unwrap();
        write_file(&path, b"two").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        let missing = dir.path().join("no/such/folder/x.png");
        let message = write_file(&missing, b"x").unwrap_err().to_string();
        assert!(
            message.contains("x.png") && message.contains("cannot write"),
            "{message}"
        );
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "only the finished file remains");
    }

    #[test]
    fn files_that_belong_together_appear_together_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let (obj, mtl) = (dir.path().join("m.obj"), dir.path().join("m.mtl"));
        write_files(&[(&obj, b"o"), (&mtl, b"m")]).unwrap();
        assert_eq!(std::fs::read(&mtl).unwrap(), b"m");
        let missing = dir.path().join("no/such/m.png");
        let message = write_files(&[(&obj, b"o2"), (&missing, b"p")])
            .unwrap_err()
            .to_string();
        assert!(message.contains("m.png"), "{message}");
        // The first file was not replaced, and no partial file is left.
        assert_eq!(std::fs::read(&obj).unwrap(), b"o");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }
}
