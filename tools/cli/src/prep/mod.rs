//! `relevo prep`: the whole chain from raw rasters to a bundle.
//!
//! The chain is the list `STAGES`; each stage is a function that reads what
//! earlier stages left in `Build` and adds its own results. Adding a stage is
//! writing one such function and listing it.

mod direct;
mod drape;
pub mod plan;
pub mod region;
pub mod tiled;

use crate::clusters::{bake_with_progress, ClustersSummary};
use crate::ingest::crs;
use crate::ingest::gdalio::{self, GridSpec};
use crate::ingest::stitch::{stitch, Mosaic, StitchOptions};
use crate::veg_io;
use anyhow::{bail, Context, Result};
use gdal::raster::GdalDataType;
use gdal::spatial_ref::SpatialRef;
use region::{ImageSection, RegionSpec, VegetationSection};
use relevo_core::bundle::names;
use relevo_core::bundle::{
    sha256_file, Bundle, BundleWriter, ColorInfo, Crs, Description, GridInfo, InputFile,
    StageTiming,
};
use relevo_core::bundle::{MAX_IMAGE_SIDE, MAX_SIDE};
use relevo_core::cluster::bake::BakeOptions;
use relevo_core::cluster::{store, Clusters};
use relevo_core::geo::{GeoTransform, TerrainFrame};
use relevo_core::grid::{pow2_plus_1_at_least, pow2_plus_1_nearest, HeightGrid, Squaring};
use relevo_core::horizon::Terrain;
use relevo_core::lp::Hierarchy;
use relevo_core::raster::fill::{fill_holes, FillReport};
use relevo_core::raster::stretch::{stretch_or_default, to_rgba8};
use relevo_core::raster::tint::terrain_drape;
use relevo_core::raster::Raster;
use relevo_core::veg::db;
use relevo_core::veg::pipeline::{self, Extraction, VegImage};
use relevo_core::veg::samples;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One stage: reads what earlier stages left in [`Build`], adds its results.
type Stage = fn(&mut Build) -> Result<()>;

/// The stages of `prep`, in order.
const STAGES: &[(&str, Stage)] = &[
    ("dem", stage_dem),
    ("fill", stage_fill),
    ("grid", stage_grid),
    ("hierarchy", stage_hierarchy),
    ("drape", stage_drape),
    ("vegetation", stage_vegetation),
    ("clusters", stage_clusters),
    ("write", stage_write),
];

/// What `prep` reports when it is done (`--json` prints it).
#[derive(Debug, Serialize)]
pub struct Summary {
    pub bundle: PathBuf,
    pub region: String,
    pub side: usize,
    pub cell_size_m: f64,
    pub valid_vertices: usize,
    pub height_range_m: [f32; 2],
    pub fill: FillReport,
    pub color: Option<[usize; 2]>,
    /// Vegetation objects found, when the region has samples.
    pub vegetation: Option<usize>,
    /// The clusters baked from them.
    pub clusters: Option<ClustersSummary>,
    pub timings: Vec<StageTiming>,
}

/// State carried from stage to stage.
struct Build<'a> {
    region: &'a RegionSpec,
    name: String,
    /// The single-grid bundle being written (none for a pyramid, which is
    /// written after the grid stages).
    writer: Option<BundleWriter>,
    /// The DEM stitched onto the bundle's metric grid (heights in metres).
    dem: Option<Mosaic>,
    cell_size_m: f64,
    fill: FillReport,
    grid: Option<HeightGrid>,
    hierarchy: Option<Hierarchy<'static>>,
    /// The drape's grid and the source bands shown as R, G, B (0 for a
    /// drape derived from the terrain).
    color: Option<(GridSpec, [usize; 3])>,
    /// The drape as RGBA8, as written to `color.rgba8`.
    rgba: Vec<u8>,
    vegetation: Option<(VegImage, Extraction)>,
    /// The samples the vegetation was detected from, on the drape (the CSV
    /// the viewer's samples tab reads).
    samples_csv: Option<String>,
    /// The baked clusters, the objects left off the terrain, the options.
    clusters: Option<(Clusters, usize, BakeOptions)>,
}

impl<'a> Build<'a> {
    /// A build of `region` named `name` that no stage has run on yet.
    fn new(region: &'a RegionSpec, name: String, writer: Option<BundleWriter>) -> Build<'a> {
        Build {
            region,
            name,
            writer,
            dem: None,
            cell_size_m: 1.0,
            fill: FillReport::default(),
            grid: None,
            hierarchy: None,
            color: None,
            rgba: Vec::new(),
            vegetation: None,
            samples_csv: None,
            clusters: None,
        }
    }
}

/// Run every stage and move the finished bundle to `out`.
pub fn prep(region: &RegionSpec, out: &Path, force: bool) -> Result<Summary> {
    let name = region.name.clone().unwrap_or_else(|| {
        out.file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_else(|| "region".into())
    });
    let writer = Some(BundleWriter::create(out, force)?);
    let mut build = Build::new(region, name, writer);
    let mut timings = Vec::new();
    let bar = crate::progress::bar(STAGES.len() as u64, "prep");
    for (stage, run) in STAGES {
        bar.set_message(*stage);
        let start = Instant::now();
        run(&mut build).with_context(|| format!("stage {stage}"))?;
        let ms = start.elapsed().as_secs_f64() * 1e3;
        tracing::info!(stage, ms, "stage done");
        timings.push(StageTiming {
            stage: stage.to_string(),
            ms,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    finish(build, timings)
}

/// Stitch the DEM tiles onto the bundle's metric grid.
fn stage_dem(b: &mut Build) -> Result<()> {
    let r = b.region;
    let first = gdalio::open(&r.dem.files[0])?;
    let target: Option<SpatialRef> = match (&r.crs, &first.srs) {
        (Some(def), _) => Some(crs::parse(def)?),
        (None, Some(srs)) if srs.is_geographic() => {
            let geo = first.geotransform.unwrap_or(GeoTransform::IDENTITY);
            let (lon, lat) = geo.apply(first.width as f64 / 2.0, first.height as f64 / 2.0);
            let (mut xs, mut ys) = ([lon], [lat]);
            crs::transform_points(srs, &crs::wgs84()?, &mut xs, &mut ys)?;
            let utm = crs::utm_for(xs[0], ys[0])?;
            tracing::info!(
                epsg = crs::epsg(&utm),
                "geographic DEM: reprojecting to UTM"
            );
            Some(utm)
        }
        (None, srs) => srs.clone(),
    };
    if let Some(t) = &target {
        if t.is_geographic() {
            bail!("the bundle CRS must be projected (metric), not geographic");
        }
    }
    // Without georeferencing, cells are pixels and `cell_size_m` says how
    // large: a DEM that does not say where or how large it is is refused
    // unless told.
    let georeferenced = first.geotransform.is_some();
    if !georeferenced && r.cell_size_m.is_none() {
        bail!(
            "{}: not georeferenced (no geotransform), so its cell size is unknown; \
             pass --cell-size METRES (cell_size_m in REGION.toml) to place it",
            first.path.display()
        );
    }
    if first.srs.is_none() && georeferenced {
        tracing::warn!(
            "{}: no CRS; its coordinates are taken as metres",
            first.path.display()
        );
    }
    let mut opts = StitchOptions {
        target_crs: target.as_ref().map(crs::to_wkt).transpose()?,
        resolution: r.cell_size_m.filter(|_| georeferenced).map(|c| (c, c)),
        resampling: r.dem.resampling,
        src_nodata: r.dem.src_nodata.map(|n| n.value()),
        overlap: r.dem.overlap,
        encoding: r.dem.encoding,
        bands: Some(vec![1]),
        ..Default::default()
    };
    let mut dem = stitch(&r.dem.files, &opts)?;
    let (cx, cy) = dem.grid.geotransform.cell_size();
    if cx != cy {
        // The LP hierarchy needs square cells: stitch again at the finer spacing.
        opts.resolution = Some((cx.min(cy), cx.min(cy)));
        dem = stitch(&r.dem.files, &opts)?;
    }
    let names: Vec<String> = r
        .dem
        .files
        .iter()
        .map(|f| f.display().to_string())
        .collect();
    // Scaled first, so that the range check sees the heights written.
    if r.z_scale != 1.0 {
        dem.raster.data.iter_mut().for_each(|v| *v *= r.z_scale);
    }
    let source = match r.z_scale {
        1.0 => names.join(", "),
        z => format!("{} (with z_scale {z})", names.join(", ")),
    };
    gdalio::check_heights(&dem.raster, &source)?;
    if !georeferenced {
        let cell = r.cell_size_m.unwrap_or(1.0);
        dem.grid.geotransform = GeoTransform::north_up(0.0, 0.0, cell, cell);
    }
    let (w, h) = (dem.grid.width, dem.grid.height);
    if w < 2 || h < 2 {
        bail!(
            "{}: the DEM grid is {w}×{h} cells; a heightfield needs at least 2×2",
            r.dem.files[0].display()
        );
    }
    let metres_per_unit = target.as_ref().map_or(1.0, |t| t.linear_units());
    b.cell_size_m = dem.grid.geotransform.cell_size().0 * metres_per_unit;
    b.dem = Some(dem);
    Ok(())
}

/// Fill small no-data holes by natural-neighbour interpolation.
fn stage_fill(b: &mut Build) -> Result<()> {
    let dem = b.dem.as_mut().context("dem stage did not run")?;
    let (w, h) = (dem.raster.width, dem.raster.height);
    b.fill = fill_holes(dem.raster.band_mut(0), w, h, b.region.fill.max_hole_cells);
    tracing::info!(?b.fill, "filled holes");
    Ok(())
}

/// Square the DEM to (2^n+1)² with its mask.
fn stage_grid(b: &mut Build) -> Result<()> {
    let dem = b.dem.as_ref().context("dem stage did not run")?;
    let longer = dem.raster.width.max(dem.raster.height);
    let side = match b.region.grid.squaring {
        Squaring::Pad => pow2_plus_1_at_least(longer),
        Squaring::Resample => pow2_plus_1_nearest(longer),
    };
    if side > MAX_SIDE {
        bail!(
            "the {side}×{side} grid exceeds the largest a bundle holds ({MAX_SIDE}²): \
             choose a coarser cell size or a smaller extent"
        );
    }
    // Heights, mask, errors and radii, the shaded drape, the hierarchy's
    // working copy: about 25 bytes per vertex; for a pyramid, which writes
    // everything but the heights and mask tile by tile, 5.
    relevo_core::memory::check(
        &format!("the {side}×{side} grid"),
        (side * side) as u64,
        if b.writer.is_some() { 25 } else { 5 },
        "choose a coarser cell size or a smaller extent",
    )?;
    let grid = HeightGrid::square(
        dem.raster.band(0),
        dem.raster.width,
        dem.raster.height,
        dem.grid.geotransform,
        b.region.grid.squaring,
    );
    b.grid = Some(grid);
    Ok(())
}

/// Lindstrom–Pascucci errors and radii of every vertex.
fn stage_hierarchy(b: &mut Build) -> Result<()> {
    let grid = b.grid.as_ref().context("grid stage did not run")?;
    b.hierarchy = Some(Hierarchy::compute(
        &grid.heights,
        grid.side,
        b.cell_size_m,
        b.region.grid.error_metric,
    ));
    Ok(())
}

/// Bring the imagery onto the bundle CRS at its own resolution, cropped to the DEM.
fn stage_drape(b: &mut Build) -> Result<()> {
    let Some(image) = &b.region.image else {
        if b.region.terrain_drape {
            derive_drape(b)?;
        }
        return Ok(());
    };
    let dem = b.dem.as_ref().context("dem stage did not run")?;
    let (rgba, grid, bands) = imagery_drape(image, &dem.grid)?;
    b.rgba = rgba;
    b.color = Some((grid, bands));
    Ok(())
}

/// The imagery of `image` on the CRS of the DEM whose grid is `dem`, at the
/// imagery's own resolution, cropped to the DEM, stretched to RGBA8; with
/// its grid and the source bands shown as R, G, B.
pub fn imagery_drape(
    image: &ImageSection,
    dem: &GridSpec,
) -> Result<(Vec<u8>, GridSpec, [usize; 3])> {
    // Default: the first three bands, or grey from a single-band image.
    let bands = match image.bands {
        Some(b) => b,
        None if gdalio::open(&image.files[0])?.bands < 3 => [1, 1, 1],
        None => [1, 2, 3],
    };
    let opts = StitchOptions {
        target_crs: (!dem.crs_wkt.is_empty()).then(|| dem.crs_wkt.clone()),
        extent: Some(dem.geotransform.bounds(dem.width, dem.height)),
        resampling: image.resampling,
        src_nodata: image.src_nodata.map(|n| n.value()),
        overlap: image.overlap,
        bands: Some(bands.to_vec()),
        ..Default::default()
    };
    // With an extent but no resolution, stitch keeps the imagery's own cell size.
    let mosaic = stitch(&image.files, &opts)?;
    let (w, h) = (mosaic.grid.width, mosaic.grid.height);
    if w.max(h) > MAX_IMAGE_SIDE {
        bail!(
            "the {w}×{h} drape exceeds the largest a bundle holds ({MAX_IMAGE_SIDE} pixels a side): \
             resample the imagery coarser first"
        );
    }
    let rgba = to_rgba8(
        &mosaic.raster,
        stretch_or_default(image.stretch, mosaic.band_type == GdalDataType::UInt8),
    );
    Ok((rgba, mosaic.grid, bands))
}

/// The drape derived from the terrain: one pixel per grid vertex, on the
/// grid's own georeferencing.
fn derive_drape(b: &mut Build) -> Result<()> {
    let grid = b.grid.as_ref().context("grid stage did not run")?;
    let dem = b.dem.as_ref().context("dem stage did not run")?;
    let range = grid.height_range().context("the DEM has no valid data")?;
    b.rgba = terrain_drape(&grid.heights, &grid.mask, grid.side, b.cell_size_m, range);
    let spec = GridSpec {
        crs_wkt: dem.grid.crs_wkt.clone(),
        geotransform: grid.geotransform,
        width: grid.side,
        height: grid.side,
    };
    b.color = Some((spec, [0, 0, 0]));
    Ok(())
}

/// Extract vegetation from the drape, as the bundle shows it (8-bit RGB).
/// Samples are marked on the first image file; they are carried through its
/// georeferencing onto the drape.
fn stage_vegetation(b: &mut Build) -> Result<()> {
    let (Some(section), Some(image_section)) = (&b.region.vegetation, &b.region.image) else {
        return Ok(());
    };
    let (grid, _) = b.color.as_ref().context("drape stage did not run")?;
    let (image, extraction, samples_csv) = detect_on_drape(section, image_section, &b.rgba, grid)?;
    b.samples_csv = Some(samples_csv);
    b.vegetation = Some((image, extraction));
    Ok(())
}

/// Vegetation detected on `rgba`, the drape of `image_section` on `grid`,
/// from the samples of `section` (marked on the first image file, carried
/// through its georeferencing onto the drape). Returns the image analysed,
/// the extraction and the samples on the drape as CSV.
pub fn detect_on_drape(
    section: &VegetationSection,
    image_section: &ImageSection,
    rgba: &[u8],
    grid: &GridSpec,
) -> Result<(VegImage, Extraction, String)> {
    let image = VegImage::from_drape(
        rgba,
        grid.width,
        grid.height,
        grid.geotransform,
        &grid.crs_wkt,
    )?;

    let first = gdalio::open(&image_section.files[0])?;
    let Some(file_geo) = first.geotransform else {
        bail!(
            "{}: not georeferenced, so samples cannot be placed on the drape",
            first.path.display()
        );
    };
    let mut samples =
        samples::read_file(&section.samples, Some(file_geo), first.width, first.height)?;
    let drape_srs = (!grid.crs_wkt.is_empty())
        .then(|| SpatialRef::from_wkt(&grid.crs_wkt))
        .transpose()?;
    for sample in &mut samples {
        let (mut xs, mut ys): (Vec<f64>, Vec<f64>) = sample
            .polygon
            .iter()
            .map(|p| file_geo.apply(p[0], p[1]))
            .unzip();
        if let (Some(from), Some(to)) = (&first.srs, &drape_srs) {
            crs::transform_points(from, to, &mut xs, &mut ys)?;
        }
        for (p, (x, y)) in sample.polygon.iter_mut().zip(xs.into_iter().zip(ys)) {
            let (col, row) = grid
                .geotransform
                .invert(x, y)
                .context("the drape's geotransform cannot be inverted")?;
            *p = [col, row];
        }
        tracing::debug!(class = %sample.class, polygon = ?sample.polygon, "sample on the drape");
    }
    let extraction = pipeline::extract(&image, &samples, &section.options)
        .with_context(|| section.samples.display().to_string())?;
    tracing::info!(objects = extraction.objects.len(), "vegetation");
    let samples_csv = samples::to_csv(&samples, grid.width, grid.height);
    Ok((image, extraction, samples_csv))
}

/// Bake the vegetation clusters: class impostors from their models, the
/// quadtree's views, the atlases.
fn stage_clusters(b: &mut Build) -> Result<()> {
    let Some((_, extraction)) = &b.vegetation else {
        return Ok(());
    };
    let grid = b.grid.as_ref().context("grid stage did not run")?;
    let section = b.region.clusters.clone().unwrap_or_default();
    let frame = TerrainFrame {
        side: grid.side,
        cell_size_m: b.cell_size_m,
        geotransform: grid.geotransform,
    };
    // From the database as stored (millimetres), so that `relevo bake`
    // on the bundle reproduces these clusters byte for byte.
    let database = db::as_stored(&extraction.objects);
    let ground = Terrain::new(
        grid.side,
        b.cell_size_m,
        &grid.heights[..],
        &grid.mask[..],
        None,
    );
    let (clusters, off_terrain) = bake_with_progress(
        &database,
        &frame,
        &ground,
        &section.models,
        &section.options,
    )?;
    b.clusters = Some((clusters, off_terrain, section.options));
    Ok(())
}

/// Write the arrays and the GeoTIFF exports into the staging directory.
fn stage_write(b: &mut Build) -> Result<()> {
    let writer = b.writer.as_mut().context("the bundle writer is gone")?;
    let grid = b.grid.as_ref().context("grid stage did not run")?;
    let dem = b.dem.as_ref().context("dem stage did not run")?;
    let side = grid.side;
    writer.write_grid(grid)?;
    if let Some(h) = &b.hierarchy {
        writer.write_hierarchy(h)?;
    }

    let spec = GridSpec {
        crs_wkt: dem.grid.crs_wkt.clone(),
        geotransform: grid.geotransform,
        width: side,
        height: side,
    };
    let heights: Vec<f64> = grid
        .heights
        .iter()
        .zip(&grid.mask)
        .map(|(&h, &m)| if m == 1 { h as f64 } else { f64::NAN })
        .collect();
    let raster = Raster::from_data(side, side, 1, heights);
    let export = names::HEIGHT_GEOTIFF;
    gdalio::write_geotiff(
        &writer.export_path(export)?,
        &raster,
        &spec,
        GdalDataType::Float32,
        Some(-9999.0),
    )?;
    writer.record_export(export)?;

    if let Some((drape_grid, bands)) = &b.color {
        let rgba = &b.rgba;
        let (w, h) = (drape_grid.width, drape_grid.height);
        let info = ColorInfo {
            width: w,
            height: h,
            geotransform: drape_grid.geotransform,
            bands: *bands,
        };
        writer.write_drape(rgba, info)?;
        let bands: Vec<f64> = (0..4)
            .flat_map(|c| rgba.iter().skip(c).step_by(4).map(|&v| v as f64))
            .collect();
        let raster = Raster::from_data(w, h, 4, bands);
        let export = names::COLOR_GEOTIFF;
        gdalio::write_geotiff(
            &writer.export_path(export)?,
            &raster,
            drape_grid,
            GdalDataType::UInt8,
            None,
        )?;
        writer.record_export(export)?;
    }
    if let Some((image, extraction)) = &b.vegetation {
        writer.staged().write_vegetation(&extraction.objects)?;
        if let Some(csv) = &b.samples_csv {
            writer.staged().write_vegetation_samples(csv)?;
        }
        let export = names::VEGETATION_GEOPACKAGE;
        veg_io::write_gpkg(
            &writer.export_path(export)?,
            &extraction.objects,
            &image.crs_wkt,
        )?;
        writer.record_export(export)?;
        let export = names::VEGETATION_LABELS;
        veg_io::write_labels(&writer.export_path(export)?, image, extraction)?;
        writer.record_export(export)?;
    }
    if let Some((clusters, off_terrain, options)) = &b.clusters {
        store::write(writer.staged(), clusters, options, *off_terrain)?;
    }
    Ok(())
}

/// What a manifest records of where a bundle came from: the CRS, every
/// input file with its hash, and the region's parameters.
fn provenance(
    region: &RegionSpec,
    dem: &Mosaic,
) -> Result<(Crs, Vec<InputFile>, BTreeMap<String, serde_json::Value>)> {
    let (inputs, parameters) = provenance_of(region)?;
    let crs = Crs {
        wkt: dem.grid.crs_wkt.clone(),
        epsg: dem.srs.as_ref().and_then(crs::epsg),
    };
    Ok((crs, inputs, parameters))
}

/// Every input file of `region` with its hash, and its parameters (the
/// CRS is left to the caller, which knows the grid's).
fn provenance_of(
    region: &RegionSpec,
) -> Result<(Vec<InputFile>, BTreeMap<String, serde_json::Value>)> {
    let mut inputs = Vec::new();
    let mut record = |role: &str, paths: &[PathBuf]| -> Result<()> {
        for p in paths {
            let (bytes, sha256) = sha256_file(p)?;
            inputs.push(InputFile {
                role: role.into(),
                path: p.display().to_string(),
                bytes,
                sha256,
            });
        }
        Ok(())
    };
    record("dem", &region.dem.files)?;
    if let Some(image) = &region.image {
        record("image", &image.files)?;
    }
    let parameters: BTreeMap<String, serde_json::Value> = match serde_json::to_value(region)? {
        serde_json::Value::Object(map) => map.into_iter().collect(),
        _ => BTreeMap::new(),
    };
    Ok((inputs, parameters))
}

/// Write the manifest and move the bundle into place.
fn finish(b: Build, timings: Vec<StageTiming>) -> Result<Summary> {
    let grid = b.grid.context("grid stage did not run")?;
    let dem = b.dem.context("dem stage did not run")?;
    let grid_info = GridInfo::of(&grid, b.cell_size_m, b.region.z_scale)
        .context("the DEM has no valid data")?;
    let height_range_m = grid_info.height_range_m;
    let (crs, inputs, parameters) = provenance(b.region, &dem)?;
    let mut writer = b.writer.context("the bundle writer is gone")?;
    writer.describe(Description {
        region: b.name.clone(),
        crs,
        grid: grid_info,
        lp_error_metric: b.region.grid.error_metric,
        inputs,
        parameters,
        timings: timings.clone(),
    });
    let bundle = writer.commit_checked(&|b: &Bundle| store::validate(b))?;
    Ok(Summary {
        bundle,
        region: b.name,
        side: grid.side,
        cell_size_m: b.cell_size_m,
        valid_vertices: grid.valid_count(),
        height_range_m,
        fill: b.fill,
        color: b.color.as_ref().map(|(c, _)| [c.width, c.height]),
        vegetation: b.vegetation.as_ref().map(|(_, e)| e.objects.len()),
        clusters: b.clusters.as_ref().map(|(c, _, _)| ClustersSummary::of(c)),
        timings,
    })
}
