//! Properties every bake and every cut must have, as functions: the unit
//! tests, the end-to-end tests on real regions and `relevo validate` call
//! the same code.

use super::bake::{render_node_view, MIP_LEVELS};
use super::cut::{box_distance, box_in_frustum, CutOptions, DrawList, Drawn};
use super::image::{ColourRange, PremulImage};
use super::model::Model;
use super::quadtree::NONE;
use super::views::ImpostorView;
use super::Clusters;
use crate::camera::Camera;

/// The texels of an atlas frame.
pub fn frame_image(clusters: &Clusters, f: &super::AtlasFrame) -> PremulImage {
    clusters.pages[f.page as usize].crop(
        f.x as usize,
        f.y as usize,
        f.width as usize,
        f.height as usize,
    )
}

/// The colour range of the class views: the sources every texel is made
/// from.
pub fn source_colour_range(clusters: &Clusters) -> ColourRange {
    let views: Vec<PremulImage> = clusters
        .classes
        .iter()
        .flat_map(|c| &c.frames)
        .map(|f| frame_image(clusters, f))
        .collect();
    ColourRange::of(&views)
}

/// No fringe at any mip level: an empty texel carries no colour, and a
/// partly covered one, un-premultiplied, lies within the sources' colour
/// range — checked as a·min − tol ≤ c ≤ a·max + tol. (A white fringe at
/// half coverage would be ~128 where the bound is ~64.) Returns the
/// number of partly covered texels checked and the problems (at most 5).
pub fn fringe_problems(clusters: &Clusters) -> (usize, Vec<String>) {
    let range = source_colour_range(clusters);
    let (mut partial, mut problems) = (0, Vec::new());
    for (p, page) in clusters.pages.iter().enumerate() {
        for (level, image) in page.mip_chain(MIP_LEVELS).iter().enumerate() {
            for (i, t) in image.texels.iter().enumerate() {
                let bad = match t[3] {
                    0 => t[..3] != [0; 3],
                    255 => false,
                    _ => {
                        partial += 1;
                        !range.holds(*t)
                    }
                };
                if bad && problems.len() < 5 {
                    problems.push(format!(
                        "page {p} level {level} texel {i}: {t:?} lies outside the sources' colours {:?}–{:?}",
                        range.lo, range.hi
                    ));
                }
            }
        }
    }
    (partial, problems)
}

/// The objects (tree order) each instance of `list` stands for, with the
/// instance's dither share; an object under a cluster fading into its
/// children appears once per instance.
pub fn represented_objects(clusters: &Clusters, list: &DrawList) -> Vec<(u32, [f32; 2])> {
    list.instances()
        .flat_map(|i| {
            let objects = match i.drawn {
                Drawn::Object(o) => o..o + 1,
                Drawn::Node(n) => {
                    let r = clusters.tree.nodes[n as usize].members();
                    r.start as u32..r.end as u32
                }
            };
            objects.map(move |o| (o, i.share))
        })
        .collect()
}

/// A quadtree cut from `camera`: every object inside the frustum and the
/// last band represented, its instances' dither shares tiling `[0, 1)`
/// (once, or split between a fading cluster and its children), the count
/// of objects represented equal to the objects in view, every drawn cluster allowed by its band,
/// baked, and its weights summing to 1. Returns the problems (at most 5).
pub fn cut_problems(
    clusters: &Clusters,
    list: &DrawList,
    camera: &Camera,
    options: &CutOptions,
) -> Vec<String> {
    let mut problems = Vec::new();
    let mut drawn = represented_objects(clusters, list);
    drawn.sort_by(|a, b| a.0.cmp(&b.0).then(a.1[0].total_cmp(&b.1[0])));
    let planes = camera.frustum_planes();
    let visible = |i: usize| {
        let [min, max] = clusters.tree.objects[i].bounds();
        box_in_frustum(&planes, min, max)
            && box_distance(camera.position, min, max) <= options.last_distance()
    };
    let mut seen = vec![false; clusters.tree.objects.len()];
    for same in drawn.chunk_by(|a, b| a.0 == b.0) {
        let o = same[0].0;
        seen[o as usize] = true;
        // Shares in order must not overlap; a visible object's must tile
        // [0, 1) (members of a fading cluster outside the view are drawn
        // by the cluster only).
        let tile = visible(o as usize);
        let mut reached = 0.0;
        for &(_, [from, to]) in same {
            if from < reached - 1e-6 || (tile && (from - reached).abs() > 1e-6) || to <= from {
                problems.push(format!(
                    "object {o}: dither shares {same:?} overlap or leave gaps"
                ));
                break;
            }
            reached = to;
        }
        if tile && (reached - 1.0).abs() > 1e-6 {
            problems.push(format!("object {o}: dither shares {same:?} do not reach 1"));
        }
    }
    let in_view = (0..seen.len()).filter(|&i| visible(i)).count();
    if in_view != list.represented {
        problems.push(format!(
            "{in_view} objects in view, the list says {} represented",
            list.represented
        ));
    }
    for (i, &seen) in seen.iter().enumerate() {
        if !seen && visible(i) {
            problems.push(format!("visible object {i} omitted"));
        }
    }
    for instance in list.instances() {
        let weights: f32 = instance.views().iter().map(|v| v.weight).sum();
        if (weights - 1.0).abs() > 1e-5 {
            problems.push(format!(
                "{:?}: view weights sum to {weights}",
                instance.drawn
            ));
        }
        if let Drawn::Node(n) = instance.drawn {
            let node = &clusters.tree.nodes[n as usize];
            let d = box_distance(camera.position, node.min, node.max);
            if node.frames == NONE || options.max_cluster_at(d).is_none_or(|m| node.count > m) {
                problems.push(format!(
                    "node {n} ({} objects at {d:.0} m) drawn against its band",
                    node.count
                ));
            }
        }
    }
    problems.truncate(5);
    problems
}

/// How far composed cluster views are from rendering their members'
/// models: mean |Δα| (coverage, 0–1) over the views of up to `nodes` baked
/// clusters of 4 to 16 members (where overlaps between members are
/// frequent and a render stays cheap), and the texels compared.
pub fn composition_difference(clusters: &Clusters, models: &[Model], nodes: usize) -> (f64, usize) {
    let (mut diff, mut count) = (0.0, 0usize);
    let baked = clusters
        .tree
        .nodes
        .iter()
        .filter(|n| n.frames != NONE && (4..=16).contains(&n.count));
    for node in baked.take(nodes) {
        for view in ImpostorView::ALL {
            let f = clusters.frames[node.frames as usize + view as usize];
            let composed = frame_image(clusters, &f);
            let members = &clusters.tree.objects[node.members()];
            let size = [f.width as usize, f.height as usize];
            let rendered = render_node_view(node, members, view, size, models);
            for (a, b) in composed.texels.iter().zip(&rendered.texels) {
                diff += (a[3] as f64 - b[3] as f64).abs() / 255.0;
                count += 1;
            }
        }
    }
    (diff / count.max(1) as f64, count)
}

/// A deterministic stream of uniform numbers in [0, 1) (xorshift64), for
/// test scenes and cameras that are the same on every run.
pub fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed.max(1);
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `count` cameras with eyes uniform in the box `[min, max]` (terrain
/// frame, metres), any heading, looking from level to 85° down, fields of
/// view of 30–100°, 1920×1080: what a cut must be right for.
pub fn random_cameras(count: usize, seed: u64, min: [f64; 3], max: [f64; 3]) -> Vec<Camera> {
    let mut next = uniform(seed);
    (0..count)
        .map(|_| {
            let mut at = |k: usize| min[k] + next() * (max[k] - min[k]);
            let position = glam::DVec3::new(at(0), at(1), at(2));
            Camera {
                position,
                heading_deg: next() * 360.0,
                pitch_deg: -next() * 85.0,
                incl_px: 540.0,
                fov_x_deg: 30.0 + next() * 70.0,
                width: 1920,
                height: 1080,
                near_m: 1.0,
                far_m: 60_000.0,
            }
        })
        .collect()
}
