//! How far one RGBA8 image is from another: the metric Relevo's own
//! snapshot tests judge rendered frames by, and `relevo check` and
//! `relevo diff` report: the share of pixels with any colour channel more
//! than a threshold off, the mean absolute difference over every channel,
//! and the peak signal-to-noise ratio of the colour channels.

use serde::{Deserialize, Serialize};

/// The difference between two images of one size.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImageDifference {
    /// Pixels with any of R, G, B, A more than `threshold` levels off.
    pub pixels_off: usize,
    /// Pixels compared.
    pub pixels: usize,
    /// The threshold `pixels_off` counts against, levels.
    pub threshold: u8,
    /// Mean absolute difference over all channels, levels.
    pub mean: f64,
    /// PSNR of R, G and B, dB (infinite when they are equal).
    pub psnr_db: f64,
}

impl ImageDifference {
    /// The share of pixels off, 0–1.
    pub fn share_off(&self) -> f64 {
        self.pixels_off as f64 / self.pixels.max(1) as f64
    }
}

/// Compare RGBA8 `actual` with `expected` (the same length, 4 bytes a
/// pixel); `None` when their lengths differ.
///
/// ```
/// use relevo_core::raster::compare::difference;
/// let a = [10u8, 20, 30, 255, 0, 0, 0, 255];
/// let b = [10u8, 20, 60, 255, 0, 0, 0, 255];
/// let d = difference(&a, &b, 16).unwrap();
/// assert_eq!((d.pixels_off, d.pixels), (1, 2));
/// assert!((d.mean - 30.0 / 8.0).abs() < 1e-12);
/// assert!(difference(&a, &a, 0).unwrap().psnr_db.is_infinite());
/// ```
pub fn difference(actual: &[u8], expected: &[u8], threshold: u8) -> Option<ImageDifference> {
    if actual.len() != expected.len() || !actual.len().is_multiple_of(4) {
        return None;
    }
    let pixels = actual.len() / 4;
    let (mut pixels_off, mut absolute, mut squared) = (0usize, 0u64, 0u64);
    for (a, b) in actual.chunks_exact(4).zip(expected.chunks_exact(4)) {
        let mut off = false;
        for k in 0..4 {
            let d = a[k].abs_diff(b[k]);
            off |= d > threshold;
            absolute += u64::from(d);
            if k < 3 {
                squared += u64::from(d) * u64::from(d);
            }
        }
        pixels_off += usize::from(off);
    }
    let mse = squared as f64 / (3 * pixels).max(1) as f64;
    Some(ImageDifference {
        pixels_off,
        pixels,
        threshold,
        mean: absolute as f64 / actual.len().max(1) as f64,
        psnr_db: if mse == 0.0 {
            f64::INFINITY
        } else {
            10.0 * (255.0f64 * 255.0 / mse).log10()
        },
    })
}

/// A picture of where two images differ: per pixel the largest channel
/// difference, amplified eightfold, in red on black.
pub fn difference_image(actual: &[u8], expected: &[u8]) -> Vec<u8> {
    actual
        .chunks_exact(4)
        .zip(expected.chunks_exact(4))
        .flat_map(|(a, b)| {
            let d = (0..3).map(|k| a[k].abs_diff(b[k])).max().unwrap_or(0);
            [d.saturating_mul(8), 0, 0, 255]
        })
        .collect()
}
