//! The seed's blobs baseline (§4.2.4.2): objects grouped into squares of a
//! fixed side, each square drawn when in view.

use super::draw_list::{DrawList, Drawn};
use super::options::CutOptions;
use super::selection::{Selection, View};
use crate::camera::Camera;
use crate::cluster::Clusters;

/// The seed's blobs (§4.2.4.2): greedy squares of side K metres. A blob
/// touching the frustum draws all its members; a blob beyond the last band
/// draws none.
pub struct Blobs<'a> {
    clusters: &'a Clusters,
    blobs: std::borrow::Cow<'a, [Blob]>,
}

/// Members (tree-order object indices) and the box they fill.
#[derive(Debug, Clone, PartialEq)]
pub struct Blob {
    pub members: Vec<u32>,
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl<'a> Blobs<'a> {
    /// Group the objects: take the first object left (database order), put
    /// every object left inside the K×K square centred on it in its blob,
    /// repeat until none is left.
    pub fn new(clusters: &'a Clusters, side_m: f32) -> Blobs<'a> {
        Blobs {
            clusters,
            blobs: group_blobs(clusters, side_m).into(),
        }
    }

    /// Blobs already grouped by [`group_blobs`] (a viewer keeps them for
    /// its session).
    pub fn from_groups(clusters: &'a Clusters, blobs: &'a [Blob]) -> Blobs<'a> {
        Blobs {
            clusters,
            blobs: blobs.into(),
        }
    }

    pub fn blobs(&self) -> &[Blob] {
        &self.blobs
    }
}

/// The seed's greedy grouping into blobs of side `side_m` (see [`Blobs`]).
pub fn group_blobs(clusters: &Clusters, side_m: f32) -> Vec<Blob> {
    let objects = &clusters.tree.objects;
    let mut order: Vec<u32> = (0..objects.len() as u32).collect();
    order.sort_by_key(|&i| objects[i as usize].row);
    // Spatial hash of cell K: the square around an object touches at
    // most the 3×3 cells around its own.
    let cell = |v: f32| (v / side_m).floor() as i64;
    let mut grid: std::collections::HashMap<(i64, i64), Vec<u32>> = Default::default();
    for &i in &order {
        let f = objects[i as usize].foot;
        grid.entry((cell(f[0]), cell(f[1]))).or_default().push(i);
    }
    let mut taken = vec![false; objects.len()];
    let mut blobs = Vec::new();
    let half = side_m / 2.0;
    for &seed in &order {
        if taken[seed as usize] {
            continue;
        }
        let centre = objects[seed as usize].foot;
        let mut members = Vec::new();
        let (cx, cy) = (cell(centre[0]), cell(centre[1]));
        for gy in cy - 1..=cy + 1 {
            for gx in cx - 1..=cx + 1 {
                for &i in grid.get(&(gx, gy)).map_or(&[][..], |v| v.as_slice()) {
                    let f = objects[i as usize].foot;
                    if !taken[i as usize]
                        && (f[0] - centre[0]).abs() <= half
                        && (f[1] - centre[1]).abs() <= half
                    {
                        taken[i as usize] = true;
                        members.push(i);
                    }
                }
            }
        }
        members.sort_unstable_by_key(|&i| objects[i as usize].row);
        let (mut min, mut max) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for &i in &members {
            let [lo, hi] = objects[i as usize].bounds();
            for k in 0..3 {
                min[k] = min[k].min(lo[k]);
                max[k] = max[k].max(hi[k]);
            }
        }
        blobs.push(Blob { members, min, max });
    }
    blobs
}

impl Selection for Blobs<'_> {
    fn name(&self) -> &'static str {
        "blobs"
    }

    fn select(&self, camera: &Camera, options: &CutOptions, out: &mut DrawList) {
        out.clear();
        let view = View::new(camera, options);
        for blob in self.blobs.iter() {
            if view.sees(blob.min, blob.max).is_some() {
                for &i in &blob.members {
                    out.first
                        .push(self.clusters.instance(Drawn::Object(i), &view));
                    let [min, max] = self.clusters.tree.objects[i as usize].bounds();
                    out.represented += usize::from(view.sees(min, max).is_some());
                }
            }
        }
    }
}
