//! The pyramid bundle: a region of any size as a quadtree of tiles of
//! (2^k+1)² vertices on the Lindstrom–Pascucci hierarchy, each holding its
//! heights, mask, errors and radii and drape, packed into four large
//! memory-mappable files, with a manifest (`format: relevo-pyramid`). See
//! docs/formats.md#pyramid for the specification.
//!
//! - [`layout`]: where each tile lies on the grid and in the files.
//! - [`store`]: the tile files being written, and a build's scratch and
//!   progress.
//! - [`build`]: the tiles computed pass by pass in bounded memory, equal
//!   bit for bit to the single grid.
//! - [`ground`]: the heights vegetation stands on, read tile by tile.
//! - [`jobs`]: a build split into jobs that processes on several machines
//!   run side by side.
//! - [`reader`]: a pyramid opened, its tiles mapped without copying, the
//!   tiles a camera sees, and the checks `relevo validate` runs.
//! - [`mesh`]: the mesh of the region or of a window of it at a tolerance,
//!   read through the tiles.
//! - [`render`]: the raycast whose distance bands are the levels.
//! - [`paging`]: tiles read in the background for a moving camera under a
//!   memory budget, and the crack-free cut a frame refines through.

pub mod build;
pub mod ground;
pub mod jobs;
pub mod layout;
pub mod mesh;
pub mod paging;
pub mod reader;
pub mod render;
pub mod store;

pub use build::{BuildOptions, BuildReport, DrapeSource, HeightSource, Progress, Step};
pub use layout::{default_tile_cells, TileKey, TileLayout, DEFAULT_TILE_CELLS};
pub use reader::Pyramid;

use crate::bundle::{
    sha256_file, Artifact, BundleLock, Crs, Dtype, GridInfo, InputFile, Leftover, StageTiming,
    StagedFiles, Staging, MANIFEST_FILE, PYRAMID_FORMAT,
};
use crate::lp::ErrorMetric;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use store::{TileArray, TileStore};

/// The version of the pyramid format this build reads and writes.
pub const FORMAT_VERSION: u32 = 1;

/// `manifest.json` of a pyramid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PyramidManifest {
    pub format: String,
    pub format_version: u32,
    pub region: String,
    pub tool_version: String,
    pub crs: Crs,
    /// The level-0 grid, as a single-grid bundle describes it.
    pub grid: GridInfo,
    pub lp_error_metric: ErrorMetric,
    pub tiling: Tiling,
    /// The tile files: `height`, `mask`, `lp`, `drape`, each
    /// `[tiles, T+1, T+1(, channels)]`; then, when the region has
    /// vegetation, its database and clusters as a single-grid bundle
    /// lists them (`vegetation`, `clusters_*`).
    pub files: BTreeMap<String, Artifact>,
    pub inputs: Vec<InputFile>,
    #[serde(default)]
    pub parameters: BTreeMap<String, serde_json::Value>,
    #[serde(default)]
    pub timings: Vec<StageTiming>,
}

/// How the grid is tiled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Tiling {
    /// Cells a tile side, 2^k (tiles have `tile_cells + 1` vertices a side).
    pub tile_cells: usize,
    /// Levels, 0 finest.
    pub levels: u32,
    /// Tiles in all levels (the files' slots).
    pub tiles: usize,
}

/// What a pyramid's manifest says besides its tiling and files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PyramidDescription {
    pub region: String,
    pub crs: Crs,
    /// The grid; its height range and data count are filled in by the build.
    pub grid: GridInfo,
    pub inputs: Vec<InputFile>,
    pub parameters: BTreeMap<String, serde_json::Value>,
}

/// How a pyramid is written.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct WriteOptions {
    pub tile_cells: usize,
    pub build: BuildOptions,
    /// Replace an existing bundle at the target.
    pub force: bool,
    /// Go on from the staging folder a killed build left.
    pub resume: bool,
}

/// The build's plan, kept in the staging folder: a resumed build must be
/// the same build.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Plan {
    layout: TileLayout,
    metric: ErrorMetric,
    cell_size_m: f64,
    drape: bool,
    inputs: Vec<InputFile>,
    parameters: BTreeMap<String, serde_json::Value>,
}

const PLAN_FILE: &str = "plan.json";

/// Build the pyramid of `source` at `target`: staged beside it, refused
/// before anything is written when the disk cannot hold it, resumable
/// after a kill, checked, then moved into place.
pub fn write_pyramid(
    target: &Path,
    source: &dyn HeightSource,
    description: PyramidDescription,
    options: WriteOptions,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<PathBuf> {
    let (staging, store) = start_build(target, &description, &options)?;
    let report = build::build(source, None, &store, &options.build, progress)?;
    let extras = StagedFiles::new(staging.dir());
    seal_build(
        staging,
        store,
        report,
        description,
        &options,
        extras,
        &|_| Vec::new(),
    )
}

/// Start (or, with `options.resume`, go on with) the build of a pyramid
/// at `target`: the checks of [`preflight`], the staging folder beside the
/// target holding the build's plan, and its tile files opened. A resumed
/// build must be of the same inputs and options.
pub fn start_build(
    target: &Path,
    description: &PyramidDescription,
    options: &WriteOptions,
) -> Result<(Staging, TileStore)> {
    let layout = TileLayout::new(description.grid.side, options.tile_cells)?;
    preflight(target, layout.side, layout.tile_cells, options.resume)?;
    if let Some(parent) = target.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    }
    let leftover = if options.resume {
        Leftover::Resume
    } else {
        Leftover::Clear
    };
    let staging = Staging::start(
        BundleLock::acquire(target)?,
        target,
        options.force,
        leftover,
    )?;
    let dir = staging.dir().to_path_buf();
    let plan = Plan {
        layout,
        metric: options.build.metric,
        cell_size_m: options.build.cell_size_m,
        drape: options.build.drape,
        inputs: description.inputs.clone(),
        parameters: description.parameters.clone(),
    };
    let plan_path = dir.join(PLAN_FILE);
    if staging.resumed() {
        let kept: Option<Plan> = crate::files::read_to_string(&plan_path)
            .ok()
            .and_then(|text| serde_json::from_str(&text).ok());
        if kept.as_ref() != Some(&plan) {
            return Err(Error::invalid(
                &dir,
                "holds a build of other inputs or options; run without --resume to start afresh",
            ));
        }
    } else {
        let text = serde_json::to_string_pretty(&plan)
            .map_err(|e| Error::Input(format!("cannot write the build plan ({e})")))?;
        std::fs::write(&plan_path, text).map_err(|e| Error::io(&plan_path, e))?;
    }
    let store = TileStore::open(&dir, layout, build::partials_capacity(&layout))?;
    Ok((staging, store))
}

/// The tile files of the build staged for `target` (see [`start_build`]),
/// opened without the bundle's lock, for one of the jobs that share the
/// build; an error when there is no such build.
pub fn open_build(target: &Path, layout: TileLayout) -> Result<TileStore> {
    let dir = crate::bundle::staging_path(target);
    if !dir.join(PLAN_FILE).is_file() {
        return Err(Error::invalid(
            &dir,
            "holds no pyramid build (finished and moved into place, or removed)",
        ));
    }
    Ok(TileStore::open(&dir, layout, build::partials_capacity(&layout))?.durable())
}

/// Finish a build whose every step is done: the manifest written with
/// the report's figures and the hashes of the tile files and of `extras`
/// (the vegetation and its clusters, written into the staging folder),
/// the pyramid validated — its tiles, and whatever `check` finds (the
/// clusters' own checks, which live above the format) — moved into place,
/// its scratch removed.
pub fn seal_build(
    staging: Staging,
    store: TileStore,
    report: BuildReport,
    description: PyramidDescription,
    options: &WriteOptions,
    extras: StagedFiles,
    check: &dyn Fn(&Pyramid) -> Vec<String>,
) -> Result<PathBuf> {
    let layout = store.layout;
    let dir = staging.dir().to_path_buf();
    for step in build::steps(&layout, options.build.drape) {
        let left = step.missing(&store, &step.tiles(&layout))?;
        if let Some(first) = left.first() {
            return Err(Error::invalid(
                &dir,
                format!(
                    "the build is not complete: step {} has {} tiles left (first {first:?})",
                    step.name(),
                    left.len()
                ),
            ));
        }
    }
    store.remove_scratch()?;
    let start = std::time::Instant::now();
    let mut files = BTreeMap::new();
    for a in TileArray::ALL {
        let (key, file) = a.name();
        let (bytes, sha256) = sha256_file(&dir.join(file))?;
        let channels = match a {
            TileArray::Lp => vec![2],
            TileArray::Drape => vec![4],
            _ => vec![],
        };
        let mut shape = vec![layout.count(), layout.samples(), layout.samples()];
        shape.extend(channels);
        let dtype = if matches!(a, TileArray::Mask | TileArray::Drape) {
            Dtype::U8
        } else {
            Dtype::F32
        };
        files.insert(
            key.to_string(),
            Artifact {
                file: file.to_string(),
                dtype,
                shape,
                bytes,
                sha256,
            },
        );
    }
    for (key, artifact) in extras.into_artifacts() {
        if files.contains_key(&key) {
            return Err(Error::invalid(&dir, format!("{key}: a tile file's key")));
        }
        files.insert(key, artifact);
    }
    let mut timings = report.timings.clone();
    timings.push(StageTiming {
        stage: "hashes".into(),
        ms: start.elapsed().as_secs_f64() * 1e3,
    });
    let mut grid = description.grid;
    grid.height_range_m = report.height_range_m;
    grid.valid_vertices = report.valid_vertices as usize;
    let manifest = PyramidManifest {
        format: PYRAMID_FORMAT.into(),
        format_version: FORMAT_VERSION,
        region: description.region,
        tool_version: env!("CARGO_PKG_VERSION").into(),
        crs: description.crs,
        grid,
        lp_error_metric: options.build.metric,
        tiling: Tiling {
            tile_cells: layout.tile_cells,
            levels: layout.levels(),
            tiles: layout.count(),
        },
        files,
        inputs: description.inputs,
        parameters: description.parameters,
        timings,
    };
    let plan_path = dir.join(PLAN_FILE);
    std::fs::remove_file(&plan_path).map_err(|e| Error::io(&plan_path, e))?;
    commit_staged(staging, &manifest, check, "written")
}

/// Write `manifest` into the staging folder, check the staged pyramid (its
/// tiles, then `check`) and move it into place; refused, naming what was
/// `done` to it, when a check fails.
fn commit_staged(
    staging: Staging,
    manifest: &PyramidManifest,
    check: &dyn Fn(&Pyramid) -> Vec<String>,
    done: &str,
) -> Result<PathBuf> {
    let dir = staging.dir();
    let path = dir.join(MANIFEST_FILE);
    let mut json = serde_json::to_string_pretty(manifest).map_err(|e| Error::Manifest {
        path: path.clone(),
        json: e,
    })?;
    json.push('\n');
    std::fs::write(&path, json).map_err(|e| Error::io(&path, e))?;
    let staged = Pyramid::open(dir)?;
    let mut problems = reader::validate(&staged, false);
    problems.extend(check(&staged));
    drop(staged);
    if !problems.is_empty() {
        return Err(Error::invalid(
            staging.target(),
            format!(
                "the pyramid {done} does not pass validation, so it was not kept: {}",
                problems.join("; ")
            ),
        ));
    }
    staging.commit()
}

/// Replace, in place and atomically, the files of `pyramid` that
/// `replaced` picks by keys (its clusters, say) with those `fill` writes
/// (see [`StagedFiles`]): the other files are hard-linked (copied where the
/// file system cannot link) into a staging folder beside it, the manifest
/// lists them and the new ones, the staged pyramid must pass its tiles'
/// validation and `check`, then it takes the pyramid's place; a failure
/// leaves the pyramid as it was. `lock` is the pyramid's, taken before it
/// was opened. Returns its path.
pub fn rewrite(
    lock: BundleLock,
    pyramid: &Pyramid,
    replaced: &dyn Fn(&str) -> bool,
    fill: impl FnOnce(&mut StagedFiles) -> Result<()>,
    check: &dyn Fn(&Pyramid) -> Vec<String>,
) -> Result<PathBuf> {
    let staging = Staging::start(lock, &pyramid.dir, true, Leftover::Clear)?;
    let dir = staging.dir().to_path_buf();
    let mut manifest = pyramid.manifest.clone();
    manifest.files.retain(|key, _| !replaced(key));
    for a in manifest.files.values() {
        let (from, to) = (pyramid.dir.join(&a.file), dir.join(&a.file));
        if let Some(parent) = to.parent() {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        if std::fs::hard_link(&from, &to).is_err() {
            std::fs::copy(&from, &to).map_err(|e| Error::io(&from, e))?;
        }
    }
    let mut extras = StagedFiles::new(&dir);
    fill(&mut extras)?;
    for (key, artifact) in extras.into_artifacts() {
        if manifest.files.contains_key(&key) {
            return Err(Error::invalid(&dir, format!("{key}: written twice")));
        }
        manifest.files.insert(key, artifact);
    }
    commit_staged(staging, &manifest, check, "rewritten")
}

/// The checks a pyramid of a `side`² grid in tiles of `tile_cells` at
/// `target` must pass before any work: the tiling, the build's working
/// memory against the budget and, for a fresh build, the disk space the
/// tiles and the build's scratch need on the file system that will hold
/// them. [`write_pyramid`] runs them; a caller with slow work to do before
/// (a scan of its input) runs them first.
pub fn preflight(target: &Path, side: usize, tile_cells: usize, resume: bool) -> Result<()> {
    let layout = TileLayout::new(side, tile_cells)?;
    build::check_working_memory(&layout)?;
    if resume {
        return Ok(());
    }
    // The nearest folder that exists on the way to the target.
    let mut dir = target.parent().unwrap_or(Path::new("."));
    while !dir.as_os_str().is_empty() && !dir.is_dir() {
        dir = dir.parent().unwrap_or(Path::new("."));
    }
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let capacity = build::partials_capacity(&layout);
    check_free_space(dir, TileStore::bytes_needed(&layout, capacity))
}

/// Refuse to start when the file system holding `dir` has less than
/// `needed` bytes free.
fn check_free_space(dir: &Path, needed: u64) -> Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes())
        .map_err(|_| Error::invalid(dir, "a path with a NUL byte"))?;
    // SAFETY: `stat` is a plain C struct, fully written by a successful
    // statvfs; `c` is a NUL-terminated path living across the call.
    let free = unsafe {
        let mut stat: libc::statvfs = std::mem::zeroed();
        (libc::statvfs(c.as_ptr(), &mut stat) == 0)
            .then(|| stat.f_bavail as u64 * stat.f_frsize as u64)
    };
    match free {
        Some(free) if free < needed => Err(Error::invalid(
            dir,
            format!(
                "the pyramid needs about {} on disk (tiles and the build's scratch) but {} is free",
                crate::memory::human(needed),
                crate::memory::human(free)
            ),
        )),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_disk_too_small_is_refused_naming_the_estimate_and_the_free_space() {
        let d = tempfile::tempdir().unwrap();
        let e = check_free_space(d.path(), u64::MAX / 4)
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs about") && e.contains("is free"), "{e}");
        assert!(e.contains(&d.path().display().to_string()), "{e}");
        check_free_space(d.path(), 1).unwrap();
        // Through the preflight, from a target whose folders do not exist yet.
        preflight(&d.path().join("a/b/x.relevo"), 1025, 128, false).unwrap();
    }
}
