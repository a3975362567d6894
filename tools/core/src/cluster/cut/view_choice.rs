//! Which views an impostor shows for a line of sight: the side view turned
//! to the eye, the top view from above a threshold angle, cross-faded
//! between them (vegetation thesis, §4.1.3 and fig. 4.4).

use super::options::CutOptions;
use crate::cluster::views::ImpostorView;
use glam::DVec3;

/// The views to draw and their weights for a line of sight `elevation_deg`
/// above the horizon and seen from compass direction `azimuth_deg` (from the
/// object towards the eye): [`ViewChoice::choose`] for that direction.
pub fn choose_views(
    elevation_deg: f64,
    azimuth_deg: f64,
    options: &CutOptions,
) -> ([(ImpostorView, f32); 3], usize) {
    let (e, a) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
    let to_eye = DVec3::new(a.sin() * e.cos(), a.cos() * e.cos(), e.sin());
    ViewChoice::new(options).choose(to_eye)
}

/// The view switch of one selection (§4.1.3, fig. 4.4): above the
/// threshold θ the top view; below, the side view nearest the azimuth.
/// Within ±crossfade/2 of θ the top view fades in linearly with the angle;
/// within ±crossfade/2 of a 45° boundary the two sides share linearly.
/// Weights sum to 1. Thresholds are kept as tangents, so only lines of
/// sight inside a fade cost an arctangent.
#[derive(Debug, Clone, Copy)]
pub struct ViewChoice {
    view_angle_deg: f64,
    half_deg: f64,
    /// tan(θ − half) and tan(θ + half): below the first no top view, above
    /// the second only the top view.
    tan_no_top: f64,
    tan_all_top: f64,
    /// tan(45° − half): below it (as min/max of |dx|, |dy|) one side only.
    tan_one_side: f64,
}

impl ViewChoice {
    pub fn new(options: &CutOptions) -> Self {
        Self::with_angle(options.view_angle_deg, options.crossfade_deg)
    }

    /// The view switch at threshold `theta` (degrees) with a cross-fade of
    /// `crossfade_deg`.
    pub fn with_angle(theta: f64, crossfade_deg: f64) -> Self {
        let half = crossfade_deg / 2.0;
        let tan = |deg: f64| {
            if deg >= 90.0 {
                f64::INFINITY
            } else if deg <= -90.0 {
                f64::NEG_INFINITY
            } else {
                deg.to_radians().tan()
            }
        };
        ViewChoice {
            view_angle_deg: theta,
            half_deg: half,
            tan_no_top: tan(theta - half),
            tan_all_top: tan(theta + half),
            tan_one_side: tan((45.0 - half).max(0.0)),
        }
    }

    /// Linear fade from 0 at −half to 1 at +half (a step when half is 0).
    fn ramp(&self, x: f64) -> f64 {
        if self.half_deg == 0.0 {
            (x >= 0.0) as u8 as f64
        } else {
            ((x + self.half_deg) / (2.0 * self.half_deg)).clamp(0.0, 1.0)
        }
    }

    /// Views and weights for `to_eye`, the vector from the impostor to the eye.
    #[inline]
    pub fn choose(&self, to_eye: DVec3) -> ([(ImpostorView, f32); 3], usize) {
        let (dx, dy, dz) = (to_eye.x, to_eye.y, to_eye.z);
        let across = (dx * dx + dy * dy).sqrt();
        let top = if dz < self.tan_no_top * across {
            0.0
        } else if dz >= self.tan_all_top * across && self.half_deg > 0.0 {
            1.0
        } else {
            self.ramp(dz.atan2(across).to_degrees() - self.view_angle_deg)
        };
        let mut out = [(ImpostorView::Top, 0.0f32); 3];
        if top >= 1.0 {
            out[0] = (ImpostorView::Top, 1.0);
            return (out, 1);
        }
        // Nearest side by the dominant axis; the neighbour is the other axis.
        let (ax, ay) = (dx.abs(), dy.abs());
        let along_y = ay >= ax;
        let y_side = if dy >= 0.0 {
            ImpostorView::Back
        } else {
            ImpostorView::Front
        };
        let x_side = if dx >= 0.0 {
            ImpostorView::Right
        } else {
            ImpostorView::Left
        };
        let (nearest, neighbour) = if along_y {
            (y_side, x_side)
        } else {
            (x_side, y_side)
        };
        let ratio = ax.min(ay) / ax.max(ay).max(f64::MIN_POSITIVE);
        // Share of the neighbour: 0 until the blend starts, ½ at the boundary.
        let shared = if ratio <= self.tan_one_side {
            0.0
        } else {
            1.0 - self.ramp(45.0 - ratio.atan().to_degrees())
        };
        let mut n = 0;
        for (view, weight) in [
            (ImpostorView::Top, top),
            (nearest, (1.0 - top) * (1.0 - shared)),
            (neighbour, (1.0 - top) * shared),
        ] {
            if weight > 0.0 {
                out[n] = (view, weight as f32);
                n += 1;
            }
        }
        (out, n)
    }
}
