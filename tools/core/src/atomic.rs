//! Whole files or nothing: every file Relevo writes outside a bundle goes
//! to a partial file beside its path (`.NAME.partial`) that is renamed onto
//! the path only when complete, so a reader never sees half a file. Before
//! any work, [`check_outputs`] refuses outputs that would replace a file
//! unasked, land in a missing folder, or overwrite each other.

use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Refuse, before any work, the outputs of one command that cannot all be
/// written: an existing file without `force`, a folder that does not exist,
/// or two outputs on one path (the second would silently replace the
/// first). Both binaries check their outputs here, in the same words.
///
/// ```
/// use relevo_core::atomic::check_outputs;
/// use std::path::Path;
/// let dir = std::env::temp_dir();
/// let (a, b) = (dir.join("relevo-doc-a.png"), dir.join("relevo-doc-b.f32"));
/// assert!(check_outputs(&[&a, &b], false).is_ok());
/// assert!(check_outputs(&[&a, &a], true).unwrap_err().to_string().contains("twice"));
/// assert!(check_outputs(&[Path::new("/no/such/dir/x.png")], true).is_err());
/// ```
pub fn check_outputs(outputs: &[&Path], force: bool) -> Result<()> {
    for (k, out) in outputs.iter().enumerate() {
        if outputs[..k].iter().any(|earlier| same_path(earlier, out)) {
            return Err(Error::invalid(
                out,
                "named twice as an output (each output needs its own path)",
            ));
        }
        if out.exists() && !force {
            return Err(Error::invalid(
                out,
                "already exists (pass --force to replace it)",
            ));
        }
        let parent = out
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        if !parent.is_dir() {
            return Err(Error::invalid(
                out,
                format!("cannot write, folder {} does not exist", parent.display()),
            ));
        }
    }
    Ok(())
}

/// Do two output paths name one file (also through `.` or a link to an
/// existing folder)?
fn same_path(a: &Path, b: &Path) -> bool {
    let resolved = |p: &Path| {
        let name = p.file_name().map(|n| n.to_os_string());
        let parent = p
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        (
            parent
                .canonicalize()
                .unwrap_or_else(|_| parent.to_path_buf()),
            name,
        )
    };
    a == b || resolved(a) == resolved(b)
}

/// Rename `from` onto `to` only if nothing is at `to`: a folder or file that
/// appeared there meanwhile is never replaced (`renameat2` with
/// `RENAME_NOREPLACE`; where the file system lacks it, a check just before
/// an ordinary rename, which a folder that appears in between can still
/// lose only if it is empty).
pub fn rename_no_replace(from: &Path, to: &Path) -> std::io::Result<()> {
    match renameat2(from, to, libc::RENAME_NOREPLACE) {
        Err(e) if unsupported(&e) => {
            if to.symlink_metadata().is_ok() {
                return Err(std::io::ErrorKind::AlreadyExists.into());
            }
            std::fs::rename(from, to)
        }
        done => done,
    }
}

/// Swap `a` and `b` in one step (`renameat2` with `RENAME_EXCHANGE`), so
/// neither path is ever missing. Returns `Ok(false)` where the file system
/// cannot exchange, leaving both untouched.
pub fn exchange(a: &Path, b: &Path) -> std::io::Result<bool> {
    match renameat2(a, b, libc::RENAME_EXCHANGE) {
        Ok(()) => Ok(true),
        Err(e) if unsupported(&e) => Ok(false),
        Err(e) => Err(e),
    }
}

/// Does an error mean the kernel or file system lacks a `renameat2` flag?
fn unsupported(e: &std::io::Error) -> bool {
    matches!(
        e.raw_os_error(),
        Some(libc::EINVAL | libc::ENOSYS | libc::ENOTSUP)
    )
}

fn renameat2(from: &Path, to: &Path, flags: libc::c_uint) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| {
        std::ffi::CString::new(p.as_os_str().as_bytes())
            .map_err(|_| std::io::Error::from(std::io::ErrorKind::InvalidInput))
    };
    let (from, to) = (c(from)?, c(to)?);
    // SAFETY: both arguments are NUL-terminated strings that live across
    // the call; AT_FDCWD resolves relative paths as `rename` does.
    let rc = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            from.as_ptr(),
            libc::AT_FDCWD,
            to.as_ptr(),
            flags,
        )
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

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
/// its texture; an image and its depth): all first, then all renamed;
/// when one cannot be written, none of them is left, partial or whole.
pub fn write_files(files: &[(&Path, &[u8])]) -> Result<()> {
    let mut outputs = Outputs::default();
    for &(path, bytes) in files {
        let pending = outputs.pending(path);
        std::fs::write(&pending, bytes)
            .map_err(|e| Error::invalid(path, format!("cannot write ({e})")))?;
    }
    outputs.commit()
}

/// The outputs of one command, made whole before any appears: each is
/// written at a hidden pending path beside it (keeping its extension, for
/// writers that choose a format by it) and all are renamed into place by
/// [`Outputs::commit`]. Dropped before that — an error on the way — it
/// removes every pending file, so a command leaves all its outputs or
/// none.
#[derive(Debug, Default)]
pub struct Outputs {
    /// (pending path, final path), in the order asked for.
    pending: Vec<(PathBuf, PathBuf)>,
}

impl Outputs {
    /// Where to write `path` until commit: `DIR/.STEM.pending.EXT`.
    pub fn pending(&mut self, path: &Path) -> PathBuf {
        let stem = path
            .file_stem()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let name = match path.extension() {
            Some(ext) => format!(".{stem}.pending.{}", ext.to_string_lossy()),
            None => format!(".{stem}.pending"),
        };
        let pending = path.with_file_name(name);
        self.pending.push((pending.clone(), path.to_path_buf()));
        pending
    }

    /// Rename every pending file onto its path.
    pub fn commit(mut self) -> Result<()> {
        for (pending, path) in std::mem::take(&mut self.pending) {
            std::fs::rename(&pending, &path)
                .map_err(|e| Error::invalid(&path, format!("cannot write ({e})")))?;
        }
        Ok(())
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        for (pending, _) in &self.pending {
            let _ = std::fs::remove_file(pending);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rename_never_replaces_what_appeared_and_an_exchange_swaps() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        std::fs::create_dir(&a).unwrap();
        std::fs::write(a.join("new"), b"1").unwrap();
        std::fs::create_dir(&b).unwrap(); // empty: rename(2) would replace it
        let refused = rename_no_replace(&a, &b).unwrap_err();
        assert_eq!(refused.kind(), std::io::ErrorKind::AlreadyExists);
        assert!(a.join("new").exists() && b.is_dir());
        if exchange(&a, &b).unwrap() {
            assert!(b.join("new").exists() && !a.join("new").exists());
        }
        std::fs::remove_dir(&a).unwrap();
        rename_no_replace(&b, &a).unwrap();
        assert!(a.join("new").exists());
    }

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
