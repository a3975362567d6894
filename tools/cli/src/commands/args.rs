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

/// Renders at named cameras (`relevo check --bless`, `relevo diff`).
#[derive(clap::Args, Debug)]
pub struct NamedCameras {
    /// A render of relevo-core's raycaster at NAME=X,Y,Z,HEADING[,PITCHdeg][,INCL]
    /// (repeatable).
    #[arg(
        long = "camera",
        value_name = "NAME=CAMERA",
        allow_hyphen_values = true
    )]
    pub cameras: Vec<String>,
    /// Size of those renders, WIDTHxHEIGHT.
    #[arg(long, default_value = "480x270", value_parser = relevo_core::scene::parse_size)]
    pub render_size: [u32; 2],
}

impl NamedCameras {
    /// The renders asked for (their files left for the caller to name).
    pub fn renders(&self) -> anyhow::Result<Vec<relevo_core::golden::RenderRecord>> {
        self.cameras
            .iter()
            .map(|spec| named_camera(spec, self.render_size))
            .collect()
    }
}

/// One `--camera NAME=CAMERA`.
fn named_camera(spec: &str, size: [u32; 2]) -> anyhow::Result<relevo_core::golden::RenderRecord> {
    let (name, camera) = spec
        .split_once('=')
        .filter(|(n, _)| {
            !n.is_empty()
                && n
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        })
        .ok_or_else(|| {
            anyhow::anyhow!(
                "--camera {spec:?}: expected NAME=X,Y,Z,HEADING with NAME of letters, digits, _ or -"
            )
        })?;
    relevo_core::scene::CameraPose::parse(camera)
        .map_err(|e| anyhow::anyhow!("--camera {name}: {e}"))?;
    Ok(relevo_core::golden::RenderRecord {
        name: name.to_string(),
        camera: camera.to_string(),
        size,
        file: String::new(),
    })
}
