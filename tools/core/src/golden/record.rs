//! The golden record: what a region's bundle is expected to hold, small
//! enough to commit and review. Per artifact its SHA-256, and for grids and
//! the vegetation a summary by blocks (see [`super::blocks`],
//! [`super::vegetation`]) that lets a check judge a change against a
//! tolerance and say where it is. Beside the record lie PNGs: reference
//! renders at named cameras, and for grids up to [`MOST_REFERENCE_CELLS`](super::reference::MOST_REFERENCE_CELLS)
//! the heights, LP errors and drape themselves, so that a check judges
//! every vertex against its tolerance.

use super::blocks::{self, BlockDigest, BlockLayout, BlockStatistics, CellValues, Cells};
use super::reference::{self, Reference};
use super::vegetation::{self, VegetationDigest};
use crate::bundle::BundleFiles;
use crate::bundle::{names, Bundle};
use crate::geo::GeoTransform;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The record's format name and version.
pub const FORMAT: &str = "relevo-golden";
pub const FORMAT_VERSION: u32 = 1;

/// A golden record (JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GoldenRecord {
    pub format: String,
    pub format_version: u32,
    /// The bundle's region name: a record of another region is refused.
    pub region: String,
    /// The grid the summaries were made on.
    pub grid: GridShape,
    /// Tolerances the record was blessed with (the command line overrides).
    pub tolerances: Tolerances,
    /// Per manifest key (artifacts and exports).
    pub artifacts: BTreeMap<String, ArtifactRecord>,
    /// Reference renders, each a PNG beside the record.
    #[serde(default)]
    pub renders: Vec<RenderRecord>,
}

/// The grid's size and georeferencing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridShape {
    pub side: usize,
    pub geotransform: GeoTransform,
    pub epsg: Option<u32>,
}

/// One artifact as recorded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArtifactRecord {
    pub file: String,
    pub bytes: u64,
    pub sha256: String,
    /// Grids: blocks; vegetation: classes; other artifacts: hash only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blocks: Option<BlockDigest>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub classes: Option<VegetationDigest>,
    /// Heights, LP errors and the drape: the values themselves, as a PNG
    /// beside the record (grids up to [`MOST_REFERENCE_CELLS`](super::reference::MOST_REFERENCE_CELLS)).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<Reference>,
}

/// A render at a named camera, with relevo-core's raycaster.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderRecord {
    pub name: String,
    /// `X,Y,Z,HEADING[,PITCHdeg][,INCL]` in the bundle's CRS.
    pub camera: String,
    pub size: [u32; 2],
    /// The PNG, relative to the record's folder.
    pub file: String,
}

/// How much each kind of value may move before a check fails. Zero means
/// exact: any change fails.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Tolerances {
    /// Heights, metres, plus `height_relative` × the recorded height.
    pub height_m: f64,
    pub height_relative: f64,
    /// LP object-space errors, metres.
    pub lp_error_m: f64,
    /// Drape colour, levels (0–255) of each channel's block mean.
    pub drape_levels: f64,
    /// Vegetation: how far a class's mean position in a block may move,
    /// metres, and how many objects a class (and a block) may gain or lose.
    pub vegetation_position_m: f64,
    pub vegetation_count: usize,
    /// Renders: a pixel is off when a channel differs by more than
    /// `render_threshold` levels; at most `render_pixels_off` (a share,
    /// 0–1) may be off, and the mean difference at most `render_mean`
    /// levels — the metric Relevo's own snapshot tests use.
    pub render_threshold: u8,
    pub render_pixels_off: f64,
    pub render_mean: f64,
}

impl Default for Tolerances {
    /// Exact for everything Relevo computes deterministically; renders with
    /// the snapshot tests' tolerance (0.5 % of pixels more than 16 levels
    /// off, a mean under one level), since the raycaster takes different
    /// SIMD paths on different CPUs.
    fn default() -> Self {
        Tolerances {
            height_m: 0.0,
            height_relative: 0.0,
            lp_error_m: 0.0,
            drape_levels: 0.0,
            vegetation_position_m: 0.0,
            vegetation_count: 0,
            render_threshold: 16,
            render_pixels_off: 0.005,
            render_mean: 1.0,
        }
    }
}

impl Tolerances {
    /// Refuse tolerances no check could use (negative or not finite).
    pub fn check(&self) -> std::result::Result<(), String> {
        let values = [
            ("height_m", self.height_m),
            ("height_relative", self.height_relative),
            ("lp_error_m", self.lp_error_m),
            ("drape_levels", self.drape_levels),
            ("vegetation_position_m", self.vegetation_position_m),
            ("render_pixels_off", self.render_pixels_off),
            ("render_mean", self.render_mean),
        ];
        match values.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
            Some((name, v)) => Err(format!(
                "tolerance {name} must be a non-negative number, got {v}"
            )),
            None if self.render_pixels_off > 1.0 => {
                Err("tolerance render_pixels_off is a share, 0–1".into())
            }
            None => Ok(()),
        }
    }
}

/// What is summarised of each artifact besides its hash.
fn summary_of(
    bundle: &Bundle,
    key: &str,
) -> Result<(Option<BlockDigest>, Option<VegetationDigest>)> {
    let side = bundle.manifest.grid.side;
    let grid = |values: CellValues, mask: Option<&[u8]>, statistics| {
        blocks::digest(
            &Cells {
                width: side,
                height: side,
                values,
                mask,
            },
            statistics,
        )
    };
    Ok(match key {
        k if k == names::HEIGHT.key => {
            let (heights, mask) = (bundle.heights()?, bundle.mask()?);
            (
                Some(grid(
                    CellValues::F32(&heights),
                    Some(&mask),
                    BlockStatistics::MinMeanMax,
                )),
                None,
            )
        }
        k if k == names::MASK.key => {
            let mask = bundle.mask()?;
            (
                Some(grid(CellValues::Mask(&mask), None, BlockStatistics::Count)),
                None,
            )
        }
        k if k == names::LP.key => {
            let lp = bundle.lp()?;
            let h = lp.hierarchy();
            (
                Some(grid(
                    CellValues::FirstOfPairs(&h.error_radius),
                    None,
                    BlockStatistics::Max,
                )),
                None,
            )
        }
        k if k == names::COLOR.key => match bundle.drape()? {
            None => (None, None),
            Some(d) => (
                Some(blocks::digest(
                    &Cells {
                        width: d.info.width,
                        height: d.info.height,
                        values: CellValues::Rgba(&d.rgba),
                        mask: None,
                    },
                    BlockStatistics::MeanColour,
                )),
                None,
            ),
        },
        k if k == names::VEGETATION.key => {
            let objects = bundle.vegetation()?.unwrap_or_default();
            let layout = BlockLayout::of(side, side);
            let geo = bundle.manifest.grid.geotransform;
            (None, Some(vegetation::digest(&objects, &layout, &geo)))
        }
        _ => (None, None),
    })
}

/// A file to write beside the record: its name and bytes.
pub type Beside = (String, Vec<u8>);

/// The record of `bundle`: every artifact and export with its hash, grids
/// and vegetation summarised, and the reference grids to write beside the
/// record as `STEM.KEY.png` (file name, PNG); `renders` are added by the
/// caller.
pub fn record_bundle(
    bundle: &Bundle,
    tolerances: Tolerances,
    stem: &str,
) -> Result<(GoldenRecord, Vec<Beside>)> {
    let m = &bundle.manifest;
    let mut artifacts = BTreeMap::new();
    let mut files = Vec::new();
    for (key, a) in m.artifacts.iter().chain(&m.exports) {
        let (blocks, classes) = summary_of(bundle, key)?;
        let reference = match reference::make(bundle, key, format!("{stem}.{key}.png"))? {
            Some((r, png)) => {
                files.push((r.file.clone(), png));
                Some(r)
            }
            None => None,
        };
        artifacts.insert(
            key.clone(),
            ArtifactRecord {
                file: a.file.clone(),
                bytes: a.bytes,
                sha256: a.sha256.clone(),
                blocks,
                classes,
                reference,
            },
        );
    }
    let record = GoldenRecord {
        format: FORMAT.into(),
        format_version: FORMAT_VERSION,
        region: m.region.clone(),
        grid: GridShape {
            side: m.grid.side,
            geotransform: m.grid.geotransform,
            epsg: m.crs.epsg,
        },
        tolerances,
        artifacts,
        renders: Vec::new(),
    };
    Ok((record, files))
}

/// The summary `bundle` has now of artifact `key` (for a check).
pub(super) fn current_summary(
    bundle: &Bundle,
    key: &str,
) -> Result<(Option<BlockDigest>, Option<VegetationDigest>)> {
    summary_of(bundle, key)
}

/// Read the record at `path`: refused, naming the file and the problem,
/// when it is not JSON, not a golden record, of another format version, or
/// holds summaries that do not parse.
pub fn read(path: &Path) -> Result<GoldenRecord> {
    let text = crate::files::read_to_string(path)?;
    let record: GoldenRecord = serde_json::from_str(&text)
        .map_err(|e| Error::invalid(path, format!("not a golden record ({e})")))?;
    if record.format != FORMAT {
        return Err(Error::invalid(
            path,
            format!("format is {:?}, expected {FORMAT:?}", record.format),
        ));
    }
    if record.format_version != FORMAT_VERSION {
        return Err(Error::invalid(
            path,
            format!(
                "format version {} is not supported (this build reads {FORMAT_VERSION})",
                record.format_version
            ),
        ));
    }
    record
        .tolerances
        .check()
        .map_err(|p| Error::invalid(path, p))?;
    for (key, a) in &record.artifacts {
        if let Some(b) = &a.blocks {
            b.parse()
                .map_err(|p| Error::invalid(path, format!("artifact {key}: {p}")))?;
        }
        for (class, c) in a.classes.iter().flatten() {
            c.parse()
                .map_err(|p| Error::invalid(path, format!("artifact {key}, class {class}: {p}")))?;
        }
    }
    let beside = record
        .renders
        .iter()
        .map(|r| (format!("render {}", r.name), &r.file))
        .chain(record.artifacts.iter().filter_map(|(k, a)| {
            a.reference
                .as_ref()
                .map(|r| (format!("artifact {k}"), &r.file))
        }));
    for (what, file) in beside {
        let inside = Path::new(file)
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)));
        if !inside || file.is_empty() {
            return Err(Error::invalid(
                path,
                format!("{what}: {file:?} is not a file beside the record"),
            ));
        }
    }
    Ok(record)
}

/// The record as the text written to a file (pretty JSON, one block row a
/// line, a final newline).
pub fn to_text(record: &GoldenRecord) -> Result<String> {
    let mut text = serde_json::to_string_pretty(record)
        .map_err(|e| Error::Input(format!("cannot write the golden record ({e})")))?;
    text.push('\n');
    Ok(text)
}
