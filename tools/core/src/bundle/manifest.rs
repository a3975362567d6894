use crate::geo::GeoTransform;
use crate::lp::ErrorMetric;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Value of `manifest.format`.
pub const FORMAT: &str = "relevo-bundle";
/// Version of the bundle layout this crate writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// `manifest.json`: everything needed to interpret and verify a bundle.
/// Maps are ordered so that the file is stable for the same content.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub format_version: u32,
    /// Region name, from REGION.toml or the output file name.
    pub region: String,
    /// `relevo` version that wrote the bundle.
    pub tool_version: String,
    pub crs: Crs,
    pub grid: GridInfo,
    /// How the `lp` array's object-space errors were measured (bundles
    /// written before this was recorded: `midpoint`).
    #[serde(default = "ErrorMetric::unrecorded")]
    pub lp_error_metric: ErrorMetric,
    /// The drape image, when the region has one.
    pub color: Option<ColorInfo>,
    pub inputs: Vec<InputFile>,
    /// Every parameter the stages used, by stage then name.
    pub parameters: BTreeMap<String, serde_json::Value>,
    /// Canonical arrays, by name (`height`, `mask`, `color`, …).
    pub artifacts: BTreeMap<String, Artifact>,
    /// Interoperability copies (GeoTIFF, …), not read back by Relevo.
    pub exports: BTreeMap<String, Artifact>,
    /// Wall time of each stage, in run order.
    pub timings: Vec<StageTiming>,
}

/// Coordinate reference system of the grid (and of every world coordinate
/// in the bundle). Empty `wkt` means the inputs were not georeferenced and
/// world units are grid cells.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Crs {
    pub wkt: String,
    pub epsg: Option<u32>,
}

/// The height grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridInfo {
    /// Vertices per side, 2^n + 1.
    pub side: usize,
    pub geotransform: GeoTransform,
    /// Horizontal spacing of vertices, metres.
    pub cell_size_m: f64,
    /// Factor applied to the input heights to get metres.
    pub z_scale: f64,
    /// `[xmin, ymin, xmax, ymax]` of the cells with real data, CRS units.
    pub valid_extent: [f64; 4],
    /// Lowest and highest real height, metres.
    pub height_range_m: [f32; 2],
    /// Vertices with mask 1.
    pub valid_vertices: usize,
}

impl GridInfo {
    /// The description of `grid` with `cell_size_m` spacing; `None` when
    /// it holds no data.
    pub fn of(grid: &crate::grid::HeightGrid, cell_size_m: f64, z_scale: f64) -> Option<GridInfo> {
        Some(GridInfo {
            side: grid.side,
            geotransform: grid.geotransform,
            cell_size_m,
            z_scale,
            valid_extent: grid.valid_extent()?,
            height_range_m: grid.height_range()?,
            valid_vertices: grid.valid_count(),
        })
    }
}

/// The drape image, at its own resolution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColorInfo {
    pub width: usize,
    pub height: usize,
    pub geotransform: GeoTransform,
    /// Source bands used for red, green and blue (1-based); `[0, 0, 0]` for
    /// a drape derived from the terrain.
    pub bands: [usize; 3],
}

/// One input file as it was read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputFile {
    /// What the file was used as: `dem`, `image`, `samples`.
    pub role: String,
    pub path: String,
    pub bytes: u64,
    pub sha256: String,
}

/// Element type of an array artifact; stored little-endian.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dtype {
    U8,
    U16,
    U32,
    F32,
    F64,
    /// Not an array (CSV, GeoTIFF, …): `shape` is empty.
    File,
}

impl Dtype {
    /// Bytes per element, or `None` for [`Dtype::File`].
    pub fn size(self) -> Option<usize> {
        match self {
            Dtype::U8 => Some(1),
            Dtype::U16 => Some(2),
            Dtype::U32 | Dtype::F32 => Some(4),
            Dtype::F64 => Some(8),
            Dtype::File => None,
        }
    }
}

/// A file in the bundle with what it holds and its digest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Artifact {
    /// Path relative to the bundle directory.
    pub file: String,
    pub dtype: Dtype,
    /// Array shape, slowest axis first (`[rows, columns]` or `[rows, columns, channels]`).
    pub shape: Vec<usize>,
    pub bytes: u64,
    pub sha256: String,
}

/// Wall time of one stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageTiming {
    pub stage: String,
    pub ms: f64,
}

impl StageTiming {
    /// Add `ms` to `stage`'s entry of `timings`, appending it when new.
    pub fn add(timings: &mut Vec<StageTiming>, stage: &str, ms: f64) {
        match timings.iter_mut().find(|t| t.stage == stage) {
            Some(t) => t.ms += ms,
            None => timings.push(StageTiming {
                stage: stage.into(),
                ms,
            }),
        }
    }
}
