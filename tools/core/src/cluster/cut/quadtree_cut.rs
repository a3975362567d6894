//! The cut through the quadtree (§4.2.4.3, with n bands): clusters far
//! away, their children nearer, objects one by one near the eye, each
//! cluster fading into its children near the distance it is refined at.

use super::draw_list::Branch;
use super::draw_list::{DrawList, Drawn};
use super::options::CutOptions;
use super::selection::{Selection, View};
use crate::camera::Camera;
use crate::cluster::quadtree::{Node, NONE};
use crate::cluster::views::ImpostorView;
use crate::cluster::Clusters;
use rayon::prelude::*;

/// The cut through the quadtree (§4.2.4.3, with n bands): from the root,
/// a node outside the frustum or beyond the last band is skipped with all
/// its members; a node whose size its band allows, whose views were baked
/// and whose texture the screen would not magnify too much is drawn as one
/// impostor; otherwise its children are visited, and a leaf's objects are
/// drawn one by one.
///
/// ```
/// use relevo_core::camera::Camera;
/// use relevo_core::cluster::bake::BakeOptions;
/// use relevo_core::cluster::stage::bake_database;
/// use relevo_core::cluster::cut::{DrawList, ObjectList, QuadtreeCut, Selection};
/// use relevo_core::geo::{GeoTransform, TerrainFrame};
/// use relevo_core::horizon::Terrain;
/// use relevo_core::veg::db::VegObject;
/// // 400 conifers 8 m across, 60 m apart, on a flat 1.28 km square.
/// let side = 65;
/// let frame = TerrainFrame {
///     side,
///     cell_size_m: 20.0,
///     geotransform: GeoTransform::north_up(0.0, 1280.0, 20.0, 20.0),
/// };
/// let database: Vec<VegObject> = (0..400)
///     .map(|k| VegObject {
///         id: k + 1,
///         x: 50.0 + (k % 20) as f64 * 60.0,
///         y: 50.0 + (k / 20) as f64 * 60.0,
///         class: "conifer".into(),
///         size: 8.0,
///         score: 0.9,
///     })
///     .collect();
/// let options = BakeOptions { budget_bytes: 16 << 20, ..BakeOptions::default() };
/// let ground = Terrain::new(side, 20.0, vec![0.0; side * side], vec![1; side * side], None);
/// let models = Default::default(); // each class's model from its name
/// let (clusters, off_terrain) =
///     bake_database(&database, &frame, &ground, &models, &options, &|_, _| {}).unwrap();
/// assert_eq!(off_terrain, 0);
/// // 3 km south of the square, 1 km up, looking north and down at it.
/// let camera = Camera {
///     position: glam::DVec3::new(640.0, -3000.0, 1000.0),
///     heading_deg: 0.0,
///     pitch_deg: -20.0,
///     incl_px: 540.0,
///     fov_x_deg: 60.0,
///     width: 1920,
///     height: 1080,
///     near_m: 1.0,
///     far_m: 50_000.0,
/// };
/// let (mut cut, mut list) = (DrawList::default(), DrawList::default());
/// QuadtreeCut(&clusters).select(&camera, &options.cut, &mut cut);
/// ObjectList(&clusters).select(&camera, &options.cut, &mut list);
/// // That far, clusters stand for many trees: fewer impostors, the same trees.
/// assert_eq!(cut.represented, list.represented);
/// assert!(cut.len() < list.len());
/// ```
pub struct QuadtreeCut<'a>(pub &'a Clusters);

/// Depth at which the walk splits into tasks run in parallel.
const SPLIT_DEPTH: u32 = 5;

impl Selection for QuadtreeCut<'_> {
    fn name(&self) -> &'static str {
        "quadtree"
    }

    /// The walk down to `SPLIT_DEPTH` runs here; the subtrees below it
    /// run in parallel, each into its own part of the list, and the parts
    /// are appended in tree order — the result does not depend on the
    /// thread count.
    fn select(&self, camera: &Camera, options: &CutOptions, out: &mut DrawList) {
        out.clear();
        if self.0.tree.nodes.is_empty() {
            return;
        }
        let view = View::new(camera, options);
        let mut frontier = std::mem::take(&mut out.frontier);
        frontier.clear();
        let root = Branch {
            mask: view.planes_tested,
            share: [0.0, 1.0],
            counted: true,
        };
        self.walk(0, root, &view, options, out, Some(&mut frontier));
        let mut parts = std::mem::take(&mut out.parts);
        if parts.len() < frontier.len() {
            parts.resize_with(frontier.len(), DrawList::default);
        }
        parts[..frontier.len()]
            .par_iter_mut()
            .zip(&frontier)
            .for_each(|(part, &(index, branch))| {
                part.clear();
                self.walk(index, branch, &view, options, part, None);
            });
        for part in &parts[..frontier.len()] {
            out.represented += part.represented;
            for (depth, &n) in part.clusters_per_depth.iter().enumerate() {
                out.count_clusters(depth, n);
            }
        }
        out.parts = parts;
        out.used = frontier.len();
        out.frontier = frontier;
    }
}

impl QuadtreeCut<'_> {
    /// Walk the subtree at `index` into `out`. With a `frontier`, nodes at
    /// [`SPLIT_DEPTH`] that need a walk of their own are left there instead.
    fn walk(
        &self,
        index: u32,
        branch: Branch,
        view: &View,
        options: &CutOptions,
        out: &mut DrawList,
        mut frontier: Option<&mut Vec<(u32, Branch)>>,
    ) {
        let clusters = self.0;
        let node = &clusters.tree.nodes[index as usize];
        let Some((distance, mask)) = view.sees_within(branch.mask, node.min, node.max) else {
            return;
        };
        let mut branch = Branch { mask, ..branch };
        let weight = if node.count > 1 {
            clusters.node_weight(node, distance, view, options)
        } else {
            0.0
        };
        if weight > 0.0 {
            let [from, to] = branch.share;
            let split = if weight >= 1.0 {
                to
            } else {
                from + (to - from) * weight as f32
            };
            let mut instance = clusters.instance(Drawn::Node(index), view);
            instance.share = [from, split];
            out.first.push(instance);
            if branch.counted {
                out.represented += view.members_in_view(clusters, node, mask);
                out.count_clusters(node.depth as usize, 1);
            }
            if split >= to {
                return;
            }
            // Fading: the children take the rest of the share.
            branch = Branch {
                share: [split, to],
                counted: false,
                ..branch
            };
        }
        if node.is_leaf() {
            for i in node.members() {
                let [min, max] = clusters.tree.objects[i].bounds();
                if node.count == 1 || view.sees_within(mask, min, max).is_some() {
                    let mut instance = clusters.instance(Drawn::Object(i as u32), view);
                    instance.share = branch.share;
                    out.first.push(instance);
                    out.represented += usize::from(branch.counted);
                }
            }
        } else if let Some(frontier) = frontier
            .as_deref_mut()
            .filter(|_| node.depth + 1 >= SPLIT_DEPTH)
        {
            frontier.extend(
                node.children
                    .iter()
                    .filter(|&&c| c != NONE)
                    .map(|&c| (c, branch)),
            );
        } else {
            for &child in node.children.iter().filter(|&&c| c != NONE) {
                self.walk(child, branch, view, options, out, frontier.as_deref_mut());
            }
        }
    }
}

impl Clusters {
    /// How much of its share `node`, `distance_m` from the eye at its
    /// nearest, takes as one impostor: 0 where it must be refined (not
    /// baked, too many objects for its band, or its texture magnified past
    /// [`CutOptions::magnification`]), 1 where it is clear of both limits
    /// by the [`CutOptions::level_fade`] margin, linear in between. The
    /// margins are relative: the distance past the band's inner edge over
    /// that edge, and the magnification left over the limit.
    fn node_weight(&self, node: &Node, distance_m: f64, view: &View, options: &CutOptions) -> f64 {
        if node.frames == NONE
            || options
                .max_cluster_at(distance_m)
                .is_none_or(|m| node.count > m)
        {
            return 0.0;
        }
        // Texels per metre of the front view against screen pixels per metre.
        let front = self.frames[node.frames as usize + ImpostorView::Front as usize];
        let width_m = (node.max[0] - node.min[0]).max(1e-3) as f64;
        let texels_per_m = front.width as f64 / width_m;
        let pixels_per_m = view.pixels_per_m_at_1m / distance_m.max(1e-9);
        let magnification_margin = texels_per_m * options.magnification / pixels_per_m - 1.0;
        if magnification_margin < 0.0 {
            return 0.0;
        }
        let band_margin = match options.nearest_distance_for(node.count) {
            Some(edge) if edge > 0.0 => distance_m / edge - 1.0,
            _ => f64::INFINITY,
        };
        let margin = magnification_margin.min(band_margin);
        if options.level_fade <= 0.0 {
            1.0
        } else {
            (margin / options.level_fade).min(1.0)
        }
    }
}
