//! The square height grid a bundle is built on: (2^n+1)² vertices, so that
//! longest-edge bisection hierarchies (Lindstrom–Pascucci) cover it exactly,
//! with a mask telling real data from padding and unfilled voids.

use crate::geo::GeoTransform;
use std::collections::VecDeque;

/// Heights in metres on a `side`×`side` grid, row-major, top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct HeightGrid {
    pub side: usize,
    pub heights: Vec<f32>,
    /// 1 = real data, 0 = padding or no-data.
    pub mask: Vec<u8>,
    /// Georeferencing of the grid's cells (sample `(c, r)` sits at the centre
    /// of cell `(c, r)`).
    pub geotransform: GeoTransform,
}

/// How a raster becomes (2^n+1)².
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Squaring {
    /// Keep every sample; extend right and down to the smallest 2^n+1 that fits.
    #[default]
    Pad,
    /// Resample (bilinear) to the 2^n+1 nearest the longer side, stretching the cells.
    Resample,
}

/// Smallest `2^n + 1` (n ≥ 1) that is at least `len`.
pub fn pow2_plus_1_at_least(len: usize) -> usize {
    let mut side = 3;
    while side < len {
        side = (side - 1) * 2 + 1;
    }
    side
}

/// The `2^n + 1` (n ≥ 1) closest to `len`; ties go to the larger.
pub fn pow2_plus_1_nearest(len: usize) -> usize {
    let up = pow2_plus_1_at_least(len);
    let down = (up - 1) / 2 + 1;
    if up > 3 && len - down < up - len {
        down
    } else {
        up
    }
}

impl HeightGrid {
    /// Build the square grid from `width`×`height` heights (NaN = no-data).
    ///
    /// No-data cells take the height of the nearest valid cell (breadth-first,
    /// so the result is deterministic) and padding replicates the last row and
    /// column: neither adds relief, so neither forces refinement. Both are
    /// masked 0.
    pub fn square(
        values: &[f64],
        width: usize,
        height: usize,
        geotransform: GeoTransform,
        squaring: Squaring,
    ) -> HeightGrid {
        assert_eq!(values.len(), width * height);
        let valid: Vec<bool> = values.iter().map(|v| !v.is_nan()).collect();
        let dense: std::borrow::Cow<[f64]> = if valid.iter().all(|&v| v) {
            std::borrow::Cow::Borrowed(values)
        } else {
            std::borrow::Cow::Owned(nearest_fill(values, width, height))
        };
        match squaring {
            Squaring::Pad => {
                let side = pow2_plus_1_at_least(width.max(height));
                let mut heights = vec![0.0f32; side * side];
                let mut mask = vec![0u8; side * side];
                for r in 0..side {
                    let sr = r.min(height - 1);
                    for c in 0..side {
                        let sc = c.min(width - 1);
                        heights[r * side + c] = dense[sr * width + sc] as f32;
                        mask[r * side + c] =
                            (r < height && c < width && valid[sr * width + sc]) as u8;
                    }
                }
                HeightGrid {
                    side,
                    heights,
                    mask,
                    geotransform,
                }
            }
            Squaring::Resample => {
                let side = pow2_plus_1_nearest(width.max(height));
                let t = geotransform.0;
                let (sx, sy) = (width as f64 / side as f64, height as f64 / side as f64);
                let geo = GeoTransform([t[0], t[1] * sx, t[2] * sy, t[3], t[4] * sx, t[5] * sy]);
                let mut heights = vec![0.0f32; side * side];
                let mut mask = vec![0u8; side * side];
                for r in 0..side {
                    // Source position of this sample's centre, in source cell units.
                    let y = ((r as f64 + 0.5) * sy - 0.5).clamp(0.0, (height - 1) as f64);
                    for c in 0..side {
                        let x = ((c as f64 + 0.5) * sx - 0.5).clamp(0.0, (width - 1) as f64);
                        heights[r * side + c] = bilinear(&dense, width, height, x, y) as f32;
                        let nearest = (y.round() as usize) * width + x.round() as usize;
                        mask[r * side + c] = valid[nearest] as u8;
                    }
                }
                HeightGrid {
                    side,
                    heights,
                    mask,
                    geotransform: geo,
                }
            }
        }
    }

    /// Number of vertices with real data.
    pub fn valid_count(&self) -> usize {
        self.mask.iter().filter(|&&m| m == 1).count()
    }

    /// World bounding box `[xmin, ymin, xmax, ymax]` of the cells with real data.
    pub fn valid_extent(&self) -> Option<[f64; 4]> {
        let (mut c0, mut r0, mut c1, mut r1) = (usize::MAX, usize::MAX, 0, 0);
        for (i, &m) in self.mask.iter().enumerate() {
            if m == 1 {
                let (c, r) = (i % self.side, i / self.side);
                c0 = c0.min(c);
                r0 = r0.min(r);
                c1 = c1.max(c + 1);
                r1 = r1.max(r + 1);
            }
        }
        if c0 == usize::MAX {
            return None;
        }
        let a = self.geotransform.apply(c0 as f64, r0 as f64);
        let b = self.geotransform.apply(c1 as f64, r1 as f64);
        Some([a.0.min(b.0), a.1.min(b.1), a.0.max(b.0), a.1.max(b.1)])
    }

    /// Lowest and highest height among real data, metres.
    pub fn height_range(&self) -> Option<[f32; 2]> {
        let mut range: Option<[f32; 2]> = None;
        for (&h, &m) in self.heights.iter().zip(&self.mask) {
            if m == 1 {
                let r = range.get_or_insert([h, h]);
                r[0] = r[0].min(h);
                r[1] = r[1].max(h);
            }
        }
        range
    }
}

/// Copy of `values` where each NaN takes the value of the nearest valid cell
/// (4-connected breadth-first order from all valid cells at once).
fn nearest_fill(values: &[f64], width: usize, height: usize) -> Vec<f64> {
    let mut out = values.to_vec();
    let mut queue: VecDeque<usize> = (0..values.len()).filter(|&i| !values[i].is_nan()).collect();
    while let Some(i) = queue.pop_front() {
        for n in neighbours4(i, width, height) {
            if out[n].is_nan() {
                out[n] = out[i];
                queue.push_back(n);
            }
        }
    }
    out
}

/// Bilinear sample at fractional cell position (x, y), both clamped inside.
fn bilinear(values: &[f64], width: usize, height: usize, x: f64, y: f64) -> f64 {
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(width - 1), (y0 + 1).min(height - 1));
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let at = |c: usize, r: usize| values[r * width + c];
    let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
    let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// The up-to-four edge neighbours of cell `i` (row-major) of a
/// `width`×`height` grid.
pub fn neighbours4(i: usize, width: usize, height: usize) -> impl Iterator<Item = usize> {
    let (c, r) = (i % width, i / width);
    [
        (c > 0).then(|| i - 1),
        (c + 1 < width).then(|| i + 1),
        (r > 0).then(|| i - width),
        (r + 1 < height).then(|| i + width),
    ]
    .into_iter()
    .flatten()
}

/// The offsets (columns, rows) of a vertex's eight neighbours, row by row.
pub const EIGHT_NEIGHBOURS: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// Unit normal (terrain frame, z up) of the full-resolution surface at
/// vertex (c, r) of a `side`² grid of `heights` with `cell`-metre spacing:
/// central differences, one-sided at the border.
pub fn vertex_normal(heights: &[f32], side: usize, cell: f64, c: usize, r: usize) -> [f64; 3] {
    vertex_normal_of(&|c, r| heights[r * side + c], side, cell, c, r)
}

/// [`vertex_normal`] with the heights of the `side`² grid given by `z`
/// (global column, row) — for a caller holding only a window of it.
pub fn vertex_normal_of(
    z: &dyn Fn(usize, usize) -> f32,
    side: usize,
    cell: f64,
    c: usize,
    r: usize,
) -> [f64; 3] {
    let z = |c: usize, r: usize| z(c, r) as f64;
    let (c0, c1) = (c.saturating_sub(1), (c + 1).min(side - 1));
    let (r0, r1) = (r.saturating_sub(1), (r + 1).min(side - 1));
    let dz_east = (z(c1, r) - z(c0, r)) / ((c1 - c0) as f64 * cell);
    // Rows grow southwards.
    let dz_north = (z(c, r0) - z(c, r1)) / ((r1 - r0) as f64 * cell);
    let len = (dz_east * dz_east + dz_north * dz_north + 1.0).sqrt();
    [-dz_east / len, -dz_north / len, 1.0 / len]
}

/// A deterministic synthetic heightfield for tests and benchmarks of the
/// algorithms at sizes no committed DEM has: a fractal (diamond-square with hash-based
/// offsets, Hurst exponent about 0.75), `side` = 2^n + 1, heights in metres.
pub fn fractal_heights(side: usize, seed: u64) -> Vec<f32> {
    let mut z = vec![0.0f64; side * side];
    let hash = |c: usize, r: usize| {
        let mut x = seed ^ ((c as u64) << 32 | r as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        x ^= x >> 29;
        x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x ^= x >> 32;
        (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut step = side - 1;
    let mut amplitude = 1500.0;
    while step > 1 {
        let half = step / 2;
        for r in (half..side).step_by(step) {
            for c in (half..side).step_by(step) {
                let corners = z[(r - half) * side + c - half]
                    + z[(r - half) * side + c + half]
                    + z[(r + half) * side + c - half]
                    + z[(r + half) * side + c + half];
                z[r * side + c] = corners / 4.0 + amplitude * hash(c, r);
            }
        }
        for r in (0..side).step_by(half) {
            let start = if (r / half).is_multiple_of(2) {
                half
            } else {
                0
            };
            for c in (start..side).step_by(step) {
                let mut sum = 0.0;
                let mut n = 0.0;
                for (dc, dr) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (nc, nr) = (c as i64 + dc * half as i64, r as i64 + dr * half as i64);
                    if nc >= 0 && nr >= 0 && nc < side as i64 && nr < side as i64 {
                        sum += z[nr as usize * side + nc as usize];
                        n += 1.0;
                    }
                }
                z[r * side + c] = sum / n + amplitude * hash(c, r);
            }
        }
        step = half;
        // Roughness of real relief: amplitude falls by 2^-0.75 per octave.
        amplitude *= 0.6;
    }
    z.into_iter().map(|v| v as f32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sides() {
        assert_eq!(pow2_plus_1_at_least(2), 3);
        assert_eq!(pow2_plus_1_at_least(111), 129);
        assert_eq!(pow2_plus_1_at_least(129), 129);
        assert_eq!(pow2_plus_1_at_least(130), 257);
        assert_eq!(pow2_plus_1_nearest(1000), 1025);
        assert_eq!(pow2_plus_1_nearest(600), 513);
        assert_eq!(pow2_plus_1_nearest(800), 1025);
    }

    #[test]
    fn pad_replicates_edges_and_masks_padding() {
        let values: Vec<f64> = vec![1.0, 2.0, f64::NAN, 3.0, 4.0, 5.0];
        let g = HeightGrid::square(&values, 3, 2, GeoTransform::IDENTITY, Squaring::Pad);
        assert_eq!(g.side, 3);
        assert_eq!(g.heights, vec![1.0, 2.0, 2.0, 3.0, 4.0, 5.0, 3.0, 4.0, 5.0]);
        assert_eq!(g.mask, vec![1, 1, 0, 1, 1, 1, 0, 0, 0]);
        assert_eq!(g.valid_extent(), Some([0.0, 0.0, 3.0, 2.0]));
    }

    #[test]
    fn resample_keeps_extent() {
        let values: Vec<f64> = (0..6 * 6).map(|i| i as f64).collect();
        let geo = GeoTransform::north_up(0.0, 60.0, 10.0, 10.0);
        let g = HeightGrid::square(&values, 6, 6, geo, Squaring::Resample);
        assert_eq!(g.side, 5);
        assert_eq!(g.geotransform.bounds(5, 5), [0.0, 0.0, 60.0, 60.0]);
        assert_eq!(g.valid_count(), 25);
    }
}
