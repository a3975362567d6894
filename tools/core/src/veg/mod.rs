//! Vegetation extraction from imagery (Savelli & Seixas; vegetation thesis,
//! chapter 3): split-and-merge segmentation, Haar-wavelet signatures learnt
//! from user-marked samples, classification of every region, and objects
//! (crowns, or regions filled at a density) written as a vegetation database.
//!
//! - [`Image`]: the analysed bands as 8-bit values and the colour space the
//!   homogeneity predicate works in.
//! - [`segment`]: split-and-merge into homogeneous, 4-connected regions.
//! - [`haar`]: the orthonormal 2-D Haar transform and region signatures.
//! - [`samples`]: marked samples (semicolon CSV rectangles, GeoJSON polygons).
//! - [`classify`]: nearest-signature classifier with a score.
//! - [`detect`]: vegetation objects from classified regions.
//! - [`spacing`]: the crown spacing learnt from the marked crowns.
//! - [`template`]: the marked crowns' brightness pattern, and each place's
//!   likeness to it.
//! - [`db`]: the `id;x;y;class;size;score` database.
//! - [`eval`]: precision, recall and F1 against truth boxes.
//! - [`tiles`]: cutting a large image into tiles with a margin of context.
//! - [`pipeline`]: the whole extraction on one image, tile by tile (options,
//!   report, overlay), as every program runs it.
//! - [`baseline`]: excess-green crowns, to measure against.
//! - [`protocol`]: leave-one-image-out figures and the correction loop of a
//!   simulated user.

/// `$body` with `$n` a constant equal to the band count `$bands` (1, 2 or
/// 3; [`MAX_BANDS`] for any more): one compiled body per band count, so the
/// loops over bands that run per pixel or per leaf are unrolled and hold
/// nothing for bands the image lacks.
macro_rules! with_band_count {
    ($bands:expr, $n:ident => $body:expr) => {
        match $bands {
            1 => {
                const $n: usize = 1;
                $body
            }
            2 => {
                const $n: usize = 2;
                $body
            }
            3 => {
                const $n: usize = 3;
                $body
            }
            _ => {
                const $n: usize = $crate::veg::MAX_BANDS;
                $body
            }
        }
    };
}

pub mod baseline;
pub mod classify;
pub mod db;
pub mod detect;
pub mod eval;
pub mod haar;
pub mod pipeline;
pub mod protocol;
pub mod samples;
pub mod segment;
pub mod spacing;
pub mod template;
pub mod tiles;

use crate::{Error, Result};
use rayon::prelude::*;

/// Most bands the analysis takes (e.g. R, G, B, NIR).
pub const MAX_BANDS: usize = 4;

/// Bands of an image as 8-bit values, pixel-interleaved, row-major. Deeper
/// imagery is stretched to 8 bits before it gets here, so thresholds are in
/// the same units for every input.
#[derive(Debug, Clone)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub bands: usize,
    pub pixels: Vec<u8>,
}

impl Image {
    pub fn new(width: usize, height: usize, bands: usize, pixels: Vec<u8>) -> Result<Image> {
        if width == 0 || height == 0 {
            return Err(Error::Input(format!("image is {width}×{height}: empty")));
        }
        if !(1..=MAX_BANDS).contains(&bands) {
            return Err(Error::Input(format!(
                "{bands} bands: the analysis takes 1 to {MAX_BANDS}"
            )));
        }
        if pixels.len() != width * height * bands {
            return Err(Error::Input(format!(
                "{} values for a {width}×{height} image of {bands} bands",
                pixels.len()
            )));
        }
        Ok(Image {
            width,
            height,
            bands,
            pixels,
        })
    }

    /// Replace `out` by every pixel's brightness (the first opponent
    /// component, [`opponent`]), row by row.
    pub fn brightness_into(&self, out: &mut Vec<f32>) {
        out.clear();
        out.par_extend(
            self.pixels
                .par_chunks_exact(self.bands)
                .map(|px| opponent(px)[0]),
        );
    }

    /// Span between the 1st and 99th percentiles of brightness (the mean of
    /// the bands), in 8-bit units: how much of the range the image uses.
    pub fn brightness_span(&self) -> f32 {
        // Band sums counted in parts of 65 536 pixels in parallel, then
        // added up and folded to brightness levels (sum / bands).
        fn count<const N: usize>(part: &[u8], sums: &mut [u64]) {
            for px in part.chunks_exact(N) {
                sums[px.iter().map(|&v| v as usize).sum::<usize>()] += 1;
            }
        }
        let sums = self
            .pixels
            .par_chunks(self.bands * 65_536)
            .map(|part| {
                let mut sums = vec![0u64; 255 * MAX_BANDS + 1];
                with_band_count!(self.bands, N => count::<N>(part, &mut sums));
                sums
            })
            .reduce(
                || vec![0u64; 255 * MAX_BANDS + 1],
                |mut a, b| {
                    a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
                    a
                },
            );
        let mut histogram = [0u64; 256];
        for (sum, &count) in sums[..=255 * self.bands].iter().enumerate() {
            histogram[sum / self.bands] += count;
        }
        let n = (self.width * self.height) as u64;
        let level = |fraction: f64| {
            let target = (fraction * n as f64).ceil() as u64;
            let mut seen = 0;
            histogram
                .iter()
                .position(|&c| {
                    seen += c;
                    seen >= target.max(1)
                })
                .unwrap_or(255) as f32
        };
        level(0.99) - level(0.01)
    }

    /// The pixels of `[x0, y0, x1, y1)`, a rectangle inside the image,
    /// copied into `pixels` (whatever it held, e.g. an earlier window's).
    pub fn window(&self, [x0, y0, x1, y1]: [usize; 4], mut pixels: Vec<u8>) -> Image {
        let b = self.bands;
        pixels.clear();
        pixels.reserve((x1 - x0) * (y1 - y0) * b);
        for y in y0..y1 {
            let row = y * self.width;
            pixels.extend_from_slice(&self.pixels[(row + x0) * b..(row + x1) * b]);
        }
        Image {
            width: x1 - x0,
            height: y1 - y0,
            bands: b,
            pixels,
        }
    }

    /// The pixel at `(x, y)` in the opponent colour space of [`opponent`].
    #[inline]
    pub fn colour(&self, x: usize, y: usize) -> [f32; MAX_BANDS] {
        let at = (y * self.width + x) * self.bands;
        opponent(&self.pixels[at..at + self.bands])
    }
}

/// √(k(k+1)) for k = 0..MAX_BANDS: the norms of the Helmert rows (k ≥ 1),
/// as f32 (the nearest f32 of each root, as `f32::sqrt` gives it).
const HELMERT_NORM: [f32; MAX_BANDS] = [0.0, std::f32::consts::SQRT_2, 2.449_489_8, 3.464_101_6];

/// Map band values to an opponent colour space: channel 0 is the mean of the
/// bands (brightness, in band units); channels 1.. are the normalised Helmert
/// contrasts between bands (for R, G, B: (R−G)/√2 and (R+G−2B)/√6), an
/// orthonormal basis of the colour differences.
///
/// Why this space: sunlit and shaded sides of one crown differ mostly in
/// brightness, while crown, grass, soil and water differ in hue. Separating
/// the two lets the homogeneity predicate tolerate shading more than hue
/// change, and the contrasts being orthonormal makes a chroma threshold mean
/// the same distance whatever the direction of the hue change.
#[inline]
pub fn opponent(bands: &[u8]) -> [f32; MAX_BANDS] {
    // Unrolled per band count (the same operations).
    with_band_count!(bands.len(), N => opponent_of::<N>(bands))
}

/// [`opponent`] of the first `N` values of `bands`.
#[inline(always)]
fn opponent_of<const N: usize>(bands: &[u8]) -> [f32; MAX_BANDS] {
    let bands = &bands[..N];
    let mut out = [0.0f32; MAX_BANDS];
    let n = N;
    let mut prefix = 0.0f32;
    for (k, &v) in bands.iter().enumerate() {
        let v = v as f32;
        if k > 0 {
            // Helmert row k: (v_0 + … + v_{k−1} − k·v_k) / √(k(k+1)).
            out[k] = (prefix - k as f32 * v) / HELMERT_NORM[k];
        }
        prefix += v;
    }
    out[0] = prefix / n as f32;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opponent_separates_brightness_from_hue() {
        // Grey has no chroma at any brightness.
        for v in [0u8, 77, 255] {
            let c = opponent(&[v, v, v]);
            assert_eq!(c[0], v as f32);
            assert!(c[1].abs() < 1e-4 && c[2].abs() < 1e-4);
        }
        // Contrasts are orthonormal: a unit change of one band moves the
        // chroma by a vector whose squared length plus (1/3)·(brightness
        // change)²·3 is 1 (Helmert matrix rows are orthonormal).
        let base = opponent(&[100, 100, 100]);
        for b in 0..3 {
            let mut px = [100u8; 3];
            px[b] = 101;
            let c = opponent(&px);
            let chroma2: f32 = (1..3).map(|k| (c[k] - base[k]).powi(2)).sum();
            let mean_part = (c[0] - base[0]).powi(2) * 3.0;
            assert!((chroma2 + mean_part - 1.0).abs() < 1e-4);
        }
    }

    #[test]
    fn helmert_norms_are_the_roots() {
        for (k, &norm) in HELMERT_NORM.iter().enumerate() {
            let kf = k as f32;
            assert_eq!(norm, (kf * (kf + 1.0)).sqrt());
        }
    }

    #[test]
    fn brightness_span_of_a_ramp() {
        let pixels: Vec<u8> = (0..=255u8).flat_map(|v| [v, v, v]).collect();
        let ramp = Image::new(256, 1, 3, pixels).unwrap();
        // 1 % of 256 values from each end: about 3 levels.
        assert!((ramp.brightness_span() - 250.0).abs() <= 3.0);
        let flat = Image::new(4, 4, 1, vec![9; 16]).unwrap();
        assert_eq!(flat.brightness_span(), 0.0);
    }

    #[test]
    fn image_rejects_bad_shapes() {
        assert!(Image::new(0, 3, 3, vec![]).is_err());
        assert!(Image::new(2, 2, 5, vec![0; 20]).is_err());
        assert!(Image::new(2, 2, 3, vec![0; 11]).is_err());
    }
}
