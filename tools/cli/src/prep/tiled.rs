//! `relevo prep --tiled`: the heights read window by window (a single
//! DEM on the target grid whose voids the fill stage fills, `direct`) or through the grid stages
//! of `prep` (stitch, fill, square, in memory), then the pyramid bundle
//! written tile by tile through relevo-core —
//! errors and radii, the derived drape and the coarser levels computed in
//! memory bounded by a few tiles and their halos, resumable after a kill,
//! with progress and an ETA per pass. The tiles' drape is sampled from the
//! imagery of `[image]` tile by tile (`drape`), else derived from the
//! heights. With `[vegetation]`, the vegetation is detected on the imagery
//! as a single-grid `prep` detects it (the imagery cropped to the DEM and
//! stretched, in memory: at most `MAX_IMAGE_SIDE` pixels a side) and its
//! clusters are baked standing on the tiles' ground
//! (`pyramid::ground::TiledGround`): the pyramid then holds the same
//! `vegetation.csv` and `clusters/` as the single-grid bundle of the region.

use super::direct::DirectSource;
use super::drape::ImageryDrape;
use super::region::RegionSpec;
use super::{
    detect_on_drape, imagery_drape, provenance, provenance_of, stage_dem, stage_fill, stage_grid,
    Build,
};
use crate::clusters::{bake_with_progress, ClustersSummary};
use crate::ingest::gdalio::GridSpec;
use anyhow::{bail, Context, Result};
use relevo_core::bundle::{GridInfo, StagedFiles};
use relevo_core::cluster::store;
use relevo_core::grid::HeightGrid;
use relevo_core::pyramid::ground::TiledGround;
use relevo_core::pyramid::{
    self, default_tile_cells, BuildOptions, DrapeSource, HeightSource, PyramidDescription,
    TileLayout, WriteOptions,
};
use relevo_core::veg::db;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How a pyramid is prepared.
#[derive(Debug, Clone, Copy)]
pub struct TiledOptions {
    /// Cells a tile side (2^k); none: [`default_tile_cells`] of the grid.
    pub tile_cells: Option<usize>,
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
    /// Objects in the vegetation database, when the region has vegetation.
    pub vegetation: Option<usize>,
    /// Its clusters.
    pub clusters: Option<ClustersSummary>,
    /// Detecting the vegetation and baking its clusters, ms.
    pub vegetation_ms: f64,
}

/// Prepare `region` as a pyramid at `out`.
pub fn prep_tiled(region: &RegionSpec, out: &Path, options: TiledOptions) -> Result<TiledSummary> {
    if out.symlink_metadata().is_ok() && !options.force && !options.resume {
        bail!(
            "{}: already exists (pass --force to replace it)",
            out.display()
        );
    }
    let name = region_name(region, out);
    let start = Instant::now();
    let (heights, description, dem) =
        height_source(region, &name, out, options.tile_cells, options.resume)?;
    let read_by_windows = matches!(heights, Heights::Windows(_));
    let grid_ms = start.elapsed().as_secs_f64() * 1e3;
    let write = write_options(region, &description, options);
    let start = Instant::now();
    // The imagery opened (and its stretch taken) before anything is staged.
    let imagery = match &region.image {
        Some(image) => Some(ImageryDrape::open(
            image,
            &dem,
            description.grid.geotransform,
            description.grid.cell_size_m,
            TileLayout::new(description.grid.side, write.tile_cells)?,
        )?),
        None => None,
    };
    let (staging, tiles) = pyramid::start_build(out, &description, &write)?;
    let bar = crate::progress::pass_bar();
    let imagery_source = imagery.as_ref().map(|i| i as &dyn DrapeSource);
    let report = pyramid::build::build(
        heights.source(),
        imagery_source,
        &tiles,
        &write.build,
        &|p| crate::progress::show_pass(&bar, p),
    )?;
    bar.finish_and_clear();
    let pyramid_ms = start.elapsed().as_secs_f64() * 1e3;
    let start = Instant::now();
    let mut extras = StagedFiles::new(staging.dir());
    let ground = TiledGround::new(heights.source(), tiles.layout, description.grid.cell_size_m);
    let vegetation = vegetation(region, &dem, &description, &ground, &mut extras)?;
    let vegetation_ms = start.elapsed().as_secs_f64() * 1e3;
    let bundle = pyramid::seal_build(staging, tiles, report, description, &write, extras, &|p| {
        store::validate(p)
    })?;
    let mut summary = TiledSummary::of(bundle, read_by_windows, grid_ms, pyramid_ms)?;
    if let Some((objects, clusters)) = vegetation {
        summary.vegetation = Some(objects);
        summary.clusters = Some(clusters);
    }
    summary.vegetation_ms = vegetation_ms;
    Ok(summary)
}

/// The region's vegetation, when it has a `[vegetation]` section: detected
/// on its imagery cropped to the DEM whose grid is `dem` (as a single-grid
/// `prep` detects it), its clusters baked standing on `ground`; the
/// database, its samples and the clusters written into `extras`. Returns
/// the database's size and what the clusters hold.
fn vegetation(
    region: &RegionSpec,
    dem: &GridSpec,
    description: &PyramidDescription,
    ground: &TiledGround,
    extras: &mut StagedFiles,
) -> Result<Option<(usize, ClustersSummary)>> {
    let (Some(section), Some(image)) = (&region.vegetation, &region.image) else {
        return Ok(None);
    };
    let (rgba, grid, _) = imagery_drape(image, dem)?;
    let (_, extraction, samples_csv) = detect_on_drape(section, image, &rgba, &grid)?;
    drop(rgba);
    extras.write_vegetation(&extraction.objects)?;
    extras.write_vegetation_samples(&samples_csv)?;
    let clusters = region.clusters.clone().unwrap_or_default();
    let g = &description.grid;
    let frame = relevo_core::geo::TerrainFrame {
        side: g.side,
        cell_size_m: g.cell_size_m,
        geotransform: g.geotransform,
    };
    // From the database as stored (millimetres), as a single-grid bundle's.
    let database = db::as_stored(&extraction.objects);
    let (baked, off_terrain) = bake_with_progress(
        &database,
        &frame,
        ground,
        &clusters.models,
        &clusters.options,
    )?;
    store::write(extras, &baked, &clusters.options, off_terrain)?;
    Ok(Some((
        extraction.objects.len(),
        ClustersSummary::of(&baked),
    )))
}

impl TiledSummary {
    /// What the pyramid written at `bundle` reports, with how its heights
    /// were read and the grid's and the pyramid's wall times, ms (the
    /// vegetation, when prepared with it, is its caller's to fill in).
    pub fn of(
        bundle: PathBuf,
        read_by_windows: bool,
        grid_ms: f64,
        pyramid_ms: f64,
    ) -> Result<TiledSummary> {
        let opened = pyramid::Pyramid::open(&bundle)?;
        let m = &opened.manifest;
        Ok(TiledSummary {
            vegetation: None,
            clusters: None,
            vegetation_ms: 0.0,
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
        tile_cells: options
            .tile_cells
            .unwrap_or_else(|| default_tile_cells(description.grid.side)),
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

/// Where the pyramid's heights come from, its description and the DEM's
/// grid before it was squared (what imagery is cropped to): a single DEM on
/// the target grid whose voids are holes the fill stage fills is read
/// window by window (the tiling, memory and disk checked before the file
/// is scanned); anything else goes through the in-memory grid stages.
pub fn height_source(
    region: &RegionSpec,
    name: &str,
    out: &Path,
    tile_cells: Option<usize>,
    resume: bool,
) -> Result<(Heights, PyramidDescription, GridSpec)> {
    if let Some(mut d) = DirectSource::open(region)? {
        let tile_cells = tile_cells.unwrap_or_else(|| default_tile_cells(d.grid.side));
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
            let dem = d.dem_grid();
            return Ok((Heights::Windows(d), description, dem));
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
    Ok((Heights::Grid(grid), description, dem.grid))
}
