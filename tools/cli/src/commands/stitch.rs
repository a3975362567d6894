//! `relevo stitch`: mosaic georeferenced tiles into one GeoTIFF.

use super::args::EncodingArg;
use crate::ingest::gdalio::{self, Resampling};
use crate::ingest::stitch::{stitch, StitchOptions};
use crate::output;
use crate::prep::region::parse_nodata;
use anyhow::{bail, Result};
use clap::Args;
use relevo_core::raster::mosaic::Overlap;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct StitchArgs {
    /// Input tiles, in priority order for --overlap first/last.
    #[arg(required = true)]
    pub tiles: Vec<PathBuf>,
    /// Output GeoTIFF.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Target CRS (EPSG:n, WKT, PROJ); default: the first tile's.
    #[arg(long = "t-srs")]
    pub t_srs: Option<String>,
    /// Target cell size: one value for square cells, or X,Y.
    #[arg(long, value_delimiter = ',', value_name = "X[,Y]")]
    pub tr: Option<Vec<f64>>,
    /// Target extent in target CRS units.
    #[arg(long, num_args = 4, value_names = ["XMIN", "YMIN", "XMAX", "YMAX"], allow_negative_numbers = true)]
    pub te: Option<Vec<f64>>,
    #[command(flatten)]
    pub common: TileArgs,
    /// No-data value written to the output.
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub dst_nodata: Option<f64>,
    /// Bands to keep, 1-based (e.g. 3,2,1).
    #[arg(long, value_delimiter = ',')]
    pub bands: Option<Vec<usize>>,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
}

/// Options shared by every command that reads tiles.
#[derive(Args, Debug, Clone)]
pub struct TileArgs {
    /// Resampling kernel when tiles are warped.
    #[arg(long, short = 'r', value_enum, default_value_t = Resampling::Nearest)]
    pub resampling: Resampling,
    /// Source no-data value (a number or nan), overriding the files'.
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub src_nodata: Option<f64>,
    /// How overlapping tiles combine.
    #[arg(long, value_enum, default_value_t = OverlapArg::Blend)]
    pub overlap: OverlapArg,
    /// How tiles encode heights.
    #[arg(long, value_enum, default_value_t = EncodingArg::Plain)]
    pub encoding: EncodingArg,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum OverlapArg {
    First,
    Last,
    Blend,
}

impl From<OverlapArg> for Overlap {
    fn from(o: OverlapArg) -> Overlap {
        match o {
            OverlapArg::First => Overlap::First,
            OverlapArg::Last => Overlap::Last,
            OverlapArg::Blend => Overlap::Blend,
        }
    }
}

pub fn run(a: StitchArgs) -> Result<()> {
    output::check(&[&a.out], a.force)?;
    if a.tr.as_ref().is_some_and(|v| v.len() > 2) {
        bail!("--tr takes X or X,Y");
    }
    let resolution = a.tr.map(|v| (v[0], *v.get(1).unwrap_or(&v[0])));
    let opts = StitchOptions {
        target_crs: a.t_srs,
        resolution,
        extent: a.te.map(|v| [v[0], v[1], v[2], v[3]]),
        resampling: a.common.resampling,
        src_nodata: a.common.src_nodata,
        dst_nodata: a.dst_nodata,
        overlap: a.common.overlap.into(),
        encoding: a.common.encoding.into(),
        bands: a.bands,
    };
    let m = stitch(&a.tiles, &opts)?;
    if m.raster.bands == 1 {
        // One band: heights (imagery has three or more).
        let names: Vec<String> = a.tiles.iter().map(|f| f.display().to_string()).collect();
        gdalio::check_heights(&m.raster, &names.join(", "))?;
    }
    gdalio::write_geotiff(&a.out, &m.raster, &m.grid, m.band_type, Some(m.nodata))?;
    eprintln!(
        "{}: {}×{} cells, {} band(s), {} of {} cells with data",
        a.out.display(),
        m.grid.width,
        m.grid.height,
        m.raster.bands,
        m.raster.valid_count(),
        m.raster.cells()
    );
    Ok(())
}
