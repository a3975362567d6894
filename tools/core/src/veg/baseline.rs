//! A simple baseline to measure the Haar-signature detector against: the
//! excess-green index ExG = 2g − r − b of chromatic coordinates (Woebbecke et
//! al., "Color indices for weed identification", 1995), thresholded by Otsu's
//! method, with a crown at each local maximum of the smoothed index inside
//! that mask (the local-maximum filtering of Wulder, Niemann & Goodenough
//! 2000, as the detector places crowns).

use super::detect::place_crowns;
use super::eval::Detection;
use super::Image;

/// Crowns `spacing_px` apart at the local maxima of excess green inside
/// its Otsu mask, each with a disc of at least `min_radius_px` of the mask
/// around it: centre in pixels, score the smoothed index, and the
/// diameter the window's, `spacing_px` (fixed-window local-maximum
/// filtering takes the window as the expected crown). Bands must be R, G,
/// B.
pub fn excess_green_crowns(image: &Image, spacing_px: f32, min_radius_px: f32) -> Vec<Detection> {
    let (w, h) = (image.width, image.height);
    let outside: Vec<bool> = excess_green_mask(image).iter().map(|&v| !v).collect();
    let mut value: Vec<f32> = image.pixels.chunks_exact(image.bands).map(exg).collect();
    let crowns = place_crowns(
        &mut value,
        &mut Vec::new(),
        &outside,
        w,
        h,
        spacing_px,
        min_radius_px,
        None,
    );
    crowns
        .into_iter()
        .map(|(i, _)| Detection {
            x: (i % w) as f64 + 0.5,
            y: (i / w) as f64 + 0.5,
            diameter: spacing_px as f64,
            score: value[i],
        })
        .collect()
}

/// Excess green of an R, G, B pixel, −1 to 2.
fn exg(p: &[u8]) -> f32 {
    let (r, g, b) = (p[0] as f32, p[1] as f32, p[2] as f32);
    (2.0 * g - r - b) / (r + g + b).max(1.0)
}

/// Per pixel, row-major: whether its ExG exceeds the image's Otsu threshold
/// (the pixels the baseline calls vegetation). Bands must be R, G, B.
pub fn excess_green_mask(image: &Image) -> Vec<bool> {
    assert!(image.bands >= 3, "excess green needs R, G, B");
    // ExG ∈ [−1, 2] mapped to 256 bins.
    let bins: Vec<u8> = image
        .pixels
        .chunks_exact(image.bands)
        .map(|p| (((exg(p) + 1.0) / 3.0) * 255.0).round().clamp(0.0, 255.0) as u8)
        .collect();
    let threshold = otsu(&bins);
    bins.iter().map(|&v| v > threshold).collect()
}

/// Otsu's threshold of 8-bit values: the level maximising between-class variance.
pub fn otsu(values: &[u8]) -> u8 {
    let mut histogram = [0u64; 256];
    for &v in values {
        histogram[v as usize] += 1;
    }
    let total = values.len() as f64;
    let sum_all: f64 = histogram
        .iter()
        .enumerate()
        .map(|(k, &c)| k as f64 * c as f64)
        .sum();
    let (mut below, mut sum_below) = (0.0f64, 0.0f64);
    let (mut best, mut best_level) = (-1.0f64, 0u8);
    for (k, &c) in histogram.iter().enumerate() {
        below += c as f64;
        sum_below += k as f64 * c as f64;
        let above = total - below;
        if below == 0.0 || above == 0.0 {
            continue;
        }
        let (m0, m1) = (sum_below / below, (sum_all - sum_below) / above);
        let between = below * above * (m0 - m1).powi(2);
        if between > best {
            best = between;
            best_level = k as u8;
        }
    }
    best_level
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn otsu_splits_two_modes() {
        let mut v = vec![40u8; 100];
        v.extend(vec![200u8; 50]);
        let t = otsu(&v);
        assert!((40..200).contains(&t));
    }

    #[test]
    fn green_crowns_are_found_at_their_middles() {
        // Two green crowns (darker, so less green, at their rims) on grey
        // soil, 12 pixels apart.
        let (w, h) = (30, 16);
        let mut px = vec![120u8; w * h * 3];
        for (cx, cy) in [(8i64, 8i64), (20, 8)] {
            for y in 0..h as i64 {
                for x in 0..w as i64 {
                    let d2 = (x - cx).pow(2) + (y - cy).pow(2);
                    if d2 <= 16 {
                        let i = (y as usize * w + x as usize) * 3;
                        let g = 200 - 8 * d2 as u8;
                        px[i..i + 3].copy_from_slice(&[60, g, 50]);
                    }
                }
            }
        }
        let image = Image::new(w, h, 3, px).unwrap();
        let mut found = excess_green_crowns(&image, 6.0, 1.0);
        found.sort_by(|a, b| a.x.total_cmp(&b.x));
        let centres: Vec<(f64, f64)> = found.iter().map(|d| (d.x, d.y)).collect();
        assert_eq!(centres, [(8.5, 8.5), (20.5, 8.5)]);
        assert!(found.iter().all(|d| d.diameter == 6.0));
    }
}
