//! `relevo prep`: build a bundle from a REGION.toml or straight from rasters.

use super::args::{parse_percentiles, EncodingArg, ErrorMetricArg};
use crate::ingest::gdalio::Resampling;
use crate::output;
use crate::prep::prep;
use crate::prep::region::{
    parse_nodata, DemSection, FillSection, GridSection, ImageSection, NoData, RegionSpec,
    VegetationSection,
};
use crate::prep::tiled::{prep_tiled, TiledOptions};
use anyhow::{bail, Result};
use clap::Args;
use relevo_core::raster::mosaic::Overlap;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct PrepArgs {
    /// REGION.toml describing the inputs (or give --dem instead).
    #[arg(required_unless_present = "dem", conflicts_with_all = ["dem", "image"])]
    pub region: Option<PathBuf>,
    /// Output bundle directory, conventionally NAME.relevo.
    #[arg(long, short)]
    pub out: PathBuf,
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
    /// first. The drape is derived from
    /// the heights.
    #[arg(long)]
    pub tiled: bool,
    /// With --tiled: cells a tile side, a power of two 16–4096 (tiles have
    /// one more vertex a side).
    #[arg(long, default_value_t = relevo_core::pyramid::DEFAULT_TILE_CELLS, requires = "tiled")]
    pub tile_size: usize,
    /// With --tiled: go on from the build a killed `prep` left beside --out.
    #[arg(long, requires = "tiled")]
    pub resume: bool,
    /// Replace an existing bundle.
    #[arg(long)]
    pub force: bool,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: PrepArgs) -> Result<()> {
    if a.bands.as_ref().is_some_and(|b| b.len() != 3) {
        bail!("--bands takes three bands R,G,B, e.g. 3,2,1");
    }
    let region = match &a.region {
        Some(path) => RegionSpec::load(path)?,
        None => {
            let region = RegionSpec {
                name: None,
                crs: a.crs,
                cell_size_m: a.cell_size,
                z_scale: a.z_scale,
                dem: DemSection {
                    files: a.dem,
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
                    files: a.image,
                    bands: a.bands.map(|b| [b[0], b[1], b[2]]),
                    src_nodata: None,
                    overlap: Overlap::Blend,
                    resampling: Resampling::Bilinear,
                    stretch: a.stretch,
                }),
                terrain_drape: a.terrain_drape,
                vegetation: a.samples.map(|samples| VegetationSection {
                    samples,
                    options: Default::default(),
                }),
                clusters: None,
            };
            region.check()?;
            region
        }
    };
    // Only the folder is checked here: the bundle writer decides what an
    // existing bundle at `--out` needs (`--force`).
    output::check(&[&a.out], true)?;
    if a.tiled {
        let options = TiledOptions {
            tile_cells: a.tile_size,
            force: a.force,
            resume: a.resume,
        };
        let s = prep_tiled(&region, &a.out, options)?;
        if a.json {
            println!("{}", serde_json::to_string(&s)?);
        } else {
            println!(
                "{}: pyramid of a {}×{} grid, {:.2} m cells, {} levels of tiles of {} cells ({} tiles), \
                 {} vertices with data, heights {:.1}..{:.1} m, {:.0} ms",
                s.bundle.display(),
                s.side,
                s.side,
                s.cell_size_m,
                s.levels,
                s.tile_cells,
                s.tiles,
                s.valid_vertices,
                s.height_range_m[0],
                s.height_range_m[1],
                s.grid_ms + s.pyramid_ms
            );
        }
        return Ok(());
    }
    let summary = prep(&region, &a.out, a.force)?;
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
