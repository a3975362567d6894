//! The interface every way of choosing what to draw implements, and the
//! camera's frustum and distances each of them computes once per frame.

use super::draw_list::DrawList;
use super::geometry::{
    box_distance_squared, box_farthest_distance_squared, frustum_mask, ALL_PLANES,
};
use super::options::CutOptions;
use super::view_choice::ViewChoice;
use crate::camera::Camera;
use crate::cluster::quadtree::Node;
use crate::cluster::Clusters;

/// A way to choose what to draw.
pub trait Selection: Sync {
    fn name(&self) -> &'static str;
    /// Fill `out` (cleared first) for `camera`.
    fn select(&self, camera: &Camera, options: &CutOptions, out: &mut DrawList);
}

/// Frustum and distance of one camera, computed once per selection.
pub(super) struct View<'c> {
    pub(super) camera: &'c Camera,
    pub(super) planes: [[f64; 4]; 6],
    /// The planes a box is tested against: all of them, or none when
    /// culling is off ([`CutOptions::cull`]).
    pub(super) planes_tested: u8,
    pub(super) last_squared: f64,
    /// Screen pixels per metre at 1 m from the eye.
    pub(super) pixels_per_m_at_1m: f64,
    pub(super) choice: ViewChoice,
    /// Per-impostor thresholds ([`CutOptions::automatic_view_angle`]).
    pub(super) automatic: bool,
    pub(super) crossfade_deg: f64,
}

impl<'c> View<'c> {
    pub(super) fn new(camera: &'c Camera, options: &CutOptions) -> Self {
        View {
            camera,
            planes: camera.frustum_planes(),
            planes_tested: if options.cull { ALL_PLANES } else { 0 },
            last_squared: options.last_distance().powi(2),
            pixels_per_m_at_1m: camera.plane_distance_px(),
            choice: ViewChoice::new(options),
            automatic: options.automatic_view_angle,
            crossfade_deg: options.crossfade_deg,
        }
    }

    /// Inside the frustum and no further than the last band: the distance.
    pub(super) fn sees(&self, min: [f32; 3], max: [f32; 3]) -> Option<f64> {
        self.sees_within(self.planes_tested, min, max)
            .map(|(d, _)| d)
    }

    /// Members of `node` (its box straddling the planes in `mask`) inside
    /// the frustum and the last band: all of them when the box lies wholly
    /// inside both, else counted one by one.
    pub(super) fn members_in_view(&self, clusters: &Clusters, node: &Node, mask: u8) -> usize {
        let far = box_farthest_distance_squared(self.camera.position, node.min, node.max);
        if mask == 0 && far <= self.last_squared {
            return node.count as usize;
        }
        clusters.tree.objects[node.members()]
            .iter()
            .filter(|o| {
                let [min, max] = o.bounds();
                self.sees_within(mask, min, max).is_some()
            })
            .count()
    }

    /// [`View::sees`] testing only the planes in `mask`: the distance and
    /// the planes the box straddles.
    #[inline]
    pub(super) fn sees_within(&self, mask: u8, min: [f32; 3], max: [f32; 3]) -> Option<(f64, u8)> {
        let straddled = frustum_mask(&self.planes, mask, min, max)?;
        let d2 = box_distance_squared(self.camera.position, min, max);
        (d2 <= self.last_squared).then(|| (d2.sqrt(), straddled))
    }
}
