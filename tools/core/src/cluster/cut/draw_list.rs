//! What a selection gives a renderer: what each instance stands for (an
//! object or a cluster), its views with their atlas frames and weights, and
//! the list of them with its counts.

use crate::cluster::views::ImpostorView;
use crate::cluster::AtlasFrame;
use rayon::prelude::*;

/// What one instance stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Drawn {
    /// One object, by its index in tree order (`Clusters::tree.objects`).
    Object(u32),
    /// A quadtree node drawn from its baked views: all its members.
    Node(u32),
}

/// One view of an instance: which, how much of it (cross-fade weight),
/// where in the atlas, and its size in metres (width, height).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewDraw {
    pub view: ImpostorView,
    pub weight: f32,
    pub frame: AtlasFrame,
    pub size: [f32; 2],
}

/// One impostor to draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instance {
    pub drawn: Drawn,
    /// Foot of the billboard: centre of the footprint at the lowest ground,
    /// terrain frame, metres. A top view lies at `foot.z + top_m`.
    pub foot: [f32; 3],
    /// Height of the top view above the foot, metres.
    pub top_m: f32,
    /// Unit horizontal vector (east, north) from the instance towards the
    /// eye: a side view is turned about the vertical to face along it.
    pub facing: [f32; 2],
    /// Views with non-zero weight, `views[..view_count]`; weights sum to 1.
    pub views: [ViewDraw; 3],
    pub view_count: u8,
    /// The share of the pixels this instance draws, as an interval of
    /// ordered-dither thresholds `[from, to)`: `[0, 1)` except while a
    /// cluster fades into its children ([`CutOptions::level_fade`](super::CutOptions::level_fade)), when
    /// the cluster and its children split the interval. The views split
    /// the instance's share by their weights.
    pub share: [f32; 2],
}

impl Instance {
    pub fn views(&self) -> &[ViewDraw] {
        &self.views[..self.view_count as usize]
    }
}

/// What a selection returns; cleared and refilled each frame so its
/// allocations are reused. The instances come in chunks (the parallel
/// quadtree walk leaves one per subtree; they are not copied together):
/// [`DrawList::chunks`] to upload them, [`DrawList::instances`] to visit.
#[derive(Debug, Clone, Default)]
pub struct DrawList {
    /// The first chunk (all of a plain list or blob selection).
    pub(super) first: Vec<Instance>,
    /// Objects inside the frustum and the last band that the instances
    /// stand for (a cluster partly in view counts only its members in
    /// view; what a viewer reports as objects represented).
    pub represented: usize,
    /// Clusters drawn per quadtree depth (objects drawn one by one are not
    /// counted here).
    pub clusters_per_depth: Vec<u32>,
    /// The parallel walk's scratch: subtrees left for tasks, each task's
    /// part (`parts[..used]` are in use).
    pub(super) frontier: Vec<(u32, Branch)>,
    pub(super) parts: Vec<DrawList>,
    pub(super) used: usize,
}

impl DrawList {
    pub fn clear(&mut self) {
        self.first.clear();
        self.represented = 0;
        self.clusters_per_depth.clear();
        self.used = 0;
    }

    /// Instances drawn.
    pub fn len(&self) -> usize {
        self.chunks().map(<[Instance]>::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The instances, chunk by chunk, in a fixed order.
    pub fn chunks(&self) -> impl Iterator<Item = &[Instance]> {
        std::iter::once(self.first.as_slice())
            .chain(self.parts[..self.used].iter().map(|p| p.first.as_slice()))
    }

    pub fn instances(&self) -> impl Iterator<Item = &Instance> {
        self.chunks().flatten()
    }

    /// Raise (or lower) every instance's foot by `lift(x, y)` metres, taken
    /// at the foot: the viewer's mesh mode moves impostors from the grid's
    /// surface, on which they were placed, onto the refined mesh it draws.
    /// Chunks in parallel.
    pub fn lift(&mut self, lift: &(dyn Fn(f64, f64) -> f64 + Sync)) {
        let used = self.used;
        std::iter::once(&mut self.first)
            .chain(self.parts[..used].iter_mut().map(|p| &mut p.first))
            .par_bridge()
            .for_each(|chunk| {
                for instance in chunk.iter_mut() {
                    let [x, y, z] = instance.foot;
                    instance.foot[2] = z + lift(x as f64, y as f64) as f32;
                }
            });
    }

    pub(super) fn count_clusters(&mut self, depth: usize, n: u32) {
        if self.clusters_per_depth.len() <= depth {
            self.clusters_per_depth.resize(depth + 1, 0);
        }
        self.clusters_per_depth[depth] += n;
    }
}

/// What the quadtree cut's walk carries down to a subtree (kept in the
/// draw list's frontier between its parallel tasks).
#[derive(Debug, Clone, Copy)]
pub(super) struct Branch {
    /// Frustum planes the subtree's parent straddles.
    pub(super) mask: u8,
    /// Dither share left to the subtree (less than `[0, 1)` below a cluster
    /// fading into its children).
    pub(super) share: [f32; 2],
    /// Are the subtree's objects counted as represented here? Not below a
    /// fading cluster, which counted them already.
    pub(super) counted: bool,
}
