//! Vegetation objects from classified regions.
//!
//! - Crowns (fine imagery, about 1 m per pixel or finer): the pixels of
//!   vegetation regions form a mask; crown centres are the maxima of the
//!   Euclidean distance to the mask's edge, kept greedily from the largest
//!   with at least `spacing_px` between centres. The distance at a centre is
//!   the radius of the largest disc of vegetation around it, so the object's
//!   size is that disc's diameter.
//! - Fill (coarse imagery, e.g. 30 m Landsat, where a pixel holds many trees):
//!   each vegetation pixel area receives objects from a jittered grid of
//!   `spacing_px`, the jitter a hash of the grid cell, so the same region
//!   always gets the same objects whatever order it is processed in.

use super::classify::Label;
use super::segment::Segmentation;
use crate::raster::distance::distance_to_seeds;
use rayon::prelude::*;

/// How vegetation regions become objects.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "mode", rename_all = "lowercase")]
pub enum Placement {
    /// One object per crown.
    Crowns {
        /// Smallest distance between crown centres (pixels).
        spacing_px: f32,
        /// Crowns whose disc radius is smaller are dropped (pixels).
        min_radius_px: f32,
    },
    /// Objects on a jittered grid inside vegetation regions.
    Fill {
        /// Grid spacing (pixels); one object per `spacing_px²` of vegetation.
        spacing_px: f32,
        /// Size given to every object (pixels).
        diameter_px: f32,
    },
}

/// A detected object in pixel coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Object {
    pub x: f64,
    pub y: f64,
    pub class: usize,
    /// Diameter in pixels.
    pub size_px: f32,
    pub score: f32,
}

/// Objects for every pixel whose region's class is in `vegetation`, sorted
/// by row then column.
pub fn detect(
    image: &super::Image,
    segmentation: &Segmentation,
    labels: &[Label],
    vegetation: &[bool],
    placement: Placement,
) -> Vec<Object> {
    let (w, h) = (segmentation.width, segmentation.height);
    let label_at = |x: usize, y: usize| labels[segmentation.labels[y * w + x] as usize];
    let is_vegetation = |x: usize, y: usize| vegetation[label_at(x, y).class];
    let object = |x: f64, y: f64, size_px: f32| {
        let label = label_at(x as usize, y as usize);
        Object {
            x,
            y,
            class: label.class,
            size_px,
            score: label.score,
        }
    };
    let mut objects: Vec<Object> = match placement {
        Placement::Fill {
            spacing_px,
            diameter_px,
        } => {
            let s = spacing_px.max(1e-3) as f64;
            let (cols, rows) = ((w as f64 / s).ceil() as u64, (h as f64 / s).ceil() as u64);
            (0..rows)
                .into_par_iter()
                .flat_map_iter(|j| {
                    (0..cols).filter_map(move |i| {
                        let r = splitmix64(j << 32 | i);
                        let u = (r >> 40) as f64 / (1u64 << 24) as f64;
                        let v = (r & 0xff_ffff) as f64 / (1u64 << 24) as f64;
                        let (x, y) = ((i as f64 + u) * s, (j as f64 + v) * s);
                        (x < w as f64 && y < h as f64).then_some((x, y))
                    })
                })
                .filter(|&(x, y)| is_vegetation(x as usize, y as usize))
                .map(|(x, y)| object(x, y, diameter_px))
                .collect()
        }
        Placement::Crowns {
            spacing_px,
            min_radius_px,
        } => {
            let outside: Vec<bool> = (0..w * h)
                .into_par_iter()
                .map(|i| !is_vegetation(i % w, i / w))
                .collect();
            let radius = distance_to_seeds(&outside, w, h);
            // Sunlit tops: smoothed brightness, only inside vegetation.
            let brightness: Vec<f32> = (0..w * h)
                .into_par_iter()
                .map(|i| image.colour(i % w, i / w)[0])
                .collect();
            let blur = (0.3 * spacing_px).round() as usize;
            let smooth = box_blur(&box_blur(&brightness, w, h, blur), w, h, blur);
            let value: Vec<f32> = smooth
                .iter()
                .zip(&outside)
                .map(|(&v, &out)| if out { f32::MIN } else { v })
                .collect();
            let r = (spacing_px.max(1.0) / 2.0).ceil() as usize;
            let peak = window_max(&value, w, h, r);
            let min_radius = min_radius_px.max(1.0);
            let mut candidates: Vec<usize> = (0..w * h)
                .into_par_iter()
                .filter(|&i| radius[i] >= min_radius && value[i] >= peak[i])
                .collect();
            candidates.sort_by(|&a, &b| value[b].total_cmp(&value[a]).then(a.cmp(&b)));
            let kept = suppress(&candidates, w, spacing_px.max(1.0));
            kept.into_iter()
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    object(x as f64 + 0.5, y as f64 + 0.5, 2.0 * radius[i])
                })
                .collect()
        }
    };
    objects.sort_by(|a, b| a.y.total_cmp(&b.y).then(a.x.total_cmp(&b.x)));
    objects
}

/// Mean over the `(2r+1)²` window around each cell, clipped at the edges
/// (separable running sums).
fn box_blur(values: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let mut rows = vec![0.0f32; w * h];
    rows.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let line = &values[y * w..(y + 1) * w];
        running_mean(|x| line[x], w, r, |x, v| out[x] = v);
    });
    // Columns: bands of rows, each with its own running column sums.
    const BAND: usize = 128;
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(BAND * w)
        .enumerate()
        .for_each(|(band, block)| {
            let y0 = band * BAND;
            let mut sums = vec![0.0f64; w];
            let (mut lo, mut hi) = (y0.saturating_sub(r), y0.saturating_sub(r));
            for (dy, line) in block.chunks_mut(w).enumerate() {
                let y = y0 + dy;
                let (want_lo, want_hi) = (y.saturating_sub(r), (y + r + 1).min(h));
                while hi < want_hi {
                    sums.iter_mut()
                        .zip(&rows[hi * w..(hi + 1) * w])
                        .for_each(|(s, v)| *s += *v as f64);
                    hi += 1;
                }
                while lo < want_lo {
                    sums.iter_mut()
                        .zip(&rows[lo * w..(lo + 1) * w])
                        .for_each(|(s, v)| *s -= *v as f64);
                    lo += 1;
                }
                let count = (hi - lo) as f64;
                line.iter_mut()
                    .zip(&sums)
                    .for_each(|(o, s)| *o = (s / count) as f32);
            }
        });
    out
}

/// Mean of `at(i−r ..= i+r)` clipped to `0..n`, for every `i`, in O(n).
fn running_mean(at: impl Fn(usize) -> f32, n: usize, r: usize, mut put: impl FnMut(usize, f32)) {
    let mut sum = 0.0f64;
    let (mut lo, mut hi) = (0usize, 0usize);
    for i in 0..n {
        let (want_lo, want_hi) = (i.saturating_sub(r), (i + r + 1).min(n));
        while hi < want_hi {
            sum += at(hi) as f64;
            hi += 1;
        }
        while lo < want_lo {
            sum -= at(lo) as f64;
            lo += 1;
        }
        put(i, (sum / (hi - lo) as f64) as f32);
    }
}

/// Keep candidates (pixel indices, best first) at least `spacing` apart.
fn suppress(candidates: &[usize], w: usize, spacing: f32) -> Vec<usize> {
    let cell = spacing as f64;
    let key = |x: f64, y: f64| ((x / cell) as i64, (y / cell) as i64);
    let mut grid: std::collections::HashMap<(i64, i64), Vec<(f64, f64)>> =
        std::collections::HashMap::new();
    let mut kept = Vec::new();
    let limit = cell * cell;
    for &i in candidates {
        let (x, y) = ((i % w) as f64, (i / w) as f64);
        let (cx, cy) = key(x, y);
        let close = (cx - 1..=cx + 1).any(|gx| {
            (cy - 1..=cy + 1).any(|gy| {
                grid.get(&(gx, gy)).is_some_and(|points| {
                    points
                        .iter()
                        .any(|&(px, py)| (px - x).powi(2) + (py - y).powi(2) < limit)
                })
            })
        });
        if !close {
            grid.entry((cx, cy)).or_default().push((x, y));
            kept.push(i);
        }
    }
    kept
}

/// Maximum over the `(2r+1)²` window around each cell (separable).
fn window_max(values: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let mut rows = vec![0.0f32; w * h];
    rows.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let line = &values[y * w..(y + 1) * w];
        for (x, o) in out.iter_mut().enumerate() {
            *o = line[x.saturating_sub(r)..(x + r + 1).min(w)]
                .iter()
                .fold(f32::MIN, |a, &b| a.max(b));
        }
    });
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, line)| {
        let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(h));
        line.copy_from_slice(&rows[y0 * w..(y0 + 1) * w]);
        for yy in y0 + 1..y1 {
            for (o, &v) in line.iter_mut().zip(&rows[yy * w..(yy + 1) * w]) {
                *o = o.max(v);
            }
        }
    });
    out
}

/// SplitMix64 (Steele, Lea & Flood 2014): a well-mixed hash of a grid cell.
fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}
