//! The WGS84 ellipsoid: Earth-centred, Earth-fixed (ECEF) positions of
//! geodetic coordinates, the local east/north/up frame, and the horizon
//! occlusion point clients cull tiles with. The CRS and vertical datum
//! transforms are PROJ's (through GDAL, in the CLI); this is only the
//! ellipsoid's closed form, which the tiles' headers need for every vertex.

/// WGS84 semi-major axis, metres, and flattening (NIMA TR8350.2, table 3.1).
pub const SEMI_MAJOR_AXIS_M: f64 = 6_378_137.0;
pub const FLATTENING: f64 = 1.0 / 298.257_223_563;

/// Semi-minor axis, metres.
pub fn semi_minor_axis_m() -> f64 {
    SEMI_MAJOR_AXIS_M * (1.0 - FLATTENING)
}

/// ECEF position (metres) of longitude, latitude (degrees) and height above
/// the ellipsoid (metres): X = (N + h) cos φ cos λ, Y = (N + h) cos φ sin λ,
/// Z = (N (1 − e²) + h) sin φ with N = a / √(1 − e² sin² φ).
pub fn ecef_from_geodetic(lon_deg: f64, lat_deg: f64, height_m: f64) -> [f64; 3] {
    let e2 = FLATTENING * (2.0 - FLATTENING);
    let (lambda, phi) = (lon_deg.to_radians(), lat_deg.to_radians());
    let n = SEMI_MAJOR_AXIS_M / (1.0 - e2 * phi.sin().powi(2)).sqrt();
    [
        (n + height_m) * phi.cos() * lambda.cos(),
        (n + height_m) * phi.cos() * lambda.sin(),
        (n * (1.0 - e2) + height_m) * phi.sin(),
    ]
}

/// Unit vectors east, north and up (the ellipsoid's normal) at a point, in
/// ECEF.
pub fn east_north_up(lon_deg: f64, lat_deg: f64) -> [[f64; 3]; 3] {
    let (sl, cl) = lon_deg.to_radians().sin_cos();
    let (sp, cp) = lat_deg.to_radians().sin_cos();
    [
        [-sl, cl, 0.0],
        [-sp * cl, -sp * sl, cp],
        [cp * cl, cp * sl, sp],
    ]
}

/// The horizon occlusion point of `points` (ECEF, metres) along
/// `direction` (ECEF): the point, in the ellipsoid-scaled frame (each axis
/// divided by its radius, where the ellipsoid is the unit sphere), nearest
/// the centre along the direction that is hidden by the ellipsoid only
/// when all the points are. For a scaled point p (|p| ≥ 1) at angle α from
/// the direction, with cos β = 1/|p|, the horizon plane of p crosses the
/// direction at 1 / cos(α + β); the point is the farthest of those. `None`
/// when a point sees past the direction's horizon (α + β ≥ 90°).
pub fn horizon_occlusion_point(points: &[[f64; 3]], direction: [f64; 3]) -> Option<[f64; 3]> {
    let radii = [SEMI_MAJOR_AXIS_M, SEMI_MAJOR_AXIS_M, semi_minor_axis_m()];
    let scaled = |p: [f64; 3]| [0, 1, 2].map(|k| p[k] / radii[k]);
    let d = unit(scaled(direction))?;
    let mut farthest: f64 = 0.0;
    for &p in points {
        let p = scaled(p);
        let magnitude = norm(p).max(1.0);
        let u = unit(p)?;
        let cos_alpha = dot(u, d).clamp(-1.0, 1.0);
        let sin_alpha = norm(cross(u, d));
        let cos_beta = 1.0 / magnitude;
        let sin_beta = (1.0 - cos_beta * cos_beta).max(0.0).sqrt();
        let denominator = cos_alpha * cos_beta - sin_alpha * sin_beta;
        if denominator <= 0.0 {
            return None;
        }
        farthest = farthest.max(1.0 / denominator);
    }
    Some(d.map(|c| c * farthest))
}

pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// `a` scaled to length 1; `None` for the zero vector.
pub fn unit(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = norm(a);
    (n > 0.0 && n.is_finite()).then(|| a.map(|c| c / n))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ecef_matches_known_points() {
        let p = ecef_from_geodetic(0.0, 0.0, 0.0);
        assert_eq!(p, [SEMI_MAJOR_AXIS_M, 0.0, 0.0]);
        let pole = ecef_from_geodetic(0.0, 90.0, 100.0);
        assert!(
            (pole[2] - (semi_minor_axis_m() + 100.0)).abs() < 1e-6,
            "{pole:?}"
        );
        // Olinda, from PROJ (EPSG:4979 → EPSG:4978, `gdaltransform`).
        let o = ecef_from_geodetic(-34.855, -8.0, 10.0);
        let proj = [5_183_313.679_6, -3_609_880.882_5, -881_781.298_5];
        for k in 0..3 {
            assert!((o[k] - proj[k]).abs() < 1e-3, "{o:?} vs {proj:?}");
        }
        let [e, n, u] = east_north_up(-34.855, -8.0);
        assert!(dot(e, n).abs() < 1e-12 && dot(n, u).abs() < 1e-12);
        assert!((dot(u, unit(o).unwrap()) - 1.0).abs() < 1e-4);
    }

    #[test]
    fn the_occlusion_point_hides_its_points_only_behind_the_horizon() {
        let points: Vec<[f64; 3]> = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .map(|&(lon, lat)| ecef_from_geodetic(lon, lat, 2000.0))
            .collect();
        let centre = ecef_from_geodetic(0.0, 0.0, 0.0);
        let o = horizon_occlusion_point(&points, centre).unwrap();
        // Outside the unit sphere, along the centre's direction.
        assert!(norm(o) > 1.0 && o[1].abs() < 1e-12 && o[2].abs() < 1e-12);
        // A point at the antipode cannot be occluded by anything.
        let far = [ecef_from_geodetic(180.0, 0.0, 0.0)];
        assert!(horizon_occlusion_point(&far, centre).is_none());
    }
}
