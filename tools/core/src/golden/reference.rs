//! Reference grids beside a golden record: the heights and LP errors as
//! 16-bit grey PNGs (values quantised between the grid's lowest and
//! highest, no-data kept apart) and the drape as an RGBA PNG, so that a
//! check judges every vertex and pixel against its tolerance and names the
//! vertex that moved most — not only the block it lies in.

use super::blocks::BlockLayout;
use super::finding::{Finding, Outcome, Place, MOST_PLACES};
use crate::bundle::{names, Bundle};
use crate::raster::png::{decode_grey16, decode_rgba, encode_grey16, encode_rgba};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Largest grid (vertices) a record keeps a reference of: bigger grids are
/// judged by their blocks alone, so that a record stays small enough to
/// commit (a 4097² grid is a PNG of a few tens of MB at most).
pub const MOST_REFERENCE_CELLS: usize = 4097 * 4097;

/// Quantised level that marks a vertex without data.
const NO_DATA: u16 = u16::MAX;

/// A reference grid: the PNG beside the record and how its levels map to
/// values (value = offset + step × level; the drape's levels are its own).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reference {
    pub file: String,
    pub offset: f64,
    /// Metres a level (0 for the drape's RGBA).
    pub step: f64,
}

/// The values of artifact `key` as a reference compares them: per cell,
/// `channels` values, `None` where there is no data.
struct Values {
    width: usize,
    height: usize,
    channels: usize,
    values: Vec<Option<f64>>,
}

fn values_of(bundle: &Bundle, key: &str) -> Result<Option<Values>> {
    let side = bundle.manifest.grid.side;
    let grid = |values: Vec<Option<f64>>| Values {
        width: side,
        height: side,
        channels: 1,
        values,
    };
    Ok(match key {
        k if k == names::HEIGHT.key => {
            let (h, m) = (bundle.heights()?, bundle.mask()?);
            Some(grid(
                h.iter()
                    .zip(m.iter())
                    .map(|(&z, &k)| (k == 1).then_some(f64::from(z)))
                    .collect(),
            ))
        }
        k if k == names::LP.key => {
            let lp = bundle.lp()?;
            let h = lp.hierarchy();
            Some(grid(
                h.error_radius
                    .iter()
                    .map(|e| Some(f64::from(e[0])))
                    .collect(),
            ))
        }
        k if k == names::COLOR.key => bundle.drape()?.map(|d| Values {
            width: d.info.width,
            height: d.info.height,
            channels: 4,
            values: d.rgba.iter().map(|&v| Some(f64::from(v))).collect(),
        }),
        _ => None,
    })
}

/// The reference of artifact `key` of `bundle`, to be written as `file`
/// beside the record: `None` for artifacts without one, or grids larger
/// than [`MOST_REFERENCE_CELLS`].
pub fn make(bundle: &Bundle, key: &str, file: String) -> Result<Option<(Reference, Vec<u8>)>> {
    let Some(v) = values_of(bundle, key)? else {
        return Ok(None);
    };
    if v.width * v.height > MOST_REFERENCE_CELLS {
        return Ok(None);
    }
    if v.channels == 4 {
        let rgba: Vec<u8> = v.values.iter().map(|x| x.unwrap_or(0.0) as u8).collect();
        let png = encode_rgba(&rgba, v.width, v.height)?;
        return Ok(Some((
            Reference {
                file,
                offset: 0.0,
                step: 0.0,
            },
            png,
        )));
    }
    let (lo, hi) = v
        .values
        .iter()
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
            (l.min(x), h.max(x))
        });
    let (offset, step) = if lo.is_finite() {
        (lo, ((hi - lo) / f64::from(NO_DATA - 1)).max(1e-9))
    } else {
        (0.0, 1.0)
    };
    let levels: Vec<u16> = v
        .values
        .iter()
        .map(|x| match x {
            Some(x) => ((x - offset) / step)
                .round()
                .clamp(0.0, f64::from(NO_DATA - 1)) as u16,
            None => NO_DATA,
        })
        .collect();
    let png = encode_grey16(&levels, v.width, v.height)?;
    Ok(Some((Reference { file, offset, step }, png)))
}

/// Read reference `r` from `dir` as values, checking its size.
fn read(
    r: &Reference,
    dir: &Path,
    width: usize,
    height: usize,
    channels: usize,
) -> Result<Vec<Option<f64>>> {
    let path = dir.join(&r.file);
    let bytes = crate::files::read(&path)?;
    let bad = |e: Error| Error::invalid(&path, e.to_string());
    let (values, w, h) = if channels == 4 {
        let (rgba, w, h) = decode_rgba(&bytes).map_err(bad)?;
        (rgba.into_iter().map(|v| Some(f64::from(v))).collect(), w, h)
    } else {
        let (levels, w, h) = decode_grey16(&bytes).map_err(bad)?;
        let values = levels
            .into_iter()
            .map(|q| (q != NO_DATA).then(|| r.offset + r.step * f64::from(q)))
            .collect();
        (values, w, h)
    };
    if (w, h) != (width, height) {
        return Err(Error::invalid(
            &path,
            format!("is {w}×{h}, the bundle's is {width}×{height}"),
        ));
    }
    Ok(values)
}

/// How much a value may move: `tolerance(recorded value)` plus half the
/// reference's quantisation step.
pub(super) struct Judge<'a> {
    pub tolerance: &'a dyn Fn(f64) -> f64,
    /// The tolerance in words, and the unit of the values.
    pub words: String,
    pub unit: &'static str,
    /// Whether any change fails (a zero tolerance).
    pub exact: bool,
}

/// Compare artifact `key` of `bundle` with its reference cell by cell.
pub(super) fn compare(
    bundle: &Bundle,
    key: &str,
    r: &Reference,
    dir: &Path,
    judge: &Judge,
) -> Result<Finding> {
    let Some(now) = values_of(bundle, key)? else {
        return Err(Error::invalid(
            &bundle.dir,
            format!("has no values for {key}"),
        ));
    };
    let before = read(r, dir, now.width, now.height, now.channels)?;
    let slack = r.step / 2.0;
    let frame = bundle.frame();
    let layout = BlockLayout::of(now.width, now.height);
    // Per block, the cell that moved most beyond tolerance: its change,
    // index, and value before and after.
    type Worst = (f64, usize, Option<f64>, Option<f64>);
    let mut worst: BTreeMap<[usize; 2], Worst> = BTreeMap::new();
    let (mut beyond, mut largest) = (0usize, 0.0f64);
    let cells = now.width * now.height;
    for cell in 0..cells {
        let range = cell * now.channels..(cell + 1) * now.channels;
        let mut change = 0.0f64;
        let mut fits = true;
        let (mut was, mut is) = (None, None);
        for k in range {
            match (before[k], now.values[k]) {
                (Some(a), Some(b)) => {
                    let d = (b - a).abs();
                    if d > change {
                        change = d;
                        (was, is) = (Some(a), Some(b));
                    }
                    let allowed = if judge.exact {
                        0.0
                    } else {
                        (judge.tolerance)(a)
                    };
                    fits &= d <= allowed + slack;
                }
                (None, None) => {}
                (a, b) => {
                    change = f64::INFINITY;
                    (was, is) = (a, b);
                    fits = false;
                }
            }
        }
        largest = largest.max(change);
        if !fits {
            beyond += 1;
            let (c, row) = (cell % now.width, cell / now.width);
            let block = [c / layout.cells, row / layout.cells];
            let entry = worst.entry(block).or_insert((-1.0, cell, was, is));
            if change > entry.0 {
                *entry = (change, cell, was, is);
            }
        }
    }
    let unit = judge.unit;
    let mut places: Vec<Place> = worst
        .into_iter()
        .map(|(block, (change, cell, was, is))| {
            let (c, row) = (cell % now.width, cell / now.width);
            let geo = match (&bundle.manifest.color, now.channels) {
                (Some(info), 4) => info.geotransform,
                _ => frame.geotransform,
            };
            let (x0, y0) = geo.apply(c as f64, row as f64 + 1.0);
            let (x1, y1) = geo.apply(c as f64 + 1.0, row as f64);
            let what = match (was, is) {
                (Some(a), Some(b)) => format!("{a:.3} → {b:.3}{unit} ({:+.3}{unit})", b - a),
                (Some(_), None) => "the data here vanished".into(),
                (None, Some(_)) => "data appeared where there was none".into(),
                (None, None) => String::new(),
            };
            Place {
                block,
                cells: [c, row, c + 1, row + 1],
                bounds: [x0.min(x1), y0.min(y1), x0.max(x1), y0.max(y1)],
                change,
                what,
            }
        })
        .collect();
    places.sort_by(|a, b| b.change.total_cmp(&a.change));
    places.truncate(MOST_PLACES);
    let changed_anywhere = beyond > 0 || judge.exact;
    Ok(Finding {
        artifact: key.to_string(),
        outcome: if changed_anywhere {
            Outcome::Changed
        } else {
            Outcome::WithinTolerance
        },
        figure: if beyond == 0 && judge.exact {
            format!(
                "values changed by less than the record's resolution ({:.4}{unit})",
                r.step
            )
        } else {
            format!("{beyond} of {cells} cells beyond tolerance, largest change {largest:.3}{unit}")
        },
        tolerance: match r.step {
            0.0 => judge.words.clone(),
            step => format!("{} (record resolution {step:.4}{unit})", judge.words),
        },
        places,
    })
}
