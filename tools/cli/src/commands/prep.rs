//! `relevo prep`: build a bundle from a REGION.toml or straight from rasters.

use super::args::{parse_percentiles, EncodingArg, ErrorMetricArg, PlanArgs};
use crate::ingest::gdalio::Resampling;
use crate::output;
use crate::prep::plan::{self, PlanOptions};
use crate::prep::prep;
use crate::prep::region::{
    parse_nodata, DemSection, FillSection, GridSection, ImageSection, NoData, RegionSpec,
    VegetationSection,
};
use crate::prep::tiled::{prep_tiled, TiledOptions, TiledSummary};
use anyhow::{bail, Context, Result};
use clap::Args;
use relevo_core::raster::mosaic::Overlap;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct PrepArgs {
    /// REGION.toml describing the inputs (or give --dem instead).
    #[arg(required_unless_present_any = ["dem", "plan"], conflicts_with_all = ["dem", "image"])]
    pub region: Option<PathBuf>,
    /// Output bundle directory, conventionally NAME.relevo.
    #[arg(long, short, required_unless_present = "plan")]
    pub out: Option<PathBuf>,
    /// DEM tiles (quick form, without a REGION.toml).
    #[arg(long, num_args = 1..)]
    pub dem: Vec<PathBuf>,
    /// Imagery tiles to drape (quick form).
    #[arg(long, num_args = 1..)]
    pub image: Vec<PathBuf>,
    /// Without imagery: drape a hypsometric tint with a baked hillshade
    /// derived from the heights (quick form).
    #[arg(long, conflicts_with = "image")]
    pub terrain_drape: bool,
    /// Image bands shown as red, green, blue (quick form), e.g. 3,2,1.
    #[arg(long, value_delimiter = ',', value_name = "R,G,B")]
    pub bands: Option<Vec<usize>>,
    /// Percentiles LOW,HIGH of each image band stretched to 0..255 (quick form).
    #[arg(long, value_name = "LOW,HIGH", value_parser = parse_percentiles, requires = "image")]
    pub stretch: Option<[f64; 2]>,
    /// Vegetation samples marked on the first image (quick form; see `veg detect`).
    #[arg(long, requires = "image")]
    pub samples: Option<PathBuf>,
    /// DEM encoding (quick form).
    #[arg(long, value_enum, default_value_t = EncodingArg::Plain)]
    pub encoding: EncodingArg,
    /// Bundle CRS (quick form).
    #[arg(long)]
    pub crs: Option<String>,
    /// Grid spacing in metres (quick form).
    #[arg(long)]
    pub cell_size: Option<f64>,
    /// Factor from the DEM's vertical unit to metres (quick form).
    #[arg(long, default_value_t = 1.0)]
    pub z_scale: f64,
    /// DEM no-data value, a number or nan (quick form).
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub src_nodata: Option<f64>,
    /// How vertex errors are measured (quick form): `bound` makes
    /// `mesh --max-error` a true bound; `midpoint` gives martini's meshes.
    #[arg(long, value_enum, default_value_t = ErrorMetricArg::Bound)]
    pub error_metric: ErrorMetricArg,
    /// Write a pyramid bundle: tiles on the LP hierarchy, errors and radii
    /// computed tile by tile in bounded memory (see docs/guide.md, "Large
    /// regions"). A single DEM on a projected grid of square cells, whose
    /// voids are holes the fill stage fills, is read window by window and
    /// never held whole; other inputs are stitched and filled in memory
    /// first. The tiles' drape is the imagery (one file, read tile by
    /// tile) or, without it, derived from the heights; with [vegetation]
    /// the vegetation is detected on the imagery and its clusters stand on
    /// the tiles.
    #[arg(long)]
    pub tiled: bool,
    /// With --tiled: cells a tile side, a power of two 16–4096 (tiles have
    /// one more vertex a side). Default: 512, or the whole grid in one tile
    /// when it is smaller.
    #[arg(long, requires = "tiled")]
    pub tile_size: Option<usize>,
    /// With --tiled: go on from the build a killed `prep` left beside --out.
    #[arg(long, requires = "tiled")]
    pub resume: bool,
    #[command(flatten)]
    pub plan: PlanArgs,
    /// Replace an existing bundle (and, with --plan, an existing plan).
    #[arg(long)]
    pub force: bool,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: PrepArgs) -> Result<()> {
    if let (Some(dir), None, true) = (&a.plan.plan, &a.region, a.dem.is_empty()) {
        return run_plan(dir, &a);
    }
    if a.bands.as_ref().is_some_and(|b| b.len() != 3) {
        bail!("--bands takes three bands R,G,B, e.g. 3,2,1");
    }
    let region = match &a.region {
        Some(path) => RegionSpec::load(path)?,
        None => {
            let region = RegionSpec {
                name: None,
                crs: a.crs.clone(),
                cell_size_m: a.cell_size,
                z_scale: a.z_scale,
                dem: DemSection {
                    files: a.dem.clone(),
                    encoding: a.encoding.into(),
                    src_nodata: a.src_nodata.map(NoData::Value),
                    overlap: Overlap::Blend,
                    resampling: Resampling::Bilinear,
                },
                fill: FillSection::default(),
                grid: GridSection {
                    error_metric: a.error_metric.into(),
                    ..GridSection::default()
                },
                image: (!a.image.is_empty()).then(|| ImageSection {
                    files: a.image.clone(),
                    bands: a.bands.clone().map(|b| [b[0], b[1], b[2]]),
                    src_nodata: None,
                    overlap: Overlap::Blend,
                    resampling: Resampling::Bilinear,
                    stretch: a.stretch,
                }),
                terrain_drape: a.terrain_drape,
                vegetation: a.samples.clone().map(|samples| VegetationSection {
                    samples,
                    options: Default::default(),
                }),
                clusters: None,
            };
            region.check()?;
            region
        }
    };
    let out = a.out.clone().context("--out is required")?;
    // Only the folder is checked here: the bundle writer decides what an
    // existing bundle at `--out` needs (`--force`).
    output::check(&[&out], true)?;
    if let Some(dir) = &a.plan.plan {
        if !a.tiled {
            bail!("--plan builds a pyramid: add --tiled");
        }
        if a.plan.job.is_some() || a.plan.finish || a.resume {
            bail!("--job, --finish and --resume act on a plan already made: give --plan alone");
        }
        let options = PlanOptions {
            tile_cells: a.tile_size,
            jobs_per_step: a.plan.jobs,
            force: a.force,
        };
        let p = plan::create(&region, &out, dir, options)?;
        let jobs: usize = p.steps.iter().map(|s| s.jobs[1] - s.jobs[0] + 1).sum();
        if !a.json {
            println!(
                "{}: a plan of {jobs} jobs in {} steps building {} ({}×{} grid, tiles of {} cells)",
                dir.display(),
                p.steps.len(),
                p.out.display(),
                p.description.grid.side,
                p.description.grid.side,
                p.write.tile_cells
            );
            for s in &p.steps {
                println!(
                    "  {:>18}: jobs {:>4}–{:<4} tiles: {}",
                    s.name, s.jobs[0], s.jobs[1], s.tiles
                );
            }
        }
        if a.plan.submit.is_some() {
            return run_plan(dir, &a);
        }
        if a.json {
            println!("{}", serde_json::to_string(&p.steps)?);
        } else {
            println!(
                "run each job with `relevo prep --plan {0} --job K`, step after step, or \
                 `relevo prep --plan {0} --submit slurm`; then `relevo prep --plan {0} --finish`",
                dir.display()
            );
        }
        return Ok(());
    }
    if a.tiled {
        let options = TiledOptions {
            tile_cells: a.tile_size,
            force: a.force,
            resume: a.resume,
        };
        let s = prep_tiled(&region, &out, options)?;
        return print_tiled(&s, a.json);
    }
    let summary = prep(&region, &out, a.force)?;
    if a.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        let total: f64 = summary.timings.iter().map(|t| t.ms).sum();
        println!(
            "{}: {}×{} grid, {:.2} m cells, {} vertices with data, heights {:.1}..{:.1} m, {:.0} ms",
            summary.bundle.display(),
            summary.side,
            summary.side,
            summary.cell_size_m,
            summary.valid_vertices,
            summary.height_range_m[0],
            summary.height_range_m[1],
            total
        );
    }
    Ok(())
}

/// `n` and `noun`, plural unless `n` is 1.
fn count(n: usize, noun: &str) -> String {
    match n {
        1 => format!("1 {noun}"),
        _ => format!("{n} {noun}s"),
    }
}

/// Print what a pyramid build reports.
fn print_tiled(s: &TiledSummary, json: bool) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string(s)?);
    } else {
        println!(
            "{}: pyramid of a {}×{} grid, {:.2} m cells, {} of tiles of {} cells ({}), \
             {} vertices with data, heights {:.1}..{:.1} m, {:.0} ms",
            s.bundle.display(),
            s.side,
            s.side,
            s.cell_size_m,
            count(s.levels as usize, "level"),
            s.tile_cells,
            count(s.tiles, "tile"),
            s.valid_vertices,
            s.height_range_m[0],
            s.height_range_m[1],
            s.grid_ms + s.pyramid_ms
        );
        if let (Some(objects), Some(c)) = (s.vegetation, &s.clusters) {
            println!(
                "  vegetation: {objects} objects, {} standing on the terrain in {} cluster nodes \
                 ({} baked, {} atlas pages, {:.1} MiB), {:.0} ms",
                c.objects,
                c.nodes,
                c.baked_nodes,
                c.pages,
                c.atlas_bytes as f64 / (1u64 << 20) as f64,
                s.vegetation_ms
            );
        }
    }
    Ok(())
}

/// `--plan DIR` with `--job`, `--finish` or `--submit`.
fn run_plan(dir: &Path, a: &PrepArgs) -> Result<()> {
    let p = &a.plan;
    if let Some(k) = p.job {
        let r = plan::run_job(dir, k)?;
        if a.json {
            println!("{}", serde_json::to_string(&r)?);
        } else {
            println!(
                "job {} ({}): {} of its {} tiles computed in {:.1} s",
                r.job,
                r.step,
                r.computed,
                r.tiles,
                r.ms / 1e3
            );
        }
        return Ok(());
    }
    if p.finish {
        return print_tiled(&plan::finish(dir)?, a.json);
    }
    let plan = plan::Plan::load(dir)?;
    if p.status {
        return p.print_status(dir, &plan, a.json);
    }
    p.submit_to(dir, &plan, a.json)
}
