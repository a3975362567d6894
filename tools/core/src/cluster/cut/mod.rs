//! What to draw from a camera: a cut through the quadtree, or one of the
//! baselines — the plain list and the seed's blobs — behind the same
//! [`Selection`] interface (vegetation thesis, §4.2.4: blobs, quadtree with
//! clusters, the distance bands of fig. 4.13 and 4.15, the view switch of
//! §4.1.3 and fig. 4.4).
//!
//! Distance bands generalise the seed's three regions to n: band i reaches
//! `until_m` and draws clusters of at most `max_cluster` objects; nothing
//! beyond the last band is drawn. A cluster is further refused where the
//! screen would magnify its texture by more than `magnification` (texels
//! per metre against pixels per metre at its nearest point); the cut then
//! descends to its children.

use super::views::ImpostorView;
use super::{AtlasFrame, Clusters};
use glam::DVec3;

mod blobs;
mod draw_list;
mod geometry;
mod list;
mod options;
mod quadtree_cut;
mod selection;
mod view_choice;

pub use blobs::{group_blobs, Blob, Blobs};
pub use draw_list::{DrawList, Drawn, Instance, ViewDraw};
pub use geometry::{box_distance, box_distance_squared, box_in_frustum, frustum_mask, ALL_PLANES};
pub use list::ObjectList;
pub use options::{CutBand, CutOptions};
pub use quadtree_cut::QuadtreeCut;
pub use selection::Selection;
use selection::View;
pub use view_choice::{choose_views, ViewChoice};

/// Builds instances with their view choice.
impl Clusters {
    /// View `view` of what `drawn` stands for, with weight 1: its atlas
    /// frame and size (metres). A viewer drawing sprites asks for views the
    /// cut did not choose.
    #[inline]
    pub fn view_of(&self, drawn: Drawn, view: ImpostorView) -> ViewDraw {
        let (frame, size) = match drawn {
            Drawn::Object(i) => {
                let o = &self.tree.objects[i as usize];
                let frame = self.classes[o.class as usize].frames[view as usize];
                let size = match view {
                    ImpostorView::Top => [o.diameter, o.diameter],
                    _ => [o.diameter, o.height],
                };
                (frame, size)
            }
            Drawn::Node(n) => {
                let node = &self.tree.nodes[n as usize];
                let frame = self.frames[node.frames as usize + view as usize];
                (
                    frame,
                    view.extent([0, 1, 2].map(|k| node.max[k] - node.min[k])),
                )
            }
        };
        ViewDraw {
            view,
            weight: 1.0,
            frame,
            size,
        }
    }

    /// Foot (centre of the footprint at the lowest ground) and height of
    /// what `drawn` stands for, metres.
    #[inline]
    fn foot_and_height(&self, drawn: Drawn) -> ([f32; 3], f32) {
        match drawn {
            Drawn::Object(i) => {
                let o = &self.tree.objects[i as usize];
                (o.foot, o.height)
            }
            Drawn::Node(n) => {
                let node = &self.tree.nodes[n as usize];
                let foot = [
                    (node.min[0] + node.max[0]) / 2.0,
                    (node.min[1] + node.max[1]) / 2.0,
                    node.min[2],
                ];
                (foot, node.max[2] - node.min[2])
            }
        }
    }

    /// The instance of `drawn` seen from the view's eye.
    #[inline]
    fn instance(&self, drawn: Drawn, view: &View) -> Instance {
        let (foot, height) = self.foot_and_height(drawn);
        let eye = view.camera.position;
        let to_eye = DVec3::new(
            eye.x - foot[0] as f64,
            eye.y - foot[1] as f64,
            eye.z - (foot[2] as f64 + height as f64 / 2.0),
        );
        let (chosen, n) = if view.automatic {
            let width = match drawn {
                Drawn::Object(i) => self.tree.objects[i as usize].diameter,
                Drawn::Node(n) => {
                    let node = &self.tree.nodes[n as usize];
                    (node.max[0] - node.min[0]).max(node.max[1] - node.min[1])
                }
            };
            let theta = (height as f64).atan2(width.max(1e-3) as f64).to_degrees();
            ViewChoice::with_angle(theta, view.crossfade_deg).choose(to_eye)
        } else {
            view.choice.choose(to_eye)
        };
        let across = (to_eye.x * to_eye.x + to_eye.y * to_eye.y).sqrt();
        let facing = if across > 0.0 {
            [(to_eye.x / across) as f32, (to_eye.y / across) as f32]
        } else {
            [0.0, -1.0]
        };
        let mut views = [ViewDraw {
            view: ImpostorView::Top,
            weight: 0.0,
            frame: AtlasFrame::default(),
            size: [0.0; 2],
        }; 3];
        for (slot, &(v, weight)) in views.iter_mut().zip(&chosen[..n]) {
            *slot = ViewDraw {
                weight,
                ..self.view_of(drawn, v)
            };
        }
        Instance {
            drawn,
            foot,
            top_m: height,
            facing,
            views,
            view_count: n as u8,
            share: [0.0, 1.0],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(crossfade: f64) -> CutOptions {
        CutOptions {
            crossfade_deg: crossfade,
            ..CutOptions::default()
        }
    }

    fn weights(e: f64, a: f64, o: &CutOptions) -> Vec<(ImpostorView, f32)> {
        let (v, n) = choose_views(e, a, o);
        v[..n].to_vec()
    }

    #[test]
    fn views_flip_at_the_threshold_and_the_azimuth_boundaries() {
        let hard = options(0.0);
        assert_eq!(weights(44.9, 180.0, &hard), [(ImpostorView::Front, 1.0)]);
        assert_eq!(weights(45.0, 180.0, &hard), [(ImpostorView::Top, 1.0)]);
        assert_eq!(weights(10.0, 44.9, &hard), [(ImpostorView::Back, 1.0)]);
        assert_eq!(weights(10.0, 45.1, &hard), [(ImpostorView::Right, 1.0)]);
        assert_eq!(weights(10.0, 225.1, &hard), [(ImpostorView::Left, 1.0)]);
        assert_eq!(weights(10.0, 359.0, &hard), [(ImpostorView::Back, 1.0)]);

        let soft = options(10.0);
        // Outside the fades: one view.
        assert_eq!(weights(30.0, 100.0, &soft), [(ImpostorView::Right, 1.0)]);
        assert_eq!(weights(60.0, 100.0, &soft), [(ImpostorView::Top, 1.0)]);
        // At the threshold, half top; at a side boundary, half each.
        assert_eq!(
            weights(45.0, 90.0, &soft),
            [(ImpostorView::Top, 0.5), (ImpostorView::Right, 0.5)]
        );
        let mut boundary = weights(0.0, 135.0, &soft);
        boundary.sort_by_key(|v| v.0 as u8);
        assert_eq!(boundary.len(), 2);
        for (v, (view, w)) in boundary.iter().enumerate() {
            assert_eq!(*view, [ImpostorView::Front, ImpostorView::Right][v]);
            assert!((w - 0.5).abs() < 1e-6);
        }
        let three = weights(43.0, 137.0, &soft);
        assert_eq!(three.len(), 3);
        for e in (0..=90).map(|e| e as f64) {
            for a in (0..720).map(|a| a as f64 * 0.5) {
                let w = weights(e, a, &soft);
                let sum: f32 = w.iter().map(|v| v.1).sum();
                assert!((sum - 1.0).abs() < 1e-6, "{e} {a}: {w:?}");
                assert!(w.iter().all(|v| v.1 > 0.0));
            }
        }
        // Weights move continuously through a fade.
        let share = |a: f64| {
            weights(0.0, a, &soft)
                .iter()
                .find(|v| v.0 == ImpostorView::Right)
                .map_or(0.0, |v| v.1)
        };
        assert_eq!(share(39.0), 0.0);
        assert!((share(42.5) - 0.25).abs() < 1e-6);
        assert!((share(47.5) - 0.75).abs() < 1e-6);
        assert_eq!(share(51.0), 1.0);
    }

    #[test]
    fn the_automatic_threshold_is_where_the_top_shows_more_than_the_side() {
        // A box twice as wide as tall: tan θ = ½, θ = 26.6°.
        let choice = ViewChoice::with_angle(0.5f64.atan().to_degrees(), 0.0);
        let seen = |e: f64| {
            let e = e.to_radians();
            choice.choose(DVec3::new(0.0, -e.cos(), e.sin())).0[0].0
        };
        assert_eq!(seen(26.0), ImpostorView::Front);
        assert_eq!(seen(27.0), ImpostorView::Top);
    }

    #[test]
    fn bands_answer_sizes_and_distances() {
        let o = CutOptions::default();
        assert!(o.check().is_ok());
        assert_eq!(o.max_cluster_at(0.0), Some(1));
        assert_eq!(o.max_cluster_at(2_000.0), Some(16));
        assert_eq!(o.max_cluster_at(20_001.0), None);
        assert_eq!(o.nearest_distance_for(1), Some(0.0));
        assert_eq!(o.nearest_distance_for(5), Some(1_000.0));
        assert_eq!(o.nearest_distance_for(300), None);
        for n in 1..=3 {
            let c = CutOptions::seed_configuration(n, 10_000.0).unwrap();
            assert!(c.check().is_ok());
            // As a bundle's cluster index keeps them.
            let json = serde_json::to_string(&c).unwrap();
            assert_eq!(serde_json::from_str::<CutOptions>(&json).unwrap(), c);
            assert_eq!(c.last_distance(), 20_000.0);
        }
        assert_eq!(
            CutOptions::seed_configuration(2, 1.0).unwrap().bands[1].max_cluster,
            4
        );
        assert_eq!(CutOptions::parse_bands("300:1, 1000:4").unwrap().len(), 2);
        assert!(CutOptions::parse_bands("300:1,200:4")
            .unwrap_err()
            .contains("increase"));
        assert!(CutOptions::parse_bands("300")
            .unwrap_err()
            .contains("UNTIL_M"));
        let mut bad = CutOptions::default();
        bad.bands[2].until_m = 10.0;
        assert!(bad.check().unwrap_err().contains("band 3"));
    }
}

#[cfg(test)]
mod selection_tests {
    use super::*;
    use crate::camera::Camera;
    use crate::cluster::bake::tests::baked_clusters;
    use crate::cluster::checks;
    use std::collections::HashSet;

    /// Cameras over and around the 2 km test square.
    fn cameras(count: usize) -> Vec<Camera> {
        checks::random_cameras(count, 7, [-500.0, -500.0, 120.0], [2500.0, 2500.0, 720.0])
    }

    /// The default cut with its bands scaled to the 2 km test square, so
    /// that every band is used.
    fn square_options() -> CutOptions {
        let mut options = CutOptions::default();
        for (b, until) in options
            .bands
            .iter_mut()
            .zip([100.0, 300.0, 700.0, 1500.0, 2500.0])
        {
            b.until_m = until;
        }
        options
    }

    #[test]
    fn the_cut_represents_every_visible_object_exactly_once() {
        let clusters = baked_clusters(600);
        let options = square_options();
        let mut list = DrawList::default();
        let (mut clusters_drawn, mut objects_drawn, mut fading) = (0, 0, 0);
        for camera in cameras(300) {
            QuadtreeCut(&clusters).select(&camera, &options, &mut list);
            assert_eq!(
                checks::cut_problems(&clusters, &list, &camera, &options),
                Vec::<String>::new()
            );
            for instance in list.instances() {
                match instance.drawn {
                    Drawn::Node(_) => clusters_drawn += 1,
                    Drawn::Object(_) => objects_drawn += 1,
                }
                fading += usize::from(instance.share != [0.0, 1.0]);
            }
            // Without the level fade every instance draws all its pixels.
            let switching = CutOptions {
                level_fade: 0.0,
                ..options.clone()
            };
            QuadtreeCut(&clusters).select(&camera, &switching, &mut list);
            assert!(list.instances().all(|i| i.share == [0.0, 1.0]));
            assert_eq!(
                checks::cut_problems(&clusters, &list, &camera, &switching),
                Vec::<String>::new()
            );
        }
        assert!(
            clusters_drawn > 100 && objects_drawn > 100 && fading > 50,
            "{clusters_drawn} {objects_drawn} {fading}"
        );
    }

    /// Per object inside the view, the dither share drawn as the object
    /// itself (not by a cluster).
    fn own_shares(clusters: &Clusters, list: &DrawList, camera: &Camera) -> Vec<Option<f32>> {
        let planes = camera.frustum_planes();
        let mut own: Vec<Option<f32>> = clusters
            .tree
            .objects
            .iter()
            .map(|o| {
                let [min, max] = o.bounds();
                box_in_frustum(&planes, min, max).then_some(0.0)
            })
            .collect();
        for instance in list.instances() {
            if let Drawn::Object(o) = instance.drawn {
                own[o as usize] = Some(instance.share[1] - instance.share[0]);
            }
        }
        own
    }

    #[test]
    fn the_level_fade_changes_the_cut_without_popping() {
        let clusters = baked_clusters(600);
        let options = square_options();
        // Fly from 2.4 km south-west of the square's centre towards it, in
        // steps of 0.4 % of the distance left.
        let largest_jump = |options: &CutOptions| {
            let (mut list, mut previous) = (DrawList::default(), None::<Vec<Option<f32>>>);
            let mut largest = 0.0f32;
            let mut back = 1700.0;
            while back > 50.0 {
                let camera = Camera {
                    position: DVec3::new(1000.0 - back, 1000.0 - back, 300.0),
                    heading_deg: 45.0,
                    pitch_deg: -10.0,
                    incl_px: 240.0,
                    fov_x_deg: 60.0,
                    width: 640,
                    height: 480,
                    near_m: 1.0,
                    far_m: 10_000.0,
                };
                QuadtreeCut(&clusters).select(&camera, options, &mut list);
                let own = own_shares(&clusters, &list, &camera);
                if let Some(previous) = &previous {
                    for (a, b) in previous.iter().zip(&own) {
                        if let (Some(a), Some(b)) = (a, b) {
                            largest = largest.max((a - b).abs());
                        }
                    }
                }
                previous = Some(own);
                back *= 0.996;
            }
            largest
        };
        let switching = largest_jump(&CutOptions {
            level_fade: 0.0,
            ..options.clone()
        });
        let fading = largest_jump(&options);
        let wide = largest_jump(&CutOptions {
            level_fade: 0.25,
            ..options.clone()
        });
        assert_eq!(switching, 1.0, "without the fade objects pop in");
        // A step of 0.4 % of the distance moves an object's share by a few
        // tenths at most with the default fade (10 % of the distance), less
        // with a wider one.
        assert!(
            fading < 0.3 && wide < fading,
            "the largest step of an object's share: {fading} (fade {}), {wide} (fade 0.25)",
            options.level_fade
        );
    }

    #[test]
    fn without_culling_everything_within_the_last_band_is_drawn() {
        let clusters = baked_clusters(600);
        let options = CutOptions {
            cull: false,
            ..CutOptions::default()
        };
        let mut list = DrawList::default();
        for camera in cameras(20) {
            let within = clusters
                .tree
                .objects
                .iter()
                .filter(|o| {
                    let [min, max] = o.bounds();
                    box_distance(camera.position, min, max) <= options.last_distance()
                })
                .count();
            ObjectList(&clusters).select(&camera, &options, &mut list);
            assert_eq!(list.len(), within);
            QuadtreeCut(&clusters).select(&camera, &options, &mut list);
            let drawn: HashSet<u32> = checks::represented_objects(&clusters, &list)
                .into_iter()
                .map(|(o, _)| o)
                .collect();
            assert_eq!(drawn.len(), within);
        }
    }

    #[test]
    fn blobs_draw_whole_blobs_that_touch_the_view_and_nothing_far() {
        let clusters = baked_clusters(600);
        let blobs = Blobs::new(&clusters, 150.0);
        // Every object in one blob, no blob wider than K.
        let mut all: Vec<u32> = blobs
            .blobs()
            .iter()
            .flat_map(|b| b.members.clone())
            .collect();
        all.sort_unstable();
        assert_eq!(all, (0..600).collect::<Vec<u32>>());
        assert!(blobs.blobs().len() > 20 && blobs.blobs().len() < 600);
        let options = CutOptions {
            bands: vec![CutBand {
                until_m: 1200.0,
                max_cluster: 1,
            }],
            ..CutOptions::default()
        };
        let mut list = DrawList::default();
        let mut lists = DrawList::default();
        for camera in cameras(100) {
            blobs.select(&camera, &options, &mut list);
            let drawn: HashSet<u32> = checks::represented_objects(&clusters, &list)
                .into_iter()
                .map(|(o, _)| o)
                .collect();
            assert_eq!(drawn.len(), list.len());
            let planes = camera.frustum_planes();
            for blob in blobs.blobs() {
                let visible = box_in_frustum(&planes, blob.min, blob.max)
                    && box_distance(camera.position, blob.min, blob.max) <= 1200.0;
                for m in &blob.members {
                    assert_eq!(drawn.contains(m), visible, "blob rule broken");
                }
            }
            // The list draws exactly what it sees; blobs draw a superset.
            ObjectList(&clusters).select(&camera, &options, &mut lists);
            let seen: HashSet<u32> = checks::represented_objects(&clusters, &lists)
                .into_iter()
                .map(|(o, _)| o)
                .collect();
            assert!(seen.is_subset(&drawn));
        }
    }
}
