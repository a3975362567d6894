//! `relevo pad`: square a heightfield to (2^n+1)² and write its data mask.

use crate::ingest::gdalio::{self, GridSpec};
use crate::output;
use crate::prep::region::parse_nodata;
use anyhow::{bail, Result};
use clap::Args;
use gdal::raster::GdalDataType;
use relevo_core::grid::{HeightGrid, Squaring};
use relevo_core::raster::Raster;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct PadArgs {
    /// Heights to square (band 1 is used).
    pub input: PathBuf,
    /// Output heights, (2^n+1)², Float32.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Output mask (1 = data, 0 = padding or no-data); default: OUT with _mask before the extension.
    #[arg(long)]
    pub mask_out: Option<PathBuf>,
    /// Resample to the nearest 2^n+1 instead of padding.
    #[arg(long)]
    pub resample: bool,
    /// Source no-data value (a number or nan), overriding the file's.
    #[arg(long, value_parser = parse_nodata, allow_negative_numbers = true)]
    pub src_nodata: Option<f64>,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

pub fn run(a: PadArgs) -> Result<()> {
    let mask_out = a.mask_out.clone().unwrap_or_else(|| {
        let stem = a
            .out
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        a.out.with_file_name(format!("{stem}_mask.tif"))
    });
    output::check(&[&a.out, &mask_out], a.force)?;
    let (raster, grid, _, _) = gdalio::read_single_band(&a.input, a.src_nodata)?;
    if raster.width < 2 || raster.height < 2 {
        bail!(
            "{}: {}×{} cells; a heightfield needs at least 2×2",
            a.input.display(),
            raster.width,
            raster.height
        );
    }
    let squaring = if a.resample {
        Squaring::Resample
    } else {
        Squaring::Pad
    };
    let g = HeightGrid::square(
        raster.band(0),
        raster.width,
        raster.height,
        grid.geotransform,
        squaring,
    );
    let spec = GridSpec {
        geotransform: g.geotransform,
        width: g.side,
        height: g.side,
        ..grid
    };
    let heights = Raster::from_data(
        g.side,
        g.side,
        1,
        g.heights.iter().map(|&h| h as f64).collect(),
    );
    let mask = Raster::from_data(
        g.side,
        g.side,
        1,
        g.mask.iter().map(|&m| m as f64).collect(),
    );
    gdalio::write_geotiff(&a.out, &heights, &spec, GdalDataType::Float32, None)?;
    gdalio::write_geotiff(&mask_out, &mask, &spec, GdalDataType::UInt8, None)?;
    eprintln!(
        "{}: {}×{} ({} of {} vertices with data); mask in {}",
        a.out.display(),
        g.side,
        g.side,
        g.valid_count(),
        g.side * g.side,
        mask_out.display()
    );
    Ok(())
}
