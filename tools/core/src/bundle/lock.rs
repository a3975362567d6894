//! One writer at a time: every command that writes or rewrites a bundle
//! holds [`BundleLock`] on it, an exclusive advisory lock (`flock`) on the
//! file `NAME.relevo.lock` beside the bundle. A second writer is refused at
//! once with the holder's pid, command line and start time, which the
//! holder writes into the lock file.
//!
//! The lock file is removed when the lock is released. So that a writer
//! never holds a lock on a file another writer has just removed, a lock is
//! only taken once the locked file is still the one at the path (same
//! device and inode); otherwise the attempt starts again.

use crate::{Error, Result};
use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// An exclusive lock on one bundle path, held until dropped.
#[derive(Debug)]
pub struct BundleLock {
    bundle: PathBuf,
    path: PathBuf,
    file: File,
}

/// Attempts before giving up when the lock file keeps being replaced under
/// us (each one means another writer released or took it meanwhile).
const ATTEMPTS: usize = 100;

impl BundleLock {
    /// Lock `bundle` (which need not exist yet) for writing, or refuse with
    /// who holds it. `bundle`'s folder must exist.
    pub fn acquire(bundle: &Path) -> Result<BundleLock> {
        let path = lock_path(bundle);
        for _ in 0..ATTEMPTS {
            let mut file = OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(|e| Error::invalid(bundle, format!("cannot write ({e})")))?;
            match file.try_lock() {
                Ok(()) => {}
                Err(TryLockError::WouldBlock) => {
                    let mut holder = String::new();
                    let _ = file.read_to_string(&mut holder);
                    return Err(Error::invalid(
                        bundle,
                        format!(
                            "is being written by another command ({}); \
                             wait for it to finish and run this one again",
                            describe_holder(&holder)
                        ),
                    ));
                }
                Err(TryLockError::Error(e)) => return Err(Error::io(&path, e)),
            }
            let (held, at_path) = (file.metadata(), path.metadata());
            let same = matches!((&held, &at_path),
                (Ok(h), Ok(p)) if h.dev() == p.dev() && h.ino() == p.ino());
            if !same {
                continue; // released and removed by its holder meanwhile
            }
            let record = holder_record();
            file.set_len(0)
                .and_then(|()| file.rewind())
                .and_then(|()| file.write_all(record.as_bytes()))
                .map_err(|e| Error::io(&path, e))?;
            return Ok(BundleLock {
                bundle: bundle.to_path_buf(),
                path,
                file,
            });
        }
        Err(Error::invalid(
            bundle,
            "its lock file kept being replaced by other writers; try again",
        ))
    }

    /// The bundle path this lock is for.
    pub fn bundle(&self) -> &Path {
        &self.bundle
    }
}

impl Drop for BundleLock {
    /// Remove the lock file while still holding it, then release it: a
    /// writer waiting on the removed file finds it gone and starts again.
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
        let _ = self.file.unlock();
    }
}

/// `NAME.relevo.lock` beside `bundle`.
pub fn lock_path(bundle: &Path) -> PathBuf {
    let mut name = bundle.file_name().unwrap_or_default().to_os_string();
    name.push(".lock");
    bundle.with_file_name(name)
}

/// What a holder writes into its lock file: pid, start (Unix seconds),
/// command line, one per line.
fn holder_record() -> String {
    let since = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let command: Vec<String> = std::env::args().collect();
    let mut command = command.join(" ");
    if command.len() > 300 {
        let mut end = 300;
        while !command.is_char_boundary(end) {
            end -= 1;
        }
        command.truncate(end);
        command.push('…');
    }
    format!("{}\n{since}\n{command}\n", std::process::id())
}

/// "pid 1234, `relevo bake x.relevo`, since 2026-12-04 18:40:01 UTC" from
/// a holder's record (which may be empty while it is being written).
fn describe_holder(record: &str) -> String {
    let mut lines = record.lines();
    let (Some(pid), Some(since), Some(command)) = (lines.next(), lines.next(), lines.next()) else {
        return "its holder has not yet said who it is".into();
    };
    let since = since
        .parse::<u64>()
        .map_or_else(|_| since.to_string(), utc_timestamp);
    format!("pid {pid}, `{command}`, since {since}")
}

/// `YYYY-MM-DD HH:MM:SS UTC` for Unix seconds (the proleptic Gregorian
/// calendar from a day count: Hinnant, "chrono-Compatible Low-Level Date
/// Algorithms", `civil_from_days`).
fn utc_timestamp(unix_s: u64) -> String {
    let days = (unix_s / 86_400) as i64;
    let seconds = unix_s % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let day_of_era = z.rem_euclid(146_097);
    let year_of_era =
        (day_of_era - day_of_era / 1460 + day_of_era / 36_524 - day_of_era / 146_096) / 365;
    let day_of_year = day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
    let mp = (5 * day_of_year + 2) / 153;
    let day = day_of_year - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = year_of_era + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02} UTC",
        seconds / 3600,
        seconds / 60 % 60,
        seconds % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_writer_is_refused_with_the_holder() {
        let dir = tempfile::tempdir().unwrap();
        let bundle = dir.path().join("a.relevo");
        let held = BundleLock::acquire(&bundle).unwrap();
        let message = BundleLock::acquire(&bundle).unwrap_err().to_string();
        assert!(
            message.contains("a.relevo")
                && message.contains(&format!("pid {}", std::process::id()))
                && message.contains(" UTC"),
            "{message}"
        );
        drop(held);
        assert!(
            !lock_path(&bundle).exists(),
            "the lock file goes with the lock"
        );
        let again = BundleLock::acquire(&bundle).unwrap();
        assert_eq!(again.bundle(), bundle);
    }

    #[test]
    fn many_threads_never_hold_one_lock_together() {
        let dir = tempfile::tempdir().unwrap();
        let bundle = dir.path().join("b.relevo");
        let holders = std::sync::atomic::AtomicUsize::new(0);
        let most = std::sync::atomic::AtomicUsize::new(0);
        let taken = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..8 {
                s.spawn(|| {
                    for _ in 0..200 {
                        if let Ok(lock) = BundleLock::acquire(&bundle) {
                            use std::sync::atomic::Ordering::SeqCst;
                            let now = holders.fetch_add(1, SeqCst) + 1;
                            most.fetch_max(now, SeqCst);
                            taken.fetch_add(1, SeqCst);
                            std::thread::yield_now();
                            holders.fetch_sub(1, SeqCst);
                            drop(lock);
                        }
                    }
                });
            }
        });
        assert_eq!(most.into_inner(), 1);
        assert!(taken.into_inner() > 0);
    }

    #[test]
    fn timestamps_are_utc_calendar_dates() {
        assert_eq!(utc_timestamp(0), "1970-01-01 00:00:00 UTC");
        assert_eq!(utc_timestamp(951_782_400), "2000-02-29 00:00:00 UTC");
        assert_eq!(utc_timestamp(1_796_409_601), "2026-12-04 18:40:01 UTC");
    }
}
