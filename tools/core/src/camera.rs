//! The camera shared by every renderer and by refinement: a pinhole in the
//! terrain frame (x east, y north, z up, metres) with wgpu's clip space
//! (depth 0 at the near plane, 1 at the far plane).

use glam::{DMat4, DVec3, DVec4};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position in the terrain frame, metres.
    pub position: DVec3,
    /// Compass direction of view, degrees clockwise from north (+y).
    pub heading_deg: f64,
    /// Elevation of the view direction above the horizon, degrees.
    pub pitch_deg: f64,
    /// Vertical shift of the projection plane (the seed's `incl`): the
    /// screen row, in pixels from the bottom, that the view axis passes
    /// through. `height / 2` is the usual centred projection; the floating-
    /// horizon raycast keeps `pitch_deg` at 0 and looks down by raising it.
    pub incl_px: f64,
    /// Horizontal field of view, degrees.
    pub fov_x_deg: f64,
    /// Viewport size in pixels.
    pub width: u32,
    pub height: u32,
    /// Near and far clip distances, metres.
    pub near_m: f64,
    pub far_m: f64,
}

impl Camera {
    /// Unit view direction.
    pub fn forward(&self) -> DVec3 {
        let (h, p) = (self.heading_deg.to_radians(), self.pitch_deg.to_radians());
        DVec3::new(h.sin() * p.cos(), h.cos() * p.cos(), p.sin())
    }

    /// World → eye transform (right-handed, looking down −z).
    pub fn view(&self) -> DMat4 {
        let forward = self.forward();
        // Straight up or down: any horizontal up vector will do.
        let up = if forward.cross(DVec3::Z).length_squared() < 1e-12 {
            DVec3::Y
        } else {
            DVec3::Z
        };
        DMat4::look_to_rh(self.position, forward, up)
    }

    /// Eye → clip transform with depth in [0, 1], as wgpu expects: the
    /// off-axis frustum of seed 000, eqs. 5.1–5.6, scaled to the near plane —
    /// left/right at ∓tan(q/2), bottom at −2·tan(q/2)·incl/w and top at
    /// 2·tan(q/2)·(h − incl)/w, for horizontal field of view q.
    pub fn projection(&self) -> DMat4 {
        let (n, f) = (self.near_m, self.far_m);
        let tan = (self.fov_x_deg.to_radians() / 2.0).tan();
        let (w, h) = (self.width as f64, self.height as f64);
        let (l, r) = (-tan * n, tan * n);
        let b = -2.0 * tan * self.incl_px / w * n;
        let t = 2.0 * tan * (h - self.incl_px) / w * n;
        DMat4::from_cols(
            DVec4::new(2.0 * n / (r - l), 0.0, 0.0, 0.0),
            DVec4::new(0.0, 2.0 * n / (t - b), 0.0, 0.0),
            DVec4::new((r + l) / (r - l), (t + b) / (t - b), f / (n - f), -1.0),
            DVec4::new(0.0, 0.0, n * f / (n - f), 0.0),
        )
    }

    /// Distance from the eye to the projection plane in pixels,
    /// d = w / (2·tan(q/2)) (seed 000, chapter 7).
    pub fn plane_distance_px(&self) -> f64 {
        self.width as f64 / (2.0 * (self.fov_x_deg.to_radians() / 2.0).tan())
    }

    /// The [0, 1] depth of a point `distance_m` ahead of the eye along the
    /// view axis: (f − f·n/d)/(f − n), seed 000 eq. 5.11 with near n and far f.
    pub fn depth_at(&self, distance_m: f64) -> f64 {
        let [a, b] = self.depth_terms();
        a - b / distance_m
    }

    /// Eq. 5.11 as depth = A − B/d: [A, B] = [f/(f − n), f·n/(f − n)], for
    /// loops that divide once per distance and share the rest.
    pub fn depth_terms(&self) -> [f64; 2] {
        let (n, f) = (self.near_m, self.far_m);
        [f / (f - n), f * n / (f - n)]
    }

    pub fn view_projection(&self) -> DMat4 {
        self.projection() * self.view()
    }

    /// Pixels per radian across the screen: λ = w / φ of LP (seed 001, eq. 1).
    pub fn lambda(&self) -> f64 {
        self.width as f64 / self.fov_x_deg.to_radians()
    }

    /// The six frustum planes `[a, b, c, d]` in the terrain frame, normals
    /// unit-length and pointing inwards: a point p is inside all of them when
    /// a·x + b·y + c·z + d ≥ 0 for each (Gribb and Hartmann, "Fast Extraction
    /// of Viewing Frustum Planes from the World-View-Projection Matrix", 2001,
    /// for a [0, 1] depth range). Order: left, right, bottom, top, near, far.
    pub fn frustum_planes(&self) -> [[f64; 4]; 6] {
        let m = self.view_projection();
        let row = |i: usize| DVec4::new(m.x_axis[i], m.y_axis[i], m.z_axis[i], m.w_axis[i]);
        let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
        [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2].map(|p| {
            let n = p.truncate().length();
            [p.x / n, p.y / n, p.z / n, p.w / n]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera {
            position: DVec3::new(100.0, 200.0, 50.0),
            heading_deg: 30.0,
            pitch_deg: -10.0,
            incl_px: 540.0,
            fov_x_deg: 60.0,
            width: 1920,
            height: 1080,
            near_m: 1.0,
            far_m: 10_000.0,
        }
    }

    #[test]
    fn points_ahead_are_inside_and_behind_outside() {
        let c = camera();
        let planes = c.frustum_planes();
        let inside = |p: DVec3| {
            planes
                .iter()
                .all(|q| q[0] * p.x + q[1] * p.y + q[2] * p.z + q[3] >= 0.0)
        };
        assert!(inside(c.position + c.forward() * 100.0));
        assert!(!inside(c.position - c.forward() * 100.0));
        assert!(!inside(c.position + c.forward() * 20_000.0));
    }

    #[test]
    fn a_point_ahead_projects_to_the_centre_with_depth_in_range() {
        let c = camera();
        let clip = c.view_projection() * (c.position + c.forward() * 500.0).extend(1.0);
        let ndc = clip.truncate() / clip.w;
        assert!(ndc.x.abs() < 1e-9 && ndc.y.abs() < 1e-9);
        assert!(ndc.z > 0.0 && ndc.z < 1.0);
    }

    #[test]
    fn off_axis_projection_puts_the_horizon_on_row_incl() {
        let mut c = camera();
        c.pitch_deg = 0.0;
        c.incl_px = 200.0;
        // A far point at eye height projects onto screen row incl (from the bottom).
        let clip = c.view_projection() * (c.position + c.forward() * 5000.0).extend(1.0);
        let ndc_y = clip.y / clip.w;
        let row_from_bottom = (ndc_y + 1.0) / 2.0 * c.height as f64;
        assert!((row_from_bottom - 200.0).abs() < 1e-6, "{row_from_bottom}");
        // Depth agrees with eq. 5.11.
        let ndc_z = clip.z / clip.w;
        assert!((ndc_z - c.depth_at(5000.0)).abs() < 1e-12);
    }

    #[test]
    fn heading_is_clockwise_from_north() {
        let mut c = camera();
        c.pitch_deg = 0.0;
        c.heading_deg = 90.0;
        assert!((c.forward() - DVec3::X).length() < 1e-12);
    }
}
