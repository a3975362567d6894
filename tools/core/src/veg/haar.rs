//! The orthonormal 2-D Haar wavelet transform and region signatures.
//!
//! Transform: the standard (Mallat) decomposition of an N×N block, N a power
//! of two: each level replaces pairs `(a, b)` along rows and then columns of
//! the current low-pass quadrant by `((a+b)/√2, (a−b)/√2)` (Stollnitz, DeRose
//! & Salesin, "Wavelets for Computer Graphics", part 1, with the orthonormal
//! scaling). Being orthonormal, it keeps the sum of squares (Parseval), so
//! sub-band energies compare across levels.
//!
//! Signature (our choice, the seed names Haar coefficients without fixing a
//! form): for each channel of the region's patch, its mean and the root mean
//! square of each detail sub-band (horizontal, vertical, diagonal) at each
//! level. Sub-band energies describe texture at each scale and do not depend
//! on where in the patch a crown or a gap falls, unlike the largest
//! coefficients (Jacobs, Finkelstein & Salesin 1995), which suit aligned
//! images, not regions of arbitrary position and shape.

use super::segment::{Segment, Segmentation};
use super::Image;
use glam::Vec4;

/// Side of the patch a region is resampled to before its transform.
pub const PATCH: usize = 16;
const LEVELS: usize = PATCH.trailing_zeros() as usize;
/// Features per channel: the mean and three sub-bands per level.
pub const FEATURES_PER_CHANNEL: usize = 1 + 3 * LEVELS;

/// A value the transform works on: one channel (`f32`), or every channel
/// of a pixel at once (`Vec4`, a lane per channel, the same operations lane
/// by lane as on one `f32`).
pub trait Coefficient:
    Copy
    + Default
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<f32, Output = Self>
{
}

impl Coefficient for f32 {}
impl Coefficient for Vec4 {}

/// Forward transform of the `n`×`n` row-major block in place (`n` a power of
/// two, at most [`PATCH`]).
pub fn forward<T: Coefficient>(block: &mut [T], n: usize) {
    forward_from(block, n, n);
}

/// [`forward`] from the level whose low-pass quadrant is `size`×`size`
/// (the top-left of the `n`×`n` block) down: the finer levels are taken as
/// done.
fn forward_from<T: Coefficient>(block: &mut [T], n: usize, size: usize) {
    assert!(n.is_power_of_two() && n <= PATCH && block.len() == n * n);
    assert!(size.is_power_of_two() && size <= n);
    // Rows go from the block to `rows`, columns from `rows` back to the block.
    let mut rows = [T::default(); PATCH * PATCH];
    let mut size = size;
    while size > 1 {
        let half = size / 2;
        for (source, out) in block
            .chunks_exact(n)
            .zip(rows.chunks_exact_mut(n))
            .take(size)
        {
            let (sum, difference) = out[..size].split_at_mut(half);
            for (i, pair) in source[..size].chunks_exact(2).enumerate() {
                sum[i] = (pair[0] + pair[1]) * std::f32::consts::FRAC_1_SQRT_2;
                difference[i] = (pair[0] - pair[1]) * std::f32::consts::FRAC_1_SQRT_2;
            }
        }
        // Columns, on whole rows at once: the row pair (2i, 2i+1) gives
        // output rows i (sums) and half + i (differences).
        for i in 0..half {
            let (upper, lower) = rows[2 * i * n..].split_at(n);
            let (sum, rest) = block[i * n..].split_at_mut(n);
            let difference = &mut rest[(half - 1) * n..];
            for (col, (&a, &b)) in upper[..size].iter().zip(&lower[..size]).enumerate() {
                sum[col] = (a + b) * std::f32::consts::FRAC_1_SQRT_2;
                difference[col] = (a - b) * std::f32::consts::FRAC_1_SQRT_2;
            }
        }
        size = half;
    }
}

/// Inverse of [`forward`].
pub fn inverse(block: &mut [f32], n: usize) {
    assert!(n.is_power_of_two() && n <= PATCH && block.len() == n * n);
    let mut scratch = [0.0f32; PATCH];
    let mut column = [0.0f32; PATCH];
    let mut size = 2;
    while size <= n {
        for col in 0..size {
            for (r, v) in column[..size].iter_mut().enumerate() {
                *v = block[r * n + col];
            }
            unstep(&mut column[..size], &mut scratch);
            for (r, v) in column[..size].iter().enumerate() {
                block[r * n + col] = *v;
            }
        }
        for row in 0..size {
            unstep(&mut block[row * n..row * n + size], &mut scratch);
        }
        size *= 2;
    }
}

/// One inverse level along a line: averages in the first half and details
/// in the second back to pairs.
fn unstep(line: &mut [f32], scratch: &mut [f32]) {
    let half = line.len() / 2;
    for i in 0..half {
        let (s, d) = (line[i], line[half + i]);
        scratch[2 * i] = (s + d) * std::f32::consts::FRAC_1_SQRT_2;
        scratch[2 * i + 1] = (s - d) * std::f32::consts::FRAC_1_SQRT_2;
    }
    line.copy_from_slice(&scratch[..line.len()]);
}

/// The signatures of the first `bands` channels of a transformed block (a
/// lane per channel), channel after channel: mean, then for each level from
/// the finest the RMS of its horizontal, vertical and diagonal details.
fn channel_signatures(coefficients: &[Vec4], bands: usize, out: &mut Vec<f32>) {
    let n = PATCH;
    let mut features = [Vec4::ZERO; FEATURES_PER_CHANNEL];
    features[0] = coefficients[0] / n as f32;
    let mut size = n;
    let mut next = 1;
    while size > 1 {
        let half = size / 2;
        let rms = |x0: usize, y0: usize| {
            let mut sum = Vec4::ZERO;
            for y in y0..y0 + half {
                for &c in &coefficients[y * n + x0..y * n + x0 + half] {
                    sum += c * c;
                }
            }
            Vec4::from_array((sum / (half * half) as f32).to_array().map(f32::sqrt))
        };
        // Rows were transformed first: the right half holds horizontal
        // differences, the bottom half vertical ones.
        features[next] = rms(half, 0);
        features[next + 1] = rms(0, half);
        features[next + 2] = rms(half, half);
        next += 3;
        size = half;
    }
    for c in 0..bands {
        out.extend(features.iter().map(|f| f[c]));
    }
}

/// Signature of region `index` of a segmentation: over its own pixels when
/// its bounding box spans `window_px` both ways, else over the window of
/// `window` around it, neighbours included (a small region is a fragment of
/// a texture that only shows at the window's scale).
pub fn region_signature(
    image: &Image,
    segmentation: &Segmentation,
    index: usize,
    window_px: u32,
) -> Vec<f32> {
    let region = &segmentation.regions[index];
    let [x0, y0, x1, y1] = region.bbox;
    let large = x1 - x0 >= window_px && y1 - y0 >= window_px;
    let area = window(region, window_px, image.width, image.height);
    let only = large.then_some((segmentation.labels.as_slice(), index as u32));
    signature(image, area, only)
}

/// The window a region is described by: its bounding box grown about its
/// centre to at least `min_side` pixels each way, clipped to the image.
fn window(region: &Segment, min_side: u32, width: usize, height: usize) -> [u32; 4] {
    let grow = |lo: u32, hi: u32, limit: usize| {
        let side = (hi - lo).max(min_side).min(limit as u32);
        let centre = (lo + hi) / 2;
        let start = centre.saturating_sub(side / 2).min(limit as u32 - side);
        (start, start + side)
    };
    let (x0, x1) = grow(region.bbox[0], region.bbox[2], width);
    let (y0, y1) = grow(region.bbox[1], region.bbox[3], height);
    [x0, y0, x1, y1]
}

/// Signature of a region: the pixels of `window` `[x0, y0, x1, y1)` are
/// resampled to [`PATCH`]² cells by averaging (large windows are sampled on a
/// grid of at most 4 samples per cell side), then each opponent channel is
/// transformed and summarised. Length `bands · FEATURES_PER_CHANNEL`.
///
/// With `only` = `Some((labels, region))`, only that region's pixels count
/// and cells without any take the region's mean: a region larger than the
/// window is described by itself, not by its neighbours.
pub fn signature(image: &Image, window: [u32; 4], only: Option<(&[u32], u32)>) -> Vec<f32> {
    let (ww, wh) = (window[2] - window[0], window[3] - window[1]);
    if only.is_none() && ww == wh && (PATCH as u32).is_multiple_of(ww) {
        replicated_signature(image, window)
    } else {
        resampled_signature(image, window, only)
    }
}

/// [`signature`] of a square window whose side divides [`PATCH`] (the
/// default 8-pixel window of small regions): resampling repeats each pixel
/// into a square of cells, so each of the transform's finest levels only
/// finds zero details and scales the low-pass values. Those levels are
/// applied to the pixels directly, with the same floating-point operations
/// the full transform does on repeated pairs, and the transform goes on
/// from the window's size: the result is bit for bit the resampled one, at
/// a quarter of the work or less.
fn replicated_signature(image: &Image, window: [u32; 4]) -> Vec<f32> {
    let [x0, y0, x1, y1] = window.map(|v| v as usize);
    let side = x1 - x0;
    let repeat_levels = (PATCH / side).trailing_zeros();
    // One level on a repeated pair (a, a): rows give (a + a)/√2, columns
    // the same again; the details (a − a)/√2 are zero.
    let coarsen = |mut v: Vec4| {
        for _ in 0..repeat_levels {
            let row = (v + v) * std::f32::consts::FRAC_1_SQRT_2;
            v = (row + row) * std::f32::consts::FRAC_1_SQRT_2;
        }
        v
    };
    let mut block = [Vec4::ZERO; PATCH * PATCH];
    for y in y0..y1 {
        for x in x0..x1 {
            block[(y - y0) * PATCH + x - x0] = coarsen(Vec4::from_array(image.colour(x, y)));
        }
    }
    forward_from(&mut block, PATCH, side);
    let mut out = Vec::with_capacity(image.bands * FEATURES_PER_CHANNEL);
    channel_signatures(&block, image.bands, &mut out);
    out
}

/// [`signature`] by resampling the window to [`PATCH`]² cells.
fn resampled_signature(image: &Image, window: [u32; 4], only: Option<(&[u32], u32)>) -> Vec<f32> {
    let [x0, y0, x1, y1] = window.map(|v| v as usize);
    let (ww, wh) = (x1 - x0, y1 - y0);
    let stride_x = (ww / (4 * PATCH)).max(1);
    let stride_y = (wh / (4 * PATCH)).max(1);
    // Patch column of every sampled column (at most 8·PATCH of them).
    let mut cell_x = [0usize; 8 * PATCH];
    for (k, x) in (x0..x1).step_by(stride_x).enumerate() {
        cell_x[k] = (x - x0) * PATCH / ww;
    }
    let mut sums = [Vec4::ZERO; PATCH * PATCH];
    let mut counts = [0u32; PATCH * PATCH];
    for y in (y0..y1).step_by(stride_y) {
        let row = (y - y0) * PATCH / wh * PATCH;
        for (k, x) in (x0..x1).step_by(stride_x).enumerate() {
            if let Some((labels, region)) = only {
                if labels[y * image.width + x] != region {
                    continue;
                }
            }
            let at = row + cell_x[k];
            sums[at] += Vec4::from_array(image.colour(x, y));
            counts[at] += 1;
        }
    }
    // A window narrower than the patch leaves cells empty: they repeat the
    // cell holding the nearest pixel along each axis (nearest-neighbour
    // upsampling).
    let source = |n: usize| -> [usize; PATCH] {
        let n = n.min(PATCH);
        std::array::from_fn(|c| (c * n / PATCH).min(n - 1) * PATCH / n)
    };
    let (source_x, source_y) = (source(ww), source(wh));
    let source_cell: [usize; PATCH * PATCH] = std::array::from_fn(|at| {
        let (cx, cy) = (at % PATCH, at / PATCH);
        if counts[at] == 0 && only.is_none() {
            source_y[cy] * PATCH + source_x[cx]
        } else {
            at
        }
    });
    // Cells left without pixels take the window's mean.
    let mut mean = Vec4::ZERO;
    if source_cell.iter().any(|&at| counts[at] == 0) {
        let total: u32 = counts.iter().sum();
        for &cell in &sums {
            mean += cell / total.max(1) as f32;
        }
    }
    let mut block = [Vec4::ZERO; PATCH * PATCH];
    for (value, &at) in block.iter_mut().zip(&source_cell) {
        *value = if counts[at] == 0 {
            mean
        } else {
            sums[at] / counts[at] as f32
        };
    }
    forward(&mut block, PATCH);
    let mut out = Vec::with_capacity(image.bands * FEATURES_PER_CHANNEL);
    channel_signatures(&block, image.bands, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pseudo_random(n: usize) -> Vec<f32> {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state % 1000) as f32 / 10.0
            })
            .collect()
    }

    #[test]
    fn transform_is_invertible_and_orthonormal() {
        for n in [2usize, 4, 8, 16] {
            let original = pseudo_random(n * n);
            let mut block = original.clone();
            forward(&mut block, n);
            let energy = |v: &[f32]| v.iter().map(|x| (*x as f64).powi(2)).sum::<f64>();
            assert!((energy(&block) / energy(&original) - 1.0).abs() < 1e-5);
            inverse(&mut block, n);
            for (a, b) in block.iter().zip(&original) {
                assert!((a - b).abs() < 1e-3, "n {n}: {a} vs {b}");
            }
        }
        // Orthonormal basis: transforming unit vectors gives orthonormal rows.
        let n = 4;
        let basis: Vec<Vec<f32>> = (0..n * n)
            .map(|i| {
                let mut e = vec![0.0; n * n];
                e[i] = 1.0;
                forward(&mut e, n);
                e
            })
            .collect();
        for i in 0..n * n {
            for j in 0..n * n {
                let dot: f32 = basis[i].iter().zip(&basis[j]).map(|(a, b)| a * b).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-5);
            }
        }
    }

    /// The shortcut for square windows dividing the patch gives the
    /// resampled signature bit for bit, on a real image's windows.
    #[test]
    fn repeated_pixels_shortcut_equals_resampling() {
        let image = crate::testdata::soap_061();
        for side in [1u32, 2, 4, 8, 16] {
            for (x, y) in [(0u32, 0u32), (37, 91), (200, 13), (392, 392), (150, 301)] {
                let (x, y) = (x.min(400 - side), y.min(400 - side));
                let window = [x, y, x + side, y + side];
                let shortcut = replicated_signature(&image, window);
                let resampled = resampled_signature(&image, window, None);
                let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&shortcut), bits(&resampled), "side {side} at {x},{y}");
            }
        }
    }

    #[test]
    fn constant_has_only_the_mean_and_stripes_only_their_band() {
        // Channel 0 flat at 7; channel 1 columns alternating 0/10: finest
        // horizontal detail only (rows give −10/√2 per pair, columns then
        // add two such rows: −10).
        let mut block: Vec<Vec4> = (0..PATCH * PATCH)
            .map(|i| Vec4::new(7.0, if i % 2 == 0 { 0.0 } else { 10.0 }, 0.0, 0.0))
            .collect();
        forward(&mut block, PATCH);
        let mut sig = Vec::new();
        channel_signatures(&block, 2, &mut sig);
        assert_eq!(sig.len(), 2 * FEATURES_PER_CHANNEL);
        let (flat, stripes) = sig.split_at(FEATURES_PER_CHANNEL);
        assert!((flat[0] - 7.0).abs() < 1e-4);
        assert!(flat[1..].iter().all(|v| v.abs() < 1e-4));
        assert!((stripes[0] - 5.0).abs() < 1e-4);
        assert!((stripes[1] - 10.0).abs() < 1e-3, "{stripes:?}");
        assert!(stripes[2..].iter().all(|v| v.abs() < 1e-3), "{stripes:?}");
    }

    /// Transforming the channels side by side (a lane each) gives each
    /// channel's own transform bit for bit.
    #[test]
    fn lanes_transform_as_each_channel_alone() {
        let values = pseudo_random(4 * PATCH * PATCH);
        let channels: Vec<&[f32]> = values.chunks_exact(PATCH * PATCH).collect();
        let mut lanes: Vec<Vec4> = (0..PATCH * PATCH)
            .map(|i| Vec4::from_array(std::array::from_fn(|c| channels[c][i])))
            .collect();
        forward(&mut lanes, PATCH);
        for (c, channel) in channels.iter().enumerate() {
            let mut alone = channel.to_vec();
            forward(&mut alone, PATCH);
            let bits = |v: &mut dyn Iterator<Item = f32>| v.map(f32::to_bits).collect::<Vec<_>>();
            assert_eq!(
                bits(&mut lanes.iter().map(|l| l[c])),
                bits(&mut alone.into_iter())
            );
        }
    }
}
