//! Argument types and parsers that several subcommands share.

use relevo_core::lp::ErrorMetric;
use relevo_core::raster::encoding::Encoding;

/// How tiles encode heights.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum EncodingArg {
    Plain,
    TerrainRgb,
    Terrarium,
}

impl From<EncodingArg> for Encoding {
    fn from(e: EncodingArg) -> Encoding {
        match e {
            EncodingArg::Plain => Encoding::Plain,
            EncodingArg::TerrainRgb => Encoding::TerrainRgb,
            EncodingArg::Terrarium => Encoding::Terrarium,
        }
    }
}

/// How the hierarchy measures a vertex's own error (relevo-core's
/// `ErrorMetric`).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum ErrorMetricArg {
    /// The largest vertical distance from the grid points a vertex's
    /// triangles cover: `mesh --max-error` is then a true bound.
    Bound,
    /// The vertex's height against its hypotenuse's midpoint, as
    /// @mapbox/martini (its meshes, vertex for vertex).
    Midpoint,
}

impl From<ErrorMetricArg> for ErrorMetric {
    fn from(m: ErrorMetricArg) -> ErrorMetric {
        match m {
            ErrorMetricArg::Bound => ErrorMetric::Bound,
            ErrorMetricArg::Midpoint => ErrorMetric::Midpoint,
        }
    }
}

/// `LOW,HIGH` percentiles with 0 ≤ LOW < HIGH ≤ 100.
pub(crate) fn parse_percentiles(text: &str) -> Result<[f64; 2], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{text:?} is not two numbers"))?;
    match values[..] {
        [lo, hi] if (0.0..100.0).contains(&lo) && lo < hi && hi <= 100.0 => Ok([lo, hi]),
        _ => Err("--stretch takes LOW,HIGH percentiles with 0 <= LOW < HIGH <= 100".into()),
    }
}
