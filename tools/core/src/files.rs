//! Reading the user's files: only regular files are read. A FIFO would
//! block a reader for good, a device could stream without end, and a
//! socket or folder is not data, so each is refused by name. Files are
//! opened without blocking and checked on the open handle, so nothing
//! swapped in between a check and the open is read either. A whole-file
//! read goes through the memory budget first.

use crate::{memory, Error, Result};
use std::fs::{File, OpenOptions};
use std::io::Read;
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::Path;

/// Open `path` for reading when it is a regular file (a symbolic link to
/// one counts); anything else is refused naming what it is.
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let error = relevo_core::files::open_regular(dir.path()).unwrap_err();
/// assert!(error.to_string().contains("is a folder, not a regular file"));
/// ```
pub fn open_regular(path: &Path) -> Result<File> {
    // O_NONBLOCK: opening a FIFO with no writer returns at once instead of
    // waiting; regular files ignore the flag.
    let file = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| Error::io(path, e))?;
    let kind = file.metadata().map_err(|e| Error::io(path, e))?.file_type();
    let what = if kind.is_file() {
        return Ok(file);
    } else if kind.is_dir() {
        "a folder"
    } else if kind.is_fifo() {
        "a FIFO (named pipe)"
    } else if kind.is_socket() {
        "a socket"
    } else if kind.is_char_device() || kind.is_block_device() {
        "a device"
    } else {
        "not a file"
    };
    Err(Error::invalid(
        path,
        format!("is {what}, not a regular file; Relevo reads only regular files"),
    ))
}

/// The bytes of the regular file `path`, its size checked against the
/// memory budget before it is read.
pub fn read(path: &Path) -> Result<Vec<u8>> {
    let mut file = open_regular(path)?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    memory::check(
        &format!("reading {}", path.display()),
        len,
        1,
        "use a smaller file",
    )?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// The text of the regular file `path` (UTF-8), as [`read`] reads it,
/// without the byte-order mark some editors and spreadsheets put first.
pub fn read_to_string(path: &Path) -> Result<String> {
    let text = String::from_utf8(read(path)?)
        .map_err(|e| Error::invalid(path, format!("is not UTF-8 text ({e})")))?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fifos_devices_and_folders_are_refused_at_once_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("height.f32");
        let c_path = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path; mkfifo only creates a node.
        assert_eq!(unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) }, 0);
        let message = read(&fifo).unwrap_err().to_string();
        assert!(
            message.contains("height.f32") && message.contains("FIFO"),
            "{message}"
        );
        let message = read(Path::new("/dev/zero")).unwrap_err().to_string();
        assert!(message.contains("/dev/zero: is a device"), "{message}");
        assert!(read_to_string(dir.path()).is_err());

        let text = dir.path().join("a.txt");
        std::fs::write(&text, "fine").unwrap();
        assert_eq!(read_to_string(&text).unwrap(), "fine");
        std::fs::write(&text, "\u{feff}xmin,ymin").unwrap();
        assert_eq!(read_to_string(&text).unwrap(), "xmin,ymin");
        std::fs::write(&text, [0xff, 0xfe]).unwrap();
        assert!(read_to_string(&text)
            .unwrap_err()
            .to_string()
            .contains("not UTF-8"));
    }
}
