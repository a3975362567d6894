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

    /// Vertical field of view in radians, from the horizontal one and the aspect.
    pub fn fov_y(&self) -> f64 {
        let aspect = self.height as f64 / self.width as f64;
        2.0 * ((self.fov_x_deg.to_radians() / 2.0).tan() * aspect).atan()
    }

    /// Eye → clip transform with depth in [0, 1], as wgpu expects.
    pub fn projection(&self) -> DMat4 {
        DMat4::perspective_rh(
            self.fov_y(),
            self.width as f64 / self.height as f64,
            self.near_m,
            self.far_m,
        )
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
    fn heading_is_clockwise_from_north() {
        let mut c = camera();
        c.pitch_deg = 0.0;
        c.heading_deg = 90.0;
        assert!((c.forward() - DVec3::X).length() < 1e-12);
    }
}
