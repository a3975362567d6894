//! A drape derived from the terrain itself, for DEMs without imagery: a
//! hypsometric tint (colour by height) with a baked hillshade — the
//! pre-illumination the floating-horizon thesis lists as future work
//! (Szenberg 1997, §9.1), in the manner of VistaPro's lit colour maps.

use crate::grid::vertex_normal_of;

/// Colour stops of the tint: (fraction of the height range, RGB).
const STOPS: [(f64, [f64; 3]); 6] = [
    (0.00, [72.0, 120.0, 64.0]),
    (0.25, [132.0, 160.0, 88.0]),
    (0.50, [196.0, 182.0, 120.0]),
    (0.70, [160.0, 124.0, 92.0]),
    (0.88, [150.0, 146.0, 142.0]),
    (1.00, [246.0, 246.0, 250.0]),
];

/// Sun of the baked hillshade: azimuth 315°, elevation 45°, 35 % ambient.
const SUN: [f64; 3] = [-0.5, 0.5, std::f64::consts::FRAC_1_SQRT_2];
const AMBIENT: f64 = 0.35;

/// The tint of a height `t` of the way up the range (clamped to 0..1).
pub fn hypsometric(t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    let k = STOPS
        .iter()
        .position(|s| s.0 >= t)
        .unwrap_or(STOPS.len() - 1)
        .max(1);
    let ((t0, c0), (t1, c1)) = (STOPS[k - 1], STOPS[k]);
    let f = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
    [0, 1, 2].map(|i| c0[i] + (c1[i] - c0[i]) * f)
}

/// RGBA8 of a `side`² grid of `heights` (metres, row 0 north) with
/// `cell`-metre spacing, one pixel per vertex: the tint over
/// `height_range_m` times Lambert shading; transparent where `mask` is 0.
pub fn terrain_drape(
    heights: &[f32],
    mask: &[u8],
    side: usize,
    cell: f64,
    height_range_m: [f32; 2],
) -> Vec<u8> {
    let mut rgba = vec![0u8; side * side * 4];
    let z = |c: usize, r: usize| heights[r * side + c];
    for (i, px) in rgba.chunks_exact_mut(4).enumerate() {
        if mask[i] == 1 {
            px.copy_from_slice(&drape_pixel(
                &z,
                side,
                cell,
                height_range_m,
                (i % side, i / side),
            ));
        }
    }
    rgba
}

/// The drape's pixel at vertex (c, r) of a `side`² grid whose heights `z`
/// gives (global column, row): the tint times the Lambert shading, opaque.
/// [`terrain_drape`] is this at every vertex with data.
pub fn drape_pixel(
    z: &dyn Fn(usize, usize) -> f32,
    side: usize,
    cell: f64,
    height_range_m: [f32; 2],
    (c, r): (usize, usize),
) -> [u8; 4] {
    let [lo, hi] = height_range_m.map(|h| h as f64);
    let span = (hi - lo).max(1e-6);
    let n = vertex_normal_of(z, side, cell, c, r);
    let lambert = (n[0] * SUN[0] + n[1] * SUN[1] + n[2] * SUN[2]).max(0.0);
    let light = AMBIENT + (1.0 - AMBIENT) * lambert;
    let tint = hypsometric((z(c, r) as f64 - lo) / span);
    let mut px = [0, 0, 0, 255];
    for k in 0..3 {
        px[k] = (tint[k] * light).round().clamp(0.0, 255.0) as u8;
    }
    px
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testdata;

    #[test]
    fn the_tint_runs_from_green_lowlands_to_white_summits() {
        assert_eq!(hypsometric(0.0), STOPS[0].1);
        assert_eq!(hypsometric(1.0), STOPS[5].1);
        assert_eq!(hypsometric(-3.0), STOPS[0].1);
        let mid = hypsometric(0.125);
        assert!((0..3).all(|c| mid[c] > STOPS[0].1[c].min(STOPS[1].1[c]) - 1e-9));
    }

    #[test]
    fn a_real_dem_is_lit_from_the_north_west_and_voids_stay_transparent() {
        let dem = testdata::dem("copernicus_grenoble_257.f32");
        let side = dem.side;
        let mut mask = vec![1u8; side * side];
        mask[0] = 0;
        let lo = dem.heights.iter().copied().fold(f32::MAX, f32::min);
        let hi = dem.heights.iter().copied().fold(f32::MIN, f32::max);
        let rgba = terrain_drape(&dem.heights, &mask, side, dem.cell_size_m, [lo, hi]);
        assert_eq!(&rgba[..4], &[0, 0, 0, 0]);
        assert!(rgba.chunks_exact(4).skip(1).all(|p| p[3] == 255));
        // Slopes facing the sun are brighter than those facing away.
        let (mut towards, mut away) = (Vec::new(), Vec::new());
        for i in 1..side * side {
            let n =
                crate::grid::vertex_normal(&dem.heights, side, dem.cell_size_m, i % side, i / side);
            if n[2] > 0.95 {
                continue;
            }
            let brightness: u32 = rgba[i * 4..i * 4 + 3].iter().map(|&v| v as u32).sum();
            let facing = n[0] * SUN[0] + n[1] * SUN[1];
            if facing > 0.1 {
                towards.push(brightness);
            } else if facing < -0.1 {
                away.push(brightness);
            }
        }
        let mean = |v: &[u32]| v.iter().sum::<u32>() as f64 / v.len().max(1) as f64;
        assert!(towards.len() > 100 && away.len() > 100);
        assert!(
            mean(&towards) > mean(&away) * 1.2,
            "{} vs {}",
            mean(&towards),
            mean(&away)
        );
    }
}
