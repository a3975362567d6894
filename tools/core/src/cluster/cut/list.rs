//! The plain list baseline: every object in view, one by one.

use super::draw_list::{DrawList, Drawn};
use super::options::CutOptions;
use super::selection::{Selection, View};
use crate::camera::Camera;
use crate::cluster::Clusters;

/// The plain list: every object inside the frustum and the last band, one
/// by one (the seed's starting point).
pub struct ObjectList<'a>(pub &'a Clusters);

impl Selection for ObjectList<'_> {
    fn name(&self) -> &'static str {
        "list"
    }

    fn select(&self, camera: &Camera, options: &CutOptions, out: &mut DrawList) {
        out.clear();
        let view = View::new(camera, options);
        for (i, o) in self.0.tree.objects.iter().enumerate() {
            let [min, max] = o.bounds();
            if view.sees(min, max).is_some() {
                out.first
                    .push(self.0.instance(Drawn::Object(i as u32), &view));
            }
        }
        out.represented = out.first.len();
    }
}
