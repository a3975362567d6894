//! `relevo fill`: fill no-data holes by natural-neighbour interpolation.

use crate::ingest::gdalio;
use crate::output;
use crate::prep::region::{parse_nodata, FillSection};
use anyhow::Result;
use clap::Args;
use gdal::raster::GdalDataType;
use relevo_core::raster::fill::fill_holes;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct FillArgs {
    /// Heights with no-data holes (band 1 is used).
    pub input: PathBuf,
    /// Output GeoTIFF.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Largest hole filled, in cells; larger holes stay no-data.
    #[arg(long, default_value_t = FillSection::default().max_hole_cells)]
    pub max_hole: usize,
    /// Source no-data value (a number or nan), overriding the file's.
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub src_nodata: Option<f64>,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

pub fn run(a: FillArgs) -> Result<()> {
    output::check(&[&a.out], a.force)?;
    let (mut raster, grid, band_type, nodata) = gdalio::read_single_band(&a.input, a.src_nodata)?;
    let (w, h) = (raster.width, raster.height);
    let report = fill_holes(raster.band_mut(0), w, h, a.max_hole);
    let band_type = if gdalio::is_float(band_type) {
        band_type
    } else {
        GdalDataType::Float32
    };
    let nodata = nodata.unwrap_or_else(|| gdalio::default_nodata(band_type));
    gdalio::write_geotiff(&a.out, &raster, &grid, band_type, Some(nodata))?;
    eprintln!(
        "{}: filled {} hole(s), {} cells; left {} hole(s), {} cells (larger than {} cells or open to the edge)",
        a.out.display(),
        report.holes_filled,
        report.cells_filled,
        report.holes_left,
        report.cells_left,
        a.max_hole
    );
    Ok(())
}
