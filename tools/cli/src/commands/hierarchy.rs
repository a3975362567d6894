//! `relevo hierarchy`: LP errors and radii of a (2^n+1)² heightfield as a GeoTIFF.

use super::args::ErrorMetricArg;
use crate::ingest::gdalio;
use crate::output;
use anyhow::{bail, Result};
use clap::Args;
use gdal::raster::GdalDataType;
use relevo_core::raster::Raster;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct HierarchyArgs {
    /// Square (2^n+1)² heights in metres, e.g. from `relevo pad`.
    pub input: PathBuf,
    /// Output GeoTIFF: band 1 error δ, band 2 radius r, metres.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Vertex spacing in metres; default: the input's cell size.
    #[arg(long)]
    pub cell_size: Option<f64>,
    /// How vertex errors are measured.
    #[arg(long, value_enum, default_value_t = ErrorMetricArg::Bound)]
    pub error_metric: ErrorMetricArg,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

pub fn run(a: HierarchyArgs) -> Result<()> {
    output::check(&[&a.out], a.force)?;
    let (raster, grid, _, _) = gdalio::read_single_band(&a.input, None)?;
    let side = raster.width;
    if raster.height != side || side < 3 || !(side - 1).is_power_of_two() {
        bail!(
            "{}: {}×{} cells; the hierarchy needs a square (2^n+1)² grid (run `relevo pad` first)",
            a.input.display(),
            raster.width,
            raster.height
        );
    }
    if raster.valid_count() != raster.cells() {
        bail!(
            "{}: has no-data cells; fill or pad it first",
            a.input.display()
        );
    }
    let (cx, cy) = grid.geotransform.cell_size();
    let cell = match a.cell_size {
        Some(c) if c.is_finite() && c > 0.0 => c,
        Some(c) => bail!("--cell-size must be positive, got {c}"),
        None if (cx - cy).abs() <= 1e-9 * cx => cx,
        None => bail!(
            "{}: cells are {cx} × {cy}, not square; pass --cell-size",
            a.input.display()
        ),
    };
    let heights: Vec<f32> = raster.band(0).iter().map(|&v| v as f32).collect();
    let h = relevo_core::lp::Hierarchy::compute(&heights, side, cell, a.error_metric.into());
    let data = h
        .error_radius
        .iter()
        .map(|e| e[0] as f64)
        .chain(h.error_radius.iter().map(|e| e[1] as f64))
        .collect();
    let out = Raster::from_data(side, side, 2, data);
    gdalio::write_geotiff(&a.out, &out, &grid, GdalDataType::Float32, None)?;
    let max_error = h.error_radius.iter().map(|e| e[0]).fold(0.0, f32::max);
    eprintln!(
        "{}: {side}×{side} vertices, largest error {max_error:.3} m",
        a.out.display()
    );
    Ok(())
}
