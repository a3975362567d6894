//! REGION.toml: what `relevo prep` builds a bundle from.
//!
//! Relative paths are relative to the REGION.toml file. See docs/guide.md for
//! the reference.

use crate::ingest::gdalio::Resampling;
use anyhow::{anyhow, bail, Context, Result};
use relevo_core::cluster::model::ModelSource;
use relevo_core::grid::Squaring;
use relevo_core::raster::encoding::Encoding;
use relevo_core::raster::mosaic::Overlap;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionSpec {
    /// Region name; default: the output's file stem.
    pub name: Option<String>,
    /// Target CRS of the bundle (anything GDAL accepts). Default: the DEM's
    /// own when it is projected, else the UTM zone of the region's centre.
    pub crs: Option<String>,
    /// Grid spacing in metres; default: the DEM's, or after reprojection the
    /// finest spacing that keeps every source cell.
    pub cell_size_m: Option<f64>,
    /// Factor from the DEM's vertical unit to metres.
    #[serde(default = "one")]
    pub z_scale: f64,
    pub dem: DemSection,
    #[serde(default)]
    pub fill: FillSection,
    #[serde(default)]
    pub grid: GridSection,
    pub image: Option<ImageSection>,
    /// Without imagery: drape the terrain with a hypsometric tint and a
    /// baked hillshade derived from the heights.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub terrain_drape: bool,
    pub vegetation: Option<VegetationSection>,
    /// Vegetation clusters (baked whenever there is vegetation; this
    /// section only changes their models and options).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clusters: Option<ClustersSection>,
}

/// `[clusters]`: a model per vegetation class and the bake's options.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClustersSection {
    /// Class name → built-in model (`broadleaf`, `conifer`, `dead`,
    /// `stand`) or OBJ file.
    #[serde(default)]
    pub models: std::collections::BTreeMap<String, ModelSource>,
    #[serde(default)]
    pub options: relevo_core::cluster::bake::BakeOptions,
}

fn one() -> f64 {
    1.0
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DemSection {
    pub files: Vec<PathBuf>,
    #[serde(default)]
    pub encoding: Encoding,
    /// No-data value overriding the files' own: a number or "nan".
    pub src_nodata: Option<NoData>,
    #[serde(default)]
    pub overlap: Overlap,
    #[serde(default = "bilinear")]
    pub resampling: Resampling,
}

fn bilinear() -> Resampling {
    Resampling::Bilinear
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FillSection {
    /// Holes of at most this many cells are interpolated; larger stay masked.
    pub max_hole_cells: usize,
}

impl Default for FillSection {
    fn default() -> Self {
        FillSection {
            max_hole_cells: 10_000,
        }
    }
}

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSection {
    #[serde(default)]
    pub squaring: Squaring,
    /// How the hierarchy measures vertex errors (`bound` or `midpoint`).
    #[serde(default)]
    pub error_metric: relevo_core::lp::ErrorMetric,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageSection {
    pub files: Vec<PathBuf>,
    /// Source bands shown as red, green, blue (1-based); default 1, 2, 3
    /// (1, 1, 1 for single-band imagery).
    pub bands: Option<[usize; 3]>,
    pub src_nodata: Option<NoData>,
    #[serde(default)]
    pub overlap: Overlap,
    #[serde(default = "bilinear")]
    pub resampling: Resampling,
    /// Percentiles `[low, high]` mapped to 0 and 255 per band. Default: none
    /// for 8-bit images (values kept), `[2, 98]` for deeper ones.
    pub stretch: Option<[f64; 2]>,
}

/// Vegetation extraction on the draped imagery.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VegetationSection {
    /// Marked samples: a semicolon CSV of rectangles in pixel coordinates of
    /// the first image file, or GeoJSON polygons in its CRS.
    pub samples: PathBuf,
    #[serde(default)]
    pub options: relevo_core::veg::pipeline::VegOptions,
}

/// A no-data value as written in TOML: a number, or the string "nan".
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(untagged)]
pub enum NoData {
    Value(f64),
    Name(NanName),
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NanName {
    Nan,
}

impl NoData {
    pub fn value(self) -> f64 {
        match self {
            NoData::Value(v) => v,
            NoData::Name(NanName::Nan) => f64::NAN,
        }
    }
}

/// Parse a no-data value from the command line: a number or `nan`.
pub fn parse_nodata(text: &str) -> Result<f64, String> {
    if text.eq_ignore_ascii_case("nan") {
        return Ok(f64::NAN);
    }
    text.parse::<f64>()
        .map_err(|_| format!("{text:?} is neither a number nor nan"))
}

impl RegionSpec {
    /// Read and check a REGION.toml, resolving relative paths against its folder.
    pub fn load(path: &Path) -> Result<RegionSpec> {
        let text = relevo_core::files::read_to_string(path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        RegionSpec::parse(&text, base).with_context(|| path.display().to_string())
    }

    /// [`RegionSpec::load`] on text, relative paths resolved against `base`.
    pub fn parse(text: &str, base: &Path) -> Result<RegionSpec> {
        let mut region: RegionSpec =
            toml::from_str(text).map_err(|e| anyhow!("{}", e.to_string().trim_end()))?;
        let resolve = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        region.dem.files.iter_mut().for_each(resolve);
        if let Some(image) = &mut region.image {
            image.files.iter_mut().for_each(resolve);
        }
        if let Some(vegetation) = &mut region.vegetation {
            resolve(&mut vegetation.samples);
        }
        if let Some(clusters) = &mut region.clusters {
            for model in clusters.models.values_mut() {
                if let ModelSource::Obj(path) = model {
                    if path.is_relative() {
                        *path = base.join(&*path);
                    }
                }
            }
        }
        region.check()?;
        Ok(region)
    }

    /// Reject values no stage could use.
    pub fn check(&self) -> Result<()> {
        if self.dem.files.is_empty() {
            bail!("dem.files is empty: give at least one elevation raster");
        }
        // A bundle's heights are metres up (its manifest refuses any other
        // scale); a negative scale would turn the terrain upside down.
        if !(self.z_scale.is_finite() && self.z_scale > 0.0) {
            bail!(
                "z_scale must be a finite, positive number, got {}",
                self.z_scale
            );
        }
        if let Some(c) = self.cell_size_m {
            if !(c.is_finite() && c > 0.0) {
                bail!("cell_size_m must be positive, got {c}");
            }
        }
        if let Some(image) = &self.image {
            if image.files.is_empty() {
                bail!("image.files is empty: remove [image] or list the imagery");
            }
            if let Some([lo, hi]) = image.stretch {
                if !((0.0..100.0).contains(&lo) && lo < hi && hi <= 100.0) {
                    bail!(
                        "image.stretch must be [low, high] percentiles with 0 <= low < high <= 100"
                    );
                }
            }
        }
        if self.terrain_drape && self.image.is_some() {
            bail!("terrain_drape and [image] both give the drape: choose one");
        }
        if let Some(clusters) = &self.clusters {
            clusters
                .options
                .cut
                .check()
                .map_err(|e| anyhow!("[clusters.options.cut]: {e}"))?;
        }
        if self.vegetation.is_some() && self.image.is_none() {
            bail!("[vegetation] needs [image]: vegetation is extracted from the imagery");
        }
        Ok(())
    }
}
