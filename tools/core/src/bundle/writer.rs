use super::files::StagedFiles;
use super::hash::sha256_bytes;
use super::lock::BundleLock;
use super::manifest::{
    Artifact, ColorInfo, Crs, Dtype, GridInfo, InputFile, Manifest, StageTiming, FORMAT,
    FORMAT_VERSION,
};
use super::names::{self, MANIFEST_FILE};
use super::reader::Bundle;
use super::staging::{Leftover, Staging};
use super::validate::validate_artifacts;
use crate::grid::HeightGrid;
use crate::lp::{ErrorMetric, Hierarchy};
use crate::{Error, Result};
use names::ArtifactName;
use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

/// What a manifest says about a bundle besides its files: set once by the
/// writer of a new bundle, kept (and amendable) when one is rewritten.
#[derive(Debug, Clone, PartialEq)]
pub struct Description {
    /// Region name, from REGION.toml or the output file name.
    pub region: String,
    pub crs: Crs,
    pub grid: GridInfo,
    pub lp_error_metric: ErrorMetric,
    pub inputs: Vec<InputFile>,
    /// Every parameter the stages used, by stage then name.
    pub parameters: BTreeMap<String, serde_json::Value>,
    pub timings: Vec<StageTiming>,
}

/// Builds a bundle in `TARGET.tmp/` and moves it to `TARGET` on [`commit`].
/// Every artifact goes through one typed call — [`write_grid`],
/// [`write_hierarchy`], [`write_drape`], the whole files of
/// [`staged`] (the vegetation database, its samples, the clusters through
/// `cluster::store::write`), the exports ([`export_path`] then
/// [`record_export`]) — which
/// writes the file `names` gives it and records it in the manifest; nothing
/// else adds to a manifest. Dropped without committing, it removes the
/// staging directory; a process killed mid-way leaves only the staging
/// directory, which the next writer for the same target clears.
///
/// ```
/// use relevo_core::bundle::{Bundle, BundleWriter, Crs, Description, GridInfo};
/// use relevo_core::geo::GeoTransform;
/// use relevo_core::grid::HeightGrid;
/// use relevo_core::lp::{ErrorMetric, Hierarchy};
///
/// let side = 9;
/// let grid = HeightGrid {
///     side,
///     heights: (0..side * side).map(|i| (i % side) as f32).collect(),
///     mask: vec![1; side * side],
///     geotransform: GeoTransform::north_up(0.0, 80.0, 10.0, 10.0),
/// };
/// let dir = std::env::temp_dir().join(format!("relevo-doc-{}", std::process::id()));
/// let mut writer = BundleWriter::create(&dir.join("ramp.relevo"), true).unwrap();
/// writer.write_grid(&grid).unwrap();
/// writer
///     .write_hierarchy(&Hierarchy::compute(&grid.heights, side, 10.0, ErrorMetric::Bound))
///     .unwrap();
/// writer.describe(Description {
///     region: "ramp".into(),
///     crs: Crs { wkt: String::new(), epsg: None },
///     grid: GridInfo::of(&grid, 10.0, 1.0).unwrap(),
///     lp_error_metric: ErrorMetric::Bound,
///     inputs: Vec::new(),
///     parameters: Default::default(),
///     timings: Vec::new(),
/// });
/// let bundle = Bundle::open(&writer.commit().unwrap()).unwrap();
/// assert_eq!(bundle.heights().unwrap()[..], grid.heights[..]);
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
///
/// [`commit`]: BundleWriter::commit
/// [`write_grid`]: BundleWriter::write_grid
/// [`write_hierarchy`]: BundleWriter::write_hierarchy
/// [`write_drape`]: BundleWriter::write_drape
/// [`staged`]: BundleWriter::staged
/// [`export_path`]: BundleWriter::export_path
/// [`record_export`]: BundleWriter::record_export
pub struct BundleWriter {
    /// The staging folder, the target and the lock.
    place: Staging,
    staging: PathBuf,
    /// `relevo` version the manifest names: this build's for a new bundle,
    /// the original's for a rewrite.
    tool_version: String,
    description: Option<Description>,
    color: Option<ColorInfo>,
    /// The artifacts written so far.
    staged: StagedFiles,
    exports: BTreeMap<String, Artifact>,
}

impl BundleWriter {
    /// Start a bundle at `target`, holding its [`BundleLock`] until the
    /// writer is committed or dropped. Fails if `target` exists, unless
    /// `force` and it is a Relevo bundle: `--force` replaces only what
    /// Relevo wrote.
    pub fn create(target: &Path, force: bool) -> Result<Self> {
        if let Some(parent) = target.parent().filter(|p| !p.as_os_str().is_empty()) {
            fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        BundleWriter::start(BundleLock::acquire(target)?, target, force)
    }

    /// [`create`](BundleWriter::create) under a lock already held.
    fn start(lock: BundleLock, target: &Path, force: bool) -> Result<Self> {
        let place = Staging::start(lock, target, force, Leftover::Clear)?;
        Ok(BundleWriter {
            staging: place.dir().to_path_buf(),
            staged: StagedFiles::new(place.dir()),
            place,
            tool_version: env!("CARGO_PKG_VERSION").into(),
            description: None,
            color: None,
            exports: BTreeMap::new(),
        })
    }

    /// Start rewriting `bundle` in place under `lock` (taken on
    /// `bundle.dir`, best before the bundle was opened): the staging
    /// directory receives every artifact and export whose key passes
    /// `keep` (hard-linked where the file system allows, copied
    /// otherwise), and the manifest keeps its description and lists only
    /// those. Refused when the bundle on disk is no longer the one opened
    /// (another command rewrote it since). Until
    /// [`commit`](BundleWriter::commit) the bundle is untouched.
    pub fn rewrite(lock: BundleLock, bundle: &Bundle, keep: impl Fn(&str) -> bool) -> Result<Self> {
        if !same_place(lock.bundle(), &bundle.dir) {
            return Err(Error::invalid(
                &bundle.dir,
                format!("rewritten under the lock of {}", lock.bundle().display()),
            ));
        }
        let on_disk = Bundle::open(&bundle.dir)?;
        if on_disk.manifest != bundle.manifest {
            return Err(Error::invalid(
                &bundle.dir,
                "was rewritten by another command since it was opened; open it again",
            ));
        }
        let mut writer = BundleWriter::start(lock, &bundle.dir, true)?;
        let m = &bundle.manifest;
        writer.tool_version.clone_from(&m.tool_version);
        writer.describe(Description {
            region: m.region.clone(),
            crs: m.crs.clone(),
            grid: m.grid.clone(),
            lp_error_metric: m.lp_error_metric,
            inputs: m.inputs.clone(),
            parameters: m.parameters.clone(),
            timings: m.timings.clone(),
        });
        writer.staged.artifacts = m.artifacts.clone();
        writer.exports = m.exports.clone();
        writer.staged.artifacts.retain(|key, _| keep(key));
        writer.exports.retain(|key, _| keep(key));
        if writer.staged.artifacts.contains_key(names::COLOR.key) {
            writer.color.clone_from(&m.color);
        }
        for a in writer
            .staged
            .artifacts
            .values()
            .chain(writer.exports.values())
        {
            let (from, to) = (bundle.dir.join(&a.file), writer.staging.join(&a.file));
            if let Some(parent) = to.parent() {
                fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            if fs::hard_link(&from, &to).is_err() {
                fs::copy(&from, &to).map_err(|e| Error::io(&from, e))?;
            }
        }
        Ok(writer)
    }

    /// Set what the manifest says besides the files (required once before
    /// [`commit`](BundleWriter::commit) of a new bundle; a rewrite starts
    /// with the bundle's own).
    pub fn describe(&mut self, description: Description) {
        self.description = Some(description);
    }

    /// The description set so far, to amend (a rewrite's parameters).
    pub fn description_mut(&mut self) -> Option<&mut Description> {
        self.description.as_mut()
    }

    /// The height grid: `height.f32` and `mask.u8`, `side`².
    pub fn write_grid(&mut self, grid: &HeightGrid) -> Result<()> {
        let square = [grid.side, grid.side];
        self.put_array(names::HEIGHT, Dtype::F32, &square, &grid.heights)?;
        self.put_array(names::MASK, Dtype::U8, &square, &grid.mask)
    }

    /// The LP errors and radii: `lp.f32x2`, `side`² pairs.
    pub fn write_hierarchy(&mut self, hierarchy: &Hierarchy) -> Result<()> {
        let side = hierarchy.side;
        let pairs: &[f32] = bytemuck::cast_slice(&hierarchy.error_radius);
        self.put_array(names::LP, Dtype::F32, &[side, side, 2], pairs)
    }

    /// The drape: RGBA8 texels of the image `info` describes.
    pub fn write_drape(&mut self, rgba: &[u8], info: ColorInfo) -> Result<()> {
        self.put_array(names::COLOR, Dtype::U8, &[info.height, info.width, 4], rgba)?;
        self.color = Some(info);
        Ok(())
    }

    /// The artifacts written so far, to add whole files to (the vegetation
    /// database, its samples, the clusters).
    pub fn staged(&mut self) -> &mut StagedFiles {
        &mut self.staged
    }

    /// Where an export (a GeoTIFF, a GeoPackage, written by another
    /// program) goes in the staging directory; its folder exists. Record it
    /// with [`record_export`](BundleWriter::record_export) once written.
    pub fn export_path(&self, name: ArtifactName) -> Result<PathBuf> {
        let path = self.staging.join(name.file);
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        Ok(path)
    }

    /// Record the export written at [`export_path`](BundleWriter::export_path).
    pub fn record_export(&mut self, name: ArtifactName) -> Result<()> {
        let artifact = self.staged.record(name.file)?;
        self.exports.insert(name.key.into(), artifact);
        Ok(())
    }

    /// Write the manifest, check the staged bundle as `relevo validate`
    /// checks its artifacts, and move it into place. Returns the bundle's
    /// path.
    pub fn commit(self) -> Result<PathBuf> {
        self.commit_checked(&|_| Vec::new())
    }

    /// [`commit`](BundleWriter::commit), refusing also when `check` finds a
    /// problem in the staged bundle (the clusters' own checks, which live
    /// above the bundle format).
    ///
    /// A new bundle is renamed into place only if nothing appeared at its
    /// path meanwhile. A replaced one is swapped with the staged one in one
    /// step; the files of the old one its manifest did not list (the
    /// user's) are moved into the new one, the rest removed.
    pub fn commit_checked(mut self, check: &dyn Fn(&Bundle) -> Vec<String>) -> Result<PathBuf> {
        let path = self.staging.join(MANIFEST_FILE);
        let Some(d) = self.description.take() else {
            return Err(Error::invalid(
                self.place.target(),
                "the bundle was never described (region, CRS, grid)",
            ));
        };
        let manifest = Manifest {
            format: FORMAT.into(),
            format_version: FORMAT_VERSION,
            region: d.region,
            tool_version: std::mem::take(&mut self.tool_version),
            crs: d.crs,
            grid: d.grid,
            lp_error_metric: d.lp_error_metric,
            color: self.color.take(),
            inputs: d.inputs,
            parameters: d.parameters,
            artifacts: std::mem::take(&mut self.staged.artifacts),
            exports: std::mem::take(&mut self.exports),
            timings: d.timings,
        };
        let mut json = serde_json::to_string_pretty(&manifest).map_err(|e| Error::Manifest {
            path: path.clone(),
            json: e,
        })?;
        json.push('\n');
        fs::write(&path, json).map_err(|e| Error::io(&path, e))?;
        let staged = Bundle::open(&self.staging)?;
        let mut problems = validate_artifacts(&staged);
        problems.extend(check(&staged));
        if !problems.is_empty() {
            return Err(Error::invalid(
                self.place.target(),
                format!(
                    "the bundle written does not pass validation, so it was not kept: {}",
                    problems.join("; ")
                ),
            ));
        }
        self.place.commit()
    }

    /// Write an array artifact under `name` (little-endian, row-major).
    pub(crate) fn put_array<T: bytemuck::Pod>(
        &mut self,
        name: ArtifactName,
        dtype: Dtype,
        shape: &[usize],
        data: &[T],
    ) -> Result<()> {
        let elements: usize = shape.iter().product();
        if elements != data.len() || dtype.size() != Some(size_of::<T>()) {
            return Err(Error::invalid(
                self.staging.join(name.file),
                format!(
                    "{} values of {} bytes do not make a {dtype:?} array of shape {shape:?}",
                    data.len(),
                    size_of::<T>()
                ),
            ));
        }
        // Every target Relevo builds for is little-endian; refuse others.
        const { assert!(cfg!(target_endian = "little")) };
        let bytes: &[u8] = bytemuck::cast_slice(data);
        self.staged.write_bytes(name.file, bytes)?;
        self.staged.artifacts.insert(
            name.key.into(),
            Artifact {
                file: name.file.to_string(),
                dtype,
                shape: shape.to_vec(),
                bytes: bytes.len() as u64,
                sha256: sha256_bytes(bytes),
            },
        );
        Ok(())
    }
}

/// Do two paths name one place (their folders resolved)?
fn same_place(a: &Path, b: &Path) -> bool {
    let resolved = |p: &Path| {
        let parent = p
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        (
            parent.canonicalize().ok(),
            p.file_name().map(|n| n.to_os_string()),
        )
    };
    a == b || resolved(a) == resolved(b)
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
    let info = GridInfo::of(grid, cell_size_m, 1.0)
        .ok_or_else(|| Error::invalid(target, "the grid holds no data"))?;
    let mut writer = BundleWriter::create(target, force)?;
    let metric = ErrorMetric::default();
    writer.write_grid(grid)?;
    writer.write_hierarchy(&Hierarchy::compute(
        &grid.heights,
        grid.side,
        cell_size_m,
        metric,
    ))?;
    writer.describe(Description {
        region: region.into(),
        crs,
        grid: info,
        lp_error_metric: metric,
        inputs: Vec::new(),
        parameters: BTreeMap::new(),
        timings: Vec::new(),
    });
    writer.commit()
}
