//! A simple baseline to measure the Haar-signature detector against: the
//! excess-green index ExG = 2g − r − b of chromatic coordinates (Woebbecke et
//! al., "Color indices for weed identification", 1995), thresholded by Otsu's
//! method, and one object per 4-connected component.

use super::Image;

/// Objects `(x, y, score)` in pixel coordinates: the centroid of every
/// 4-connected component of at least `min_area` pixels whose ExG exceeds the
/// Otsu threshold; score is the component's area. Bands must be R, G, B.
pub fn excess_green(image: &Image, min_area: usize) -> Vec<(f64, f64, f32)> {
    let (w, h) = (image.width, image.height);
    let mut seen: Vec<bool> = excess_green_mask(image).iter().map(|&v| !v).collect();
    let mut objects = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let (mut n, mut sx, mut sy) = (0usize, 0.0f64, 0.0f64);
        while let Some(i) = stack.pop() {
            n += 1;
            sx += (i % w) as f64 + 0.5;
            sy += (i / w) as f64 + 0.5;
            for j in crate::grid::neighbours4(i, w, h) {
                if !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        if n >= min_area {
            objects.push((sx / n as f64, sy / n as f64, n as f32));
        }
    }
    objects
}

/// Per pixel, row-major: whether its ExG exceeds the image's Otsu threshold
/// (the pixels the baseline calls vegetation). Bands must be R, G, B.
pub fn excess_green_mask(image: &Image) -> Vec<bool> {
    assert!(image.bands >= 3, "excess green needs R, G, B");
    // ExG ∈ [−1, 2] mapped to 256 bins.
    let bins: Vec<u8> = image
        .pixels
        .chunks_exact(image.bands)
        .map(|p| {
            let (r, g, b) = (p[0] as f32, p[1] as f32, p[2] as f32);
            let sum = (r + g + b).max(1.0);
            let exg = (2.0 * g - r - b) / sum;
            (((exg + 1.0) / 3.0) * 255.0).round().clamp(0.0, 255.0) as u8
        })
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
    fn green_blobs_become_objects() {
        // Two green squares on grey soil.
        let (w, h) = (20, 10);
        let mut px = vec![120u8; w * h * 3];
        for (x0, y0) in [(2, 2), (12, 4)] {
            for y in y0..y0 + 4 {
                for x in x0..x0 + 4 {
                    px[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[60, 160, 50]);
                }
            }
        }
        let image = Image::new(w, h, 3, px).unwrap();
        let found = excess_green(&image, 4);
        assert_eq!(found, vec![(4.0, 4.0, 16.0), (14.0, 6.0, 16.0)]);
    }
}
