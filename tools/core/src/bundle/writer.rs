use super::Bundle;
use super::{
    names, sha256_bytes, sha256_file, Artifact, Crs, Dtype, GridInfo, Manifest, FORMAT,
    FORMAT_VERSION, MANIFEST_FILE,
};
use crate::grid::HeightGrid;
use crate::lp::{ErrorMetric, Hierarchy};
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

/// Builds a bundle in `TARGET.tmp/` and moves it to `TARGET` on [`commit`].
/// Dropped without committing, it removes the staging directory; a process
/// killed mid-way leaves only the staging directory, which the next writer
/// for the same target clears.
///
/// [`commit`]: BundleWriter::commit
pub struct BundleWriter {
    target: PathBuf,
    staging: PathBuf,
    committed: bool,
}

impl BundleWriter {
    /// Start a bundle at `target`. Fails if `target` exists, unless `force`
    /// and it is a Relevo bundle: `--force` replaces only what Relevo wrote.
    pub fn create(target: &Path, force: bool) -> Result<Self> {
        if target.symlink_metadata().is_ok() {
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
        let staging = staging_path(target);
        if staging.exists() {
            fs::remove_dir_all(&staging).map_err(|e| Error::io(&staging, e))?;
        }
        fs::create_dir_all(&staging)
            .map_err(|e| Error::invalid(target, format!("cannot write ({e})")))?;
        Ok(BundleWriter {
            target: target.to_path_buf(),
            staging,
            committed: false,
        })
    }

    /// Start rewriting `bundle` in place: the staging directory receives
    /// every artifact and export whose key passes `keep` (hard-linked where
    /// the file system allows, copied otherwise), and the returned manifest
    /// lists only those. Until [`commit`](BundleWriter::commit) the bundle
    /// is untouched.
    pub fn rewrite(bundle: &Bundle, keep: impl Fn(&str) -> bool) -> Result<(Self, Manifest)> {
        let writer = BundleWriter::create(&bundle.dir, true)?;
        let mut manifest = bundle.manifest.clone();
        manifest.artifacts.retain(|key, _| keep(key));
        manifest.exports.retain(|key, _| keep(key));
        for a in manifest.artifacts.values().chain(manifest.exports.values()) {
            let (from, to) = (bundle.dir.join(&a.file), writer.staging.join(&a.file));
            if let Some(parent) = to.parent() {
                fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            if fs::hard_link(&from, &to).is_err() {
                fs::copy(&from, &to).map_err(|e| Error::io(&from, e))?;
            }
        }
        Ok((writer, manifest))
    }

    /// The staging directory, for writers that produce files themselves.
    pub fn dir(&self) -> &Path {
        &self.staging
    }

    /// Write a little-endian array and describe it.
    pub fn write_array<T: bytemuck::Pod>(
        &self,
        file: &str,
        dtype: Dtype,
        shape: &[usize],
        data: &[T],
    ) -> Result<Artifact> {
        let elements: usize = shape.iter().product();
        assert_eq!(elements, data.len(), "{file}: shape does not match data");
        assert_eq!(dtype.size(), Some(size_of::<T>()), "{file}: dtype");
        // Every target Relevo builds for is little-endian; refuse others.
        const { assert!(cfg!(target_endian = "little")) };
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let path = self.staging.join(file);
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        fs::write(&path, bytes).map_err(|e| Error::io(&path, e))?;
        Ok(Artifact {
            file: file.to_string(),
            dtype,
            shape: shape.to_vec(),
            bytes: bytes.len() as u64,
            sha256: sha256_bytes(bytes),
        })
    }

    /// Write a non-array file (CSV, PNG, …) and describe it.
    pub fn write_file(&self, file: &str, bytes: &[u8]) -> Result<Artifact> {
        let path = self.staging.join(file);
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        fs::write(&path, bytes).map_err(|e| Error::io(&path, e))?;
        self.record_file(file)
    }

    /// Describe a file already written inside the staging directory.
    pub fn record_file(&self, file: &str) -> Result<Artifact> {
        let (bytes, sha256) = sha256_file(&self.staging.join(file))?;
        Ok(Artifact {
            file: file.to_string(),
            dtype: Dtype::File,
            shape: Vec::new(),
            bytes,
            sha256,
        })
    }

    /// Write the manifest and move the bundle into place, replacing an older
    /// one only after the new one is complete.
    pub fn commit(mut self, manifest: &Manifest) -> Result<PathBuf> {
        let path = self.staging.join(MANIFEST_FILE);
        let mut json = serde_json::to_string_pretty(manifest).map_err(|e| Error::Manifest {
            path: path.clone(),
            source: e,
        })?;
        json.push('\n');
        fs::write(&path, json).map_err(|e| Error::io(&path, e))?;
        if self.target.exists() {
            let old = unused_path(&self.target, "old");
            fs::rename(&self.target, &old).map_err(|e| Error::io(&self.target, e))?;
            fs::rename(&self.staging, &self.target).map_err(|e| Error::io(&self.target, e))?;
            fs::remove_dir_all(&old).map_err(|e| Error::io(&old, e))?;
        } else {
            fs::rename(&self.staging, &self.target).map_err(|e| Error::io(&self.target, e))?;
        }
        self.committed = true;
        Ok(self.target.clone())
    }
}

impl Drop for BundleWriter {
    fn drop(&mut self) {
        if !self.committed {
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}

/// A terrain-only bundle of `grid` (heights, mask, LP errors and radii):
/// what a program that makes its own heightfield writes, and the viewer's
/// tests use on real DEM crops. `crs` empty means grid units.
pub fn write_terrain_bundle(
    target: &Path,
    region: &str,
    grid: &HeightGrid,
    cell_size_m: f64,
    crs: Crs,
    force: bool,
) -> Result<PathBuf> {
    let side = grid.side;
    let info = GridInfo::of(grid, cell_size_m, 1.0)
        .ok_or_else(|| Error::invalid(target, "the grid holds no data"))?;
    let writer = BundleWriter::create(target, force)?;
    let hierarchy = Hierarchy::compute(&grid.heights, side, cell_size_m, ErrorMetric::default());
    let square = [side, side];
    let mut artifacts = BTreeMap::new();
    artifacts.insert(
        names::HEIGHT.key.to_string(),
        writer.write_array(names::HEIGHT.file, Dtype::F32, &square, &grid.heights)?,
    );
    artifacts.insert(
        names::MASK.key.to_string(),
        writer.write_array(names::MASK.file, Dtype::U8, &square, &grid.mask)?,
    );
    let pairs: &[f32] = bytemuck::cast_slice(&hierarchy.error_radius);
    artifacts.insert(
        names::LP.key.to_string(),
        writer.write_array(names::LP.file, Dtype::F32, &[side, side, 2], pairs)?,
    );
    let manifest = Manifest {
        format: FORMAT.into(),
        format_version: FORMAT_VERSION,
        region: region.into(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
        crs,
        grid: info,
        lp_error_metric: ErrorMetric::default(),
        color: None,
        inputs: Vec::new(),
        parameters: BTreeMap::new(),
        artifacts,
        exports: BTreeMap::new(),
        timings: Vec::new(),
    };
    writer.commit(&manifest)
}

/// `TARGET.tmp` beside the target.
/// Is `dir` a Relevo bundle: a folder whose `manifest.json` is JSON of
/// format `relevo-bundle` (any version)?
pub fn is_bundle(dir: &Path) -> bool {
    dir.is_dir()
        && fs::read_to_string(dir.join(MANIFEST_FILE))
            .ok()
            .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
            .is_some_and(|m| m.get("format").and_then(|f| f.as_str()) == Some(FORMAT))
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

pub(crate) fn staging_path(target: &Path) -> PathBuf {
    let mut name = target.file_name().unwrap_or_default().to_os_string();
    name.push(".tmp");
    target.with_file_name(name)
}
