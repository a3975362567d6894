//! `relevo prep --tiled`: the heights read window by window (a single
//! DEM on the target grid whose voids the fill stage fills, `direct`) or through the grid stages
//! of `prep` (stitch, fill, square, in memory), then the pyramid bundle
//! written tile by tile through relevo-core —
//! errors and radii, the derived drape and the coarser levels computed in
//! memory bounded by a few tiles and their halos, resumable after a kill,
//! with progress and an ETA per pass. The drape is always derived from the
//! heights; imagery, vegetation and clusters are not yet written into
//! pyramids and are refused.

use super::direct::DirectSource;
use super::region::RegionSpec;
use super::{provenance, provenance_of, stage_dem, stage_fill, stage_grid, Build};
use anyhow::{bail, Context, Result};
use relevo_core::bundle::GridInfo;
use relevo_core::grid::HeightGrid;
use relevo_core::pyramid::{self, BuildOptions, HeightSource, PyramidDescription, WriteOptions};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How a pyramid is prepared.
#[derive(Debug, Clone, Copy)]
pub struct TiledOptions {
    /// Cells a tile side (2^k).
    pub tile_cells: usize,
    pub force: bool,
    /// Go on from a killed build's staging folder.
    pub resume: bool,
}

/// What `prep --tiled` reports (`--json` prints it).
#[derive(Debug, Serialize)]
pub struct TiledSummary {
    pub bundle: PathBuf,
    pub region: String,
    pub side: usize,
    pub cell_size_m: f64,
    pub tile_cells: usize,
    pub levels: u32,
    pub tiles: usize,
    pub valid_vertices: usize,
    pub height_range_m: [f32; 2],
    /// Whether the DEM was read window by window (else through the
    /// in-memory grid stages).
    pub read_by_windows: bool,
    pub grid_ms: f64,
    pub pyramid_ms: f64,
}

/// Prepare `region` as a pyramid at `out`.
pub fn prep_tiled(region: &RegionSpec, out: &Path, options: TiledOptions) -> Result<TiledSummary> {
    if region.image.is_some() || region.vegetation.is_some() || region.clusters.is_some() {
        bail!(
            "a tiled bundle (--tiled) derives its drape from the heights; imagery, vegetation \
             and clusters are not written into pyramids yet — drop [image], [vegetation] and \
             [clusters], or prepare a single-grid bundle"
        );
    }
    if out.symlink_metadata().is_ok() && !options.force && !options.resume {
        bail!(
            "{}: already exists (pass --force to replace it)",
            out.display()
        );
    }
    let name = region_name(region, out);
    let start = Instant::now();
    let (heights, description) =
        height_source(region, &name, out, options.tile_cells, options.resume)?;
    let read_by_windows = matches!(heights, Heights::Windows(_));
    let grid_ms = start.elapsed().as_secs_f64() * 1e3;
    let write = write_options(region, &description, options);
    let start = Instant::now();
    let bar = crate::progress::pass_bar();
    let bundle = pyramid::write_pyramid(out, heights.source(), description, write, &|p| {
        crate::progress::show_pass(&bar, p);
    })?;
    bar.finish_and_clear();
    let pyramid_ms = start.elapsed().as_secs_f64() * 1e3;
    TiledSummary::of(bundle, read_by_windows, grid_ms, pyramid_ms)
}

impl TiledSummary {
    /// What the pyramid written at `bundle` reports, with how its heights
    /// were read and the grid's and the pyramid's wall times, ms.
    pub fn of(
        bundle: PathBuf,
        read_by_windows: bool,
        grid_ms: f64,
        pyramid_ms: f64,
    ) -> Result<TiledSummary> {
        let opened = pyramid::Pyramid::open(&bundle)?;
        let m = &opened.manifest;
        Ok(TiledSummary {
            region: m.region.clone(),
            side: m.grid.side,
            cell_size_m: m.grid.cell_size_m,
            tile_cells: m.tiling.tile_cells,
            levels: m.tiling.levels,
            tiles: m.tiling.tiles,
            valid_vertices: m.grid.valid_vertices,
            height_range_m: m.grid.height_range_m,
            read_by_windows,
            grid_ms,
            pyramid_ms,
            bundle,
        })
    }
}

/// The region's name: its own, else the output's file stem.
pub fn region_name(region: &RegionSpec, out: &Path) -> String {
    region.name.clone().unwrap_or_else(|| {
        out.file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_else(|| "region".into())
    })
}

/// How the pyramid of `region` described by `description` is written.
pub fn write_options(
    region: &RegionSpec,
    description: &PyramidDescription,
    options: TiledOptions,
) -> WriteOptions {
    WriteOptions {
        tile_cells: options.tile_cells,
        build: BuildOptions {
            metric: region.grid.error_metric,
            cell_size_m: description.grid.cell_size_m,
            drape: true,
        },
        force: options.force,
        resume: options.resume,
    }
}

/// Where a pyramid's heights come from.
pub enum Heights {
    /// The DEM read window by window.
    Windows(DirectSource),
    /// The grid built in memory by the grid stages.
    Grid(HeightGrid),
}

impl Heights {
    pub fn source(&self) -> &dyn HeightSource {
        match self {
            Heights::Windows(d) => d,
            Heights::Grid(g) => g,
        }
    }
}

/// Where the pyramid's heights come from, and its description: a single
/// DEM on the target grid whose voids are holes the fill stage fills is
/// read window by window (the tiling, memory and disk checked before the
/// file is scanned); anything else goes through the in-memory grid stages.
pub fn height_source(
    region: &RegionSpec,
    name: &str,
    out: &Path,
    tile_cells: usize,
    resume: bool,
) -> Result<(Heights, PyramidDescription)> {
    if let Some(mut d) = DirectSource::open(region)? {
        pyramid::preflight(out, d.grid.side, tile_cells, resume)?;
        if d.scan()? {
            let (inputs, parameters) = provenance_of(region)?;
            let description = PyramidDescription {
                region: name.to_string(),
                crs: d.crs.clone(),
                grid: d.grid.clone(),
                inputs,
                parameters,
            };
            return Ok((Heights::Windows(d), description));
        }
    }
    let mut b = Build::new(region, name.to_string(), None);
    for (stage, run) in [
        ("dem", stage_dem as fn(&mut Build) -> Result<()>),
        ("fill", stage_fill),
        ("grid", stage_grid),
    ] {
        run(&mut b).with_context(|| format!("stage {stage}"))?;
    }
    let grid: HeightGrid = b.grid.take().context("grid stage did not run")?;
    let dem = b.dem.take().context("dem stage did not run")?;
    let info =
        GridInfo::of(&grid, b.cell_size_m, region.z_scale).context("the DEM has no valid data")?;
    let (crs, inputs, parameters) = provenance(region, &dem)?;
    let description = PyramidDescription {
        region: name.to_string(),
        crs,
        grid: info,
        inputs,
        parameters,
    };
    Ok((Heights::Grid(grid), description))
}
