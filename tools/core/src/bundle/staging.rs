//! The staging folder every bundle writer builds in (`NAME.relevo.tmp/`
//! beside the target, marked as Relevo's own), and the one way it becomes
//! the bundle: a new bundle is renamed into place only if nothing appeared
//! at its path meanwhile; a replaced one is swapped in one step, the files
//! of the old one its manifest did not list (the user's) carried over.
//! Grid bundles ([`super::BundleWriter`]) and pyramids both build here.

use super::lock::BundleLock;
use super::manifest::FORMAT;
use super::names::MANIFEST_FILE;
use crate::atomic;
use crate::{Error, Result};
use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

/// The pyramid bundle's format name (see `crate::pyramid`).
pub const PYRAMID_FORMAT: &str = "relevo-pyramid";

/// What to do with a staging folder a killed writer left.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Leftover {
    /// Clear it and start afresh.
    Clear,
    /// Keep it: the writer resumes from what it holds (and keeps it on a
    /// failure too, to resume again).
    Resume,
}

/// A bundle being built: the target, its staging folder and the lock.
#[derive(Debug)]
pub struct Staging {
    target: PathBuf,
    dir: PathBuf,
    /// Whether `target` existed when the writer started (and so may be
    /// replaced at commit).
    replacing: bool,
    committed: bool,
    keep_on_failure: bool,
    /// Whether the folder held a killed writer's work when it started.
    resumed: bool,
    /// Held from start to commit: one writer per bundle at a time.
    _lock: BundleLock,
}

impl Staging {
    /// Start building `target` under `lock`. Fails if `target` exists,
    /// unless `force` and it is a Relevo bundle: `--force` replaces only
    /// what Relevo wrote.
    pub fn start(
        lock: BundleLock,
        target: &Path,
        force: bool,
        leftover: Leftover,
    ) -> Result<Staging> {
        let replacing = target.symlink_metadata().is_ok();
        if replacing {
            if !force {
                return Err(Error::invalid(
                    target,
                    "already exists (pass --force to replace it)",
                ));
            }
            if !is_bundle(target) {
                return Err(Error::invalid(
                    target,
                    "exists and is not a Relevo bundle (no manifest.json of format \
                     relevo-bundle); refusing to replace it, even with --force",
                ));
            }
        }
        let dir = staging_path(target);
        let mut resumed = false;
        if dir.symlink_metadata().is_ok() {
            // Left by a writer that was killed; anything else is the user's.
            if !dir.join(STAGING_MARK).is_file() {
                return Err(Error::invalid(
                    &dir,
                    "is in the way of the bundle's staging folder and was not made by \
                     Relevo; move it away",
                ));
            }
            let plan = fs::read_to_string(dir.join(PLAN_MARK)).ok();
            if let (Some(plan), Leftover::Clear, false) = (&plan, leftover, force) {
                return Err(Error::invalid(
                    &dir,
                    format!(
                        "holds the build of the plan in {} (relevo prep --plan): finish it \
                         there, or pass --force to start afresh",
                        plan.trim()
                    ),
                ));
            }
            if leftover == Leftover::Resume {
                resumed = true;
            } else {
                tracing::warn!(
                    "{}: left by a run of Relevo that did not finish; removed, starting afresh",
                    dir.display()
                );
                fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
            }
        }
        if !resumed {
            fs::create_dir(&dir)
                .and_then(|()| fs::write(dir.join(STAGING_MARK), b""))
                .map_err(|e| Error::invalid(target, format!("cannot write ({e})")))?;
        }
        Ok(Staging {
            target: target.to_path_buf(),
            dir,
            replacing,
            committed: false,
            keep_on_failure: leftover == Leftover::Resume,
            resumed,
            _lock: lock,
        })
    }

    /// The staging folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The bundle's final path.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Whether a killed writer's work was kept to resume from.
    pub fn resumed(&self) -> bool {
        self.resumed
    }

    /// Leave the staging folder as it is, for a later writer to resume
    /// (the jobs of a plan, `relevo prep --plan`), releasing the lock.
    pub fn keep(mut self) {
        self.keep_on_failure = true;
    }

    /// Move the staged bundle into place (its manifest written and checked
    /// by the caller).
    pub fn commit(mut self) -> Result<PathBuf> {
        let mark = self.dir.join(STAGING_MARK);
        fs::remove_file(&mark).map_err(|e| Error::io(&mark, e))?;
        let plan = self.dir.join(PLAN_MARK);
        if plan.exists() {
            fs::remove_file(&plan).map_err(|e| Error::io(&plan, e))?;
        }
        // Only a bundle that was there when this writer started (and that it
        // was allowed to replace) is replaced; one that appeared since is not.
        if self.replacing && self.target.symlink_metadata().is_ok() {
            self.replace()?;
        } else {
            atomic::rename_no_replace(&self.dir, &self.target).map_err(|e| {
                if e.kind() == std::io::ErrorKind::AlreadyExists {
                    Error::invalid(
                        &self.target,
                        "appeared while this command ran; it was not replaced (run again \
                         with --force to replace it)",
                    )
                } else {
                    Error::io(&self.target, e)
                }
            })?;
        }
        self.committed = true;
        Ok(self.target.clone())
    }

    /// Put the staged bundle in the place of the existing one (a Relevo
    /// bundle, checked by `create`), keeping the user's files.
    fn replace(&self) -> Result<()> {
        let listed = listed_files(&self.target);
        let old =
            if atomic::exchange(&self.dir, &self.target).map_err(|e| Error::io(&self.target, e))? {
                self.dir.clone()
            } else {
                let old = unused_path(&self.target, "old");
                fs::rename(&self.target, &old).map_err(|e| Error::io(&self.target, e))?;
                fs::rename(&self.dir, &self.target).map_err(|e| Error::io(&self.target, e))?;
                old
            };
        let mut kept = Vec::new();
        carry_over(&old, &old, &self.target, &listed, &mut kept);
        if kept.is_empty() {
            fs::remove_dir_all(&old).map_err(|e| Error::io(&old, e))?;
        } else {
            let aside = unused_path(&self.target, "old");
            fs::rename(&old, &aside).map_err(|e| Error::io(&old, e))?;
            tracing::warn!(
                "{}: the new bundle has files at the paths of {} of yours ({}); yours are in {}",
                self.target.display(),
                kept.len(),
                kept.join(", "),
                aside.display()
            );
        }
        Ok(())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed && !self.keep_on_failure {
            let _ = fs::remove_dir_all(&self.dir);
        }
    }
}

/// The files a bundle's manifest lists (a single grid's artifacts and
/// exports, a pyramid's files) and the manifest itself: what Relevo wrote
/// there.
fn listed_files(dir: &Path) -> BTreeSet<PathBuf> {
    let mut listed = BTreeSet::from([PathBuf::from(MANIFEST_FILE)]);
    let manifest = crate::files::read_to_string(&dir.join(MANIFEST_FILE))
        .ok()
        .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok());
    for table in ["artifacts", "exports", "files"] {
        let entries = manifest
            .as_ref()
            .and_then(|m| m.get(table))
            .and_then(|t| t.as_object());
        for entry in entries.into_iter().flat_map(|t| t.values()) {
            if let Some(file) = entry.get("file").and_then(|f| f.as_str()) {
                listed.insert(PathBuf::from(file));
            }
        }
    }
    listed
}

/// Move every file under `dir` (inside the old bundle `root`) that `listed`
/// does not name into the same place under `new`; those whose place is
/// taken stay and are named in `kept`.
fn carry_over(
    root: &Path,
    dir: &Path,
    new: &Path,
    listed: &BTreeSet<PathBuf>,
    kept: &mut Vec<String>,
) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let Ok(relative) = path.strip_prefix(root) else {
            continue;
        };
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            carry_over(root, &path, new, listed, kept);
            continue;
        }
        if listed.contains(relative) {
            continue;
        }
        let to = new.join(relative);
        let moved = to.symlink_metadata().is_err()
            && to.parent().is_some_and(|p| fs::create_dir_all(p).is_ok())
            && fs::rename(&path, &to).is_ok();
        if !moved {
            kept.push(relative.display().to_string());
        }
    }
}

/// The `format` of the folder `dir`'s `manifest.json` (`relevo-bundle`,
/// `relevo-pyramid`), or `None` when it has no readable one.
pub fn format_of(dir: &Path) -> Option<String> {
    dir.is_dir()
        .then(|| crate::files::read_to_string(&dir.join(MANIFEST_FILE)).ok())
        .flatten()
        .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
        .and_then(|m| m.get("format").and_then(|f| f.as_str()).map(str::to_string))
}

/// Is `dir` a Relevo bundle: a folder whose `manifest.json` is JSON of
/// format `relevo-bundle` or `relevo-pyramid` (any version)?
pub fn is_bundle(dir: &Path) -> bool {
    matches!(format_of(dir).as_deref(), Some(FORMAT | PYRAMID_FORMAT))
}

/// `TARGET.SUFFIX`, or `TARGET.SUFFIX.N` for the first N not taken: a place
/// to move the replaced bundle to without touching anything of the user's.
fn unused_path(target: &Path, suffix: &str) -> PathBuf {
    let name = target.file_name().unwrap_or_default().to_string_lossy();
    let mut path = target.with_file_name(format!("{name}.{suffix}"));
    let mut n = 1;
    while path.symlink_metadata().is_ok() {
        path = target.with_file_name(format!("{name}.{suffix}.{n}"));
        n += 1;
    }
    path
}

/// The empty file that marks a staging folder as Relevo's own, so that only
/// such a folder is ever cleared; it is removed before the folder becomes
/// the bundle.
const STAGING_MARK: &str = ".relevo-staging";

/// The file a plan's build keeps in its staging folder, naming the plan's
/// folder: the jobs share the folder, and no other writer clears it
/// without `--force`.
pub const PLAN_MARK: &str = ".relevo-plan";

/// `TARGET.tmp` beside the target.
pub fn staging_path(target: &Path) -> PathBuf {
    let mut name = target.file_name().unwrap_or_default().to_os_string();
    name.push(".tmp");
    target.with_file_name(name)
}
