//! Flying: the camera's state in the terrain frame and how input moves it
//! (after SJD-Vis3D, LP seed §2.2.3: arrows move and turn, `a`/`b` — here
//! PgUp/PgDn — climb and sink along the terrain normal). The camera never
//! goes below the surface; terrain following keeps the height above ground.
//! Looking up and down tilts the camera for real (every mode draws the
//! pitch, the raycast within its range).

use crate::scene::Scene;
use glam::DVec3;
use relevo_core::camera::Camera;
use relevo_core::grid::vertex_normal;
use relevo_core::horizon::pitch_range;
use relevo_core::scene::{CameraPose, View};

/// Lowest height of the eye above the ground, metres.
pub const MIN_CLEARANCE_M: f64 = 2.0;

/// The camera being flown, in the terrain frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flight {
    /// Eye, terrain frame, metres.
    pub position: DVec3,
    /// Degrees clockwise from north.
    pub heading_deg: f64,
    /// Degrees above the horizon (negative looks down); kept within the
    /// raycaster's range when the camera is made.
    pub pitch_deg: f64,
    /// The view axis's screen row as a fraction of the height from the bottom
    /// (0.5 centred; larger looks further down): the seed's `incl`, kept
    /// relative so a resize keeps the view.
    pub horizon_frac: f64,
    /// Horizontal field of view, degrees.
    pub fov_x_deg: f64,
    /// Far plane, grid cells.
    pub far_cells: f64,
    /// Flying speed, metres per second.
    pub speed_mps: f64,
    /// Keep the height above ground while moving.
    pub follow_terrain: bool,
}

/// What the user is asking for this frame; each value in −1..1.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Controls {
    /// Forward (+) or back (−).
    pub forward: f64,
    /// Turn right (+) or left (−), as a fraction of a turn rate.
    pub turn: f64,
    /// Climb (+) or sink (−) along the terrain normal.
    pub climb: f64,
    /// Look down (+) or up (−): tilts the camera.
    pub look: f64,
}

/// Turn rate at full input, degrees per second.
const TURN_DEG_PER_S: f64 = 60.0;
/// Tilt rate at full input, degrees per second.
const LOOK_DEG_PER_S: f64 = 30.0;

/// A speed that crosses the scene in about a minute (10 m/s to 2 km/s).
fn cruising_speed(scene: &Scene) -> f64 {
    (scene.extent_m() / 60.0).clamp(10.0, 2000.0)
}

impl Flight {
    /// The home view of the scene (see [`View::home`]).
    pub fn home(scene: &Scene) -> Flight {
        let view = View::home(&scene.grid, [1280, 720]);
        Flight::from_pose(scene, &view.pose(), 720).unwrap_or(Flight {
            position: DVec3::new(scene.extent_m() / 2.0, 0.0, 1000.0),
            heading_deg: 0.0,
            pitch_deg: 0.0,
            horizon_frac: 0.75,
            fov_x_deg: 60.0,
            far_cells: 1024.0,
            speed_mps: cruising_speed(scene),
            follow_terrain: false,
        })
    }

    /// A flight at a camera string's pose for an image `height_px` tall.
    pub fn from_pose(scene: &Scene, pose: &CameraPose, height_px: u32) -> Option<Flight> {
        let (x, y) = scene.frame.terrain_from_world(pose.eye[0], pose.eye[1])?;
        Some(Flight {
            position: DVec3::new(x, y, pose.eye[2]),
            heading_deg: pose.heading_deg,
            pitch_deg: pose.pitch_deg,
            horizon_frac: pose.incl_px.map_or(0.5, |incl| incl / height_px as f64),
            fov_x_deg: 60.0,
            far_cells: 1024.0,
            speed_mps: cruising_speed(scene),
            follow_terrain: false,
        })
    }

    /// The camera string of this view for an image `height_px` tall: the
    /// syntax `relevo render` and `relevo-view render` read.
    pub fn pose(&self, scene: &Scene, height_px: u32) -> CameraPose {
        let (east, north) = scene
            .frame
            .world_from_terrain(self.position.x, self.position.y);
        CameraPose {
            eye: [east, north, self.position.z],
            heading_deg: self.heading_deg.rem_euclid(360.0),
            pitch_deg: self.pitch_deg,
            incl_px: Some(self.horizon_frac * height_px as f64),
        }
    }

    /// The core camera for a `size` viewport (near plane one cell ahead),
    /// its pitch within the raycaster's range for that viewport so that
    /// every mode draws the same view.
    pub fn camera(&self, scene: &Scene, size: [u32; 2]) -> Camera {
        let cell = scene.grid.cell_size_m;
        let mut camera = Camera {
            position: self.position,
            heading_deg: self.heading_deg,
            pitch_deg: 0.0,
            incl_px: self.horizon_frac * size[1] as f64,
            fov_x_deg: self.fov_x_deg,
            width: size[0],
            height: size[1],
            near_m: cell,
            far_m: self.far_cells * cell,
        };
        let [low, high] = pitch_range(&camera);
        camera.pitch_deg = self.pitch_deg.clamp(low, high);
        camera
    }

    /// Height of the eye above the ground under it, when there is ground.
    pub fn height_above_ground(&self, scene: &Scene) -> Option<f64> {
        scene
            .ground_height(self.position.x, self.position.y)
            .map(|g| self.position.z - g)
    }

    /// Move for `dt` seconds of `controls`.
    pub fn fly(&mut self, scene: &Scene, controls: &Controls, dt: f64) {
        let above = self.height_above_ground(scene);
        self.heading_deg =
            (self.heading_deg + controls.turn * TURN_DEG_PER_S * dt).rem_euclid(360.0);
        // Within the range of a 16:9 view, so that no input is lost beyond it.
        let [low, high] = pitch_range(&self.camera(scene, [1280, 720]));
        self.pitch_deg = (self.pitch_deg - controls.look * LOOK_DEG_PER_S * dt).clamp(low, high);
        let h = self.heading_deg.to_radians();
        let step = controls.forward * self.speed_mps * dt;
        self.position += DVec3::new(h.sin() * step, h.cos() * step, 0.0);
        if controls.climb != 0.0 {
            self.position += self.terrain_normal(scene) * controls.climb * self.speed_mps * dt;
        }
        if let (true, Some(above), 0.0) = (self.follow_terrain, above, controls.climb) {
            if let Some(g) = scene.ground_height(self.position.x, self.position.y) {
                self.position.z = g + above;
            }
        }
        self.keep_above_ground(scene);
    }

    /// Lift the eye to at least [`MIN_CLEARANCE_M`] above the ground.
    pub fn keep_above_ground(&mut self, scene: &Scene) {
        if let Some(g) = scene.ground_height(self.position.x, self.position.y) {
            self.position.z = self.position.z.max(g + MIN_CLEARANCE_M);
        }
    }

    /// The surface normal under the eye (straight up off the grid).
    fn terrain_normal(&self, scene: &Scene) -> DVec3 {
        let f = &scene.frame;
        let (c, r) = f.vertex_from_terrain(self.position.x, self.position.y);
        let last = (f.side - 1) as f64;
        if !(0.0..=last).contains(&c) || !(0.0..=last).contains(&r) {
            return DVec3::Z;
        }
        let n = vertex_normal(
            scene.terrain.heights(),
            f.side,
            f.cell_size_m,
            c.round() as usize,
            r.round() as usize,
        );
        DVec3::from_array(n)
    }
}
