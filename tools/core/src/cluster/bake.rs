//! Baking: the class impostors rendered from their models, the quadtree's
//! cluster views composed from them, everything packed into atlas pages
//! under a memory budget (vegetation thesis, §4.2.4.3 and its future work:
//! cluster textures, billboards sized to their quad, n levels; the seed ran
//! out of texture memory and reused textures near the leaves — here the
//! budget is stated and the bake says what it dropped).
//!
//! A cluster's view is composed, not re-rendered: each member's class view
//! (from the mip level nearest above the size it takes) is drawn with
//! tiny-skia at the member's true position and height, in painter's order —
//! farthest first for a side view, lowest top first for the top view. This
//! costs a few texture copies per member instead of re-rasterising every
//! member's triangles into every cluster above it; the difference to a true
//! render of the members' models is measured in the tests and documented
//! (docs/algorithms.md#clusters).

use super::cut::CutOptions;
use super::image::{ColourRange, PremulImage};
use super::model::{Model, ModelSource};
use super::quadtree::{ClusterObject, Node, Quadtree, NONE};
use super::views::{render_view, ImpostorView, Placed};
use super::{AtlasFrame, BakeReport, ClassImpostor, Clusters, LevelReport};
use crate::{Error, Result};
use rayon::prelude::*;

/// Frames start on multiples of this many texels, sizes are multiples of
/// it and frames lie at least this far apart: with [`MIP_LEVELS`] levels,
/// no texel of any level mixes two frames, and bilinear sampling at a
/// frame's edge reads transparent texels.
pub const ALIGN: usize = 8;
/// Mip levels kept per atlas page: 1, ½, ¼ and ⅛ (256 → 32 px frames).
pub const MIP_LEVELS: usize = 4;

/// Bytes of a page of `w`×`h` texels with its mip chain, RGBA8.
pub fn page_bytes(w: usize, h: usize) -> u64 {
    (0..MIP_LEVELS)
        .map(|m| (w.div_ceil(1 << m) * h.div_ceil(1 << m) * 4) as u64)
        .sum()
}

/// What a bake is asked to do (REGION.toml `[clusters.options]`; any
/// field left out takes its default).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BakeOptions {
    /// The cut the textures are sized for.
    pub cut: CutOptions,
    /// Most bytes of atlas texture (all pages with their mip levels).
    pub budget_bytes: u64,
    /// Screen the texel density is chosen for: width in pixels and
    /// horizontal field of view.
    pub reference_width_px: u32,
    pub reference_fov_deg: f64,
    /// Longer side of a class view, texels.
    pub class_frame_px: u32,
    /// Longer side of a cluster view at most, texels.
    pub max_frame_px: u32,
    /// Side of an atlas page, texels.
    pub page_px: u32,
    /// Deepest quadtree level.
    pub max_depth: u32,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            cut: CutOptions::default(),
            budget_bytes: 256 << 20,
            reference_width_px: 1920,
            reference_fov_deg: 60.0,
            class_frame_px: 256,
            max_frame_px: 256,
            page_px: 2048,
            max_depth: 16,
        }
    }
}

/// A vegetation class to bake: its name, model and where the model came
/// from.
#[derive(Debug, Clone)]
pub struct ClassSource {
    pub name: String,
    pub source: ModelSource,
    pub model: Model,
}

/// The five views' sizes in texels, each a multiple of [`ALIGN`], for a
/// box of `size` metres at `texels_per_m`, the longer side at most `max_px`.
fn frame_sizes(size: [f32; 3], texels_per_m: f64, max_px: u32) -> [[usize; 2]; 5] {
    let longest = size.iter().fold(0f32, |m, &v| m.max(v)) as f64;
    let density = texels_per_m.min(max_px as f64 / longest.max(1e-6));
    ImpostorView::ALL.map(|v| {
        v.extent(size).map(|e| {
            ((e as f64 * density).ceil() as usize)
                .max(1)
                .next_multiple_of(ALIGN)
        })
    })
}

/// Texture bytes a frame of `w`×`h` takes in a page, with its gutter.
fn frame_bytes([w, h]: [usize; 2]) -> u64 {
    page_bytes(w + ALIGN, h + ALIGN)
}

/// Bake the class impostors and the quadtree over `objects` (terrain
/// frame, classes indexing `classes`) inside the square at `origin` with
/// side `side_m`. `progress(done, total)` is told of each cluster composed.
///
/// The steps: the class impostors rendered from their models; the texel
/// density each cluster needs; the atlas planned under the budget (the
/// density cap); the report per depth; the clusters' views composed from
/// the class impostors; everything pasted into the pages.
pub fn bake(
    classes: Vec<ClassSource>,
    objects: Vec<ClusterObject>,
    origin: [f32; 2],
    side_m: f32,
    options: &BakeOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<Clusters> {
    options.cut.check().map_err(Error::Input)?;
    if objects.is_empty() {
        return Err(Error::Input(
            "the vegetation database is empty: there is nothing to cluster".into(),
        ));
    }
    if let Some(o) = objects.iter().find(|o| o.class as usize >= classes.len()) {
        return Err(Error::Input(format!(
            "object row {} has no class model",
            o.row
        )));
    }
    let class_views = render_class_views(&classes, options);
    let class_sizes: Vec<[usize; 2]> = class_views
        .iter()
        .flatten()
        .map(|i| [i.width, i.height])
        .collect();
    let class_bytes: u64 = pack(&class_sizes, options.page_px as usize)?
        .1
        .iter()
        .map(|&[w, h]| page_bytes(w, h))
        .sum();
    if class_bytes > options.budget_bytes {
        return Err(Error::Input(format!(
            "an atlas budget of {} bytes is below the {class_bytes} bytes the {} class impostors need",
            options.budget_bytes,
            classes.len()
        )));
    }

    let object_count = objects.len();
    let mut tree = Quadtree::build(objects, origin, side_m, options.max_depth);
    let need = Densities::of(&tree, options);
    let atlas = AtlasPlan::under_budget(&tree, &need, &class_sizes, class_bytes, options)?;
    let baked_nodes: Vec<usize> = (0..tree.nodes.len())
        .filter(|&i| atlas.plans[i].is_some())
        .collect();
    let levels = level_reports(&tree, &need, &atlas);
    let cap = atlas.cap;
    let sharp_from_m = (cap.is_finite() && cap > 0.0)
        .then(|| need.pixels_per_m_at_1m / (cap * need.magnification));
    if let Some(d) = sharp_from_m {
        // The report says it too (`relevo info`, `bake`): not a warning.
        tracing::info!(
            budget = options.budget_bytes,
            "the atlas budget caps cluster textures at {cap:.3} texels/m: clusters are sharp from {d:.0} m; nearer, smaller clusters give way to objects one by one"
        );
    }

    let composed = compose_clusters(&tree, &baked_nodes, &atlas, &class_views, progress);
    // Paste everything into the pages.
    let mut pages: Vec<PremulImage> = atlas
        .pages_size
        .iter()
        .map(|&[w, h]| PremulImage::transparent(w, h))
        .collect();
    let images = class_views
        .iter()
        .flatten()
        .chain(composed.iter().flatten());
    for (image, frame) in images.zip(&atlas.layout) {
        pages[frame.page as usize].paste(image, frame.x as usize, frame.y as usize);
    }
    let mut class_frames = atlas.layout.chunks_exact(5);
    let classes = classes
        .iter()
        .zip(&mut class_frames)
        .map(|(c, frames)| ClassImpostor {
            name: c.name.clone(),
            model: c.source.clone(),
            aspect: c.model.aspect(),
            frames: [frames[0], frames[1], frames[2], frames[3], frames[4]],
        })
        .collect();
    let frames: Vec<AtlasFrame> = atlas.layout[5 * class_views.len()..].to_vec();
    for (k, &i) in baked_nodes.iter().enumerate() {
        tree.nodes[i].frames = (5 * k) as u32;
    }
    let atlas_bytes = atlas
        .pages_size
        .iter()
        .map(|&[w, h]| page_bytes(w, h))
        .sum();
    Ok(Clusters {
        classes,
        tree,
        frames,
        pages,
        report: BakeReport {
            objects: object_count,
            levels,
            class_bytes,
            atlas_bytes,
            budget_bytes: options.budget_bytes,
            density_cap: cap.is_finite().then_some(cap),
            sharp_from_m,
        },
    })
}

/// Class impostors: each model's five views over its own box, the longer
/// side at `class_frame_px`.
fn render_class_views(classes: &[ClassSource], options: &BakeOptions) -> Vec<[PremulImage; 5]> {
    classes
        .par_iter()
        .map(|c| {
            let (d, h) = c.model.size();
            let size = [d, d, h];
            let density = options.class_frame_px as f64 / d.max(h) as f64;
            let sizes = frame_sizes(size, density, options.class_frame_px);
            let scene = [Placed {
                model: &c.model,
                foot: [0.0; 3],
                diameter: d,
                height: h,
            }];
            let (min, max) = ([-d / 2.0, -d / 2.0, 0.0], [d / 2.0, d / 2.0, h]);
            ImpostorView::ALL.map(|v| {
                let [w, h] = sizes[v as usize];
                render_view(&scene, v, min, max, w, h)
            })
        })
        .collect()
}

/// The texel density each node needs as a cluster — the reference screen's
/// pixels per metre at the nearest distance its size is drawn at, over the
/// magnification the cut tolerates — `None` for nodes never drawn as
/// clusters; and each node's parent.
struct Densities {
    per_node: Vec<Option<f64>>,
    parent: Vec<u32>,
    /// Pixels per metre at 1 m on the reference screen.
    pixels_per_m_at_1m: f64,
    magnification: f64,
}

impl Densities {
    fn of(tree: &Quadtree, options: &BakeOptions) -> Densities {
        let pixels_per_m_at_1m = options.reference_width_px as f64
            / (2.0 * (options.reference_fov_deg.to_radians() / 2.0).tan());
        let magnification = options.cut.magnification.max(1.0);
        let largest = options.cut.largest_cluster();
        let per_node = tree
            .nodes
            .iter()
            .map(|n| {
                if n.count < 2 || n.count > largest {
                    return None;
                }
                let near = options.cut.nearest_distance_for(n.count)?;
                Some(pixels_per_m_at_1m / near.max(1e-9) / magnification)
            })
            .collect();
        let mut parent = vec![NONE; tree.nodes.len()];
        for (i, n) in tree.nodes.iter().enumerate() {
            for &c in n.children.iter().filter(|&&c| c != NONE) {
                parent[c as usize] = i as u32;
            }
        }
        Densities {
            per_node,
            parent,
            pixels_per_m_at_1m,
            magnification,
        }
    }

    /// The highest density any node needs.
    fn highest(&self) -> f64 {
        self.per_node.iter().flatten().fold(0f64, |m, &v| m.max(v))
    }
}

/// The atlas under the budget: per node the sizes of its five views when
/// baked, where every frame lies in the pages, the pages' sizes, and the
/// density cap that made it fit (infinite when none was needed, 0 when no
/// cluster fits).
struct AtlasPlan {
    plans: Vec<Option<[[usize; 2]; 5]>>,
    layout: Vec<AtlasFrame>,
    pages_size: Vec<[usize; 2]>,
    cap: f64,
}

impl AtlasPlan {
    /// The budget caps the density (texels per metre) of every cluster
    /// view. A capped cluster is only sharp from farther away, where its
    /// parent — if capped too — is drawn instead; so a node whose parent is
    /// capped is not baked at all. Bytes grow with the cap: bisect for the
    /// largest cap whose atlas fits, then pack (and tighten if shelf waste
    /// overflows). A cap of 0 bakes no cluster at all (the class impostors
    /// always fit, as checked before).
    fn under_budget(
        tree: &Quadtree,
        need: &Densities,
        class_sizes: &[[usize; 2]],
        class_bytes: u64,
        options: &BakeOptions,
    ) -> Result<AtlasPlan> {
        let plan = |cap: f64| -> Vec<Option<[[usize; 2]; 5]>> {
            tree.nodes
                .iter()
                .enumerate()
                .map(|(i, n)| {
                    let density = need.per_node[i].filter(|_| cap > 0.0)?;
                    let parent = need.parent[i];
                    let parent_capped =
                        parent != NONE && need.per_node[parent as usize].is_some_and(|p| p > cap);
                    (!parent_capped).then(|| {
                        frame_sizes(size_of_node(n), density.min(cap), options.max_frame_px)
                    })
                })
                .collect()
        };
        let estimate = |plans: &[Option<[[usize; 2]; 5]>]| -> u64 {
            class_bytes
                + plans
                    .iter()
                    .flatten()
                    .flat_map(|sizes| sizes.iter().map(|&s| frame_bytes(s)))
                    .sum::<u64>()
        };
        let mut cap = f64::INFINITY;
        if estimate(&plan(cap)) > options.budget_bytes {
            let (mut lo, mut hi) = (1e-6f64, need.highest().max(1e-6));
            for _ in 0..40 {
                let mid = (lo * hi).sqrt();
                if estimate(&plan(mid)) <= options.budget_bytes {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            cap = if estimate(&plan(lo)) <= options.budget_bytes {
                lo
            } else {
                0.0
            };
        }
        loop {
            let plans = plan(cap);
            let mut sizes = class_sizes.to_vec();
            sizes.extend(plans.iter().flatten().flatten());
            let (layout, pages_size) = pack(&sizes, options.page_px as usize)?;
            let bytes: u64 = pages_size.iter().map(|&[w, h]| page_bytes(w, h)).sum();
            if bytes <= options.budget_bytes {
                return Ok(AtlasPlan {
                    plans,
                    layout,
                    pages_size,
                    cap,
                });
            }
            if cap == 0.0 {
                return Err(Error::Input(format!(
                    "an atlas budget of {} bytes is below the {bytes} bytes of the class impostors' pages",
                    options.budget_bytes
                )));
            }
            cap = if cap < 1e-5 {
                // Not even the coarsest clusters at their smallest fit: none.
                0.0
            } else if cap.is_finite() {
                cap * 0.9
            } else {
                need.highest() * 0.9
            };
        }
    }
}

/// Per quadtree depth: nodes, clusters a cut may draw, clusters baked,
/// those reduced by the cap, and their atlas bytes.
fn level_reports(tree: &Quadtree, need: &Densities, atlas: &AtlasPlan) -> Vec<LevelReport> {
    let depths = tree.nodes_per_depth().len();
    let mut levels: Vec<LevelReport> = (0..depths)
        .map(|d| LevelReport {
            depth: d as u32,
            nodes: 0,
            clusters: 0,
            baked: 0,
            reduced: 0,
            atlas_bytes: 0,
        })
        .collect();
    for (i, node) in tree.nodes.iter().enumerate() {
        let level = &mut levels[node.depth as usize];
        level.nodes += 1;
        level.clusters += need.per_node[i].is_some() as usize;
        if let Some(sizes) = &atlas.plans[i] {
            level.baked += 1;
            level.reduced += need.per_node[i].is_some_and(|n| n > atlas.cap) as usize;
            level.atlas_bytes += sizes.iter().map(|&s| frame_bytes(s)).sum::<u64>();
        }
    }
    levels
}

/// Compose the baked clusters' views from the class impostors' mip chains
/// (in parallel; each depends only on its members, so the result does not
/// depend on the thread count).
fn compose_clusters(
    tree: &Quadtree,
    baked_nodes: &[usize],
    atlas: &AtlasPlan,
    class_views: &[[PremulImage; 5]],
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Vec<[PremulImage; 5]> {
    let range = ColourRange::of(class_views.as_flattened());
    let class_mips: Vec<[Vec<tiny_skia::Pixmap>; 5]> = class_views
        .iter()
        .map(|views| {
            let mut out: [Vec<tiny_skia::Pixmap>; 5] = Default::default();
            for (slot, image) in out.iter_mut().zip(views) {
                *slot = image
                    .mip_chain(MIP_LEVELS)
                    .iter()
                    .filter_map(to_pixmap)
                    .collect();
            }
            out
        })
        .collect();
    baked_nodes
        .par_iter()
        .map(|&i| {
            let node = &tree.nodes[i];
            let members = &tree.objects[node.members()];
            let sizes = atlas.plans[i].unwrap_or_default();
            let views = ImpostorView::ALL
                .map(|v| compose_view(node, members, v, sizes[v as usize], &class_mips, &range));
            progress(1, baked_nodes.len() as u64);
            views
        })
        .collect()
}

/// Extents (x, y, z) of the box a node's members fill, metres.
pub fn size_of_node(n: &Node) -> [f32; 3] {
    [0, 1, 2].map(|k| (n.max[k] - n.min[k]).max(1e-3))
}

/// A premultiplied image as a tiny-skia pixmap (same layout).
fn to_pixmap(image: &PremulImage) -> Option<tiny_skia::Pixmap> {
    let size = tiny_skia::IntSize::from_wh(image.width as u32, image.height as u32)?;
    tiny_skia::Pixmap::from_vec(image.bytes().to_vec(), size)
}

/// View `view` of `node`: each member's class view at its place, in
/// painter's order, into `w`×`h` texels over the node's box, held within
/// the class views' colour `range`.
fn compose_view(
    node: &Node,
    members: &[ClusterObject],
    view: ImpostorView,
    [w, h]: [usize; 2],
    class_mips: &[[Vec<tiny_skia::Pixmap>; 5]],
    range: &ColourRange,
) -> PremulImage {
    let Some(mut canvas) = tiny_skia::Pixmap::new(w as u32, h as u32) else {
        return PremulImage::transparent(w, h);
    };
    let size = size_of_node(node);
    let centre = [0, 1, 2].map(|k| (node.min[k] + node.max[k]) / 2.0);
    let [span_w, span_h] = view.extent(size);
    let (sx, sy) = (w as f32 / span_w, h as f32 / span_h);
    // (depth key, member): farthest (smallest depth) first; ties by row.
    let mut order: Vec<(f32, u32, &ClusterObject)> = members
        .iter()
        .map(|o| {
            let key = match view {
                ImpostorView::Top => o.foot[2] + o.height,
                _ => view.project([o.foot[0] - centre[0], o.foot[1] - centre[1], 0.0])[2],
            };
            (key, o.row, o)
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let paint = tiny_skia::PixmapPaint {
        quality: tiny_skia::FilterQuality::Bilinear,
        ..Default::default()
    };
    for (_, _, o) in order {
        let [r, u, _] = view.project([
            o.foot[0] - centre[0],
            o.foot[1] - centre[1],
            o.foot[2] - centre[2],
        ]);
        // The member's rectangle in the node's image (x right, y down).
        let (left, top, width, height) = match view {
            ImpostorView::Top => (
                r - o.diameter / 2.0,
                u + o.diameter / 2.0,
                o.diameter,
                o.diameter,
            ),
            _ => (r - o.diameter / 2.0, u + o.height, o.diameter, o.height),
        };
        let x0 = (left + span_w / 2.0) * sx;
        let y0 = (span_h / 2.0 - top) * sy;
        let (pw, ph) = (width * sx, height * sy);
        let mips = &class_mips[o.class as usize][view as usize];
        // The smallest level still at least as wide as the drawn size.
        let Some(source) = mips
            .iter()
            .rev()
            .find(|p| p.width() as f32 >= pw)
            .or_else(|| mips.first())
        else {
            continue;
        };
        let transform = tiny_skia::Transform::from_row(
            pw / source.width() as f32,
            0.0,
            0.0,
            ph / source.height() as f32,
            x0,
            y0,
        );
        canvas.draw_pixmap(0, 0, source.as_ref(), &paint, transform, None);
    }
    let texels = canvas
        .data()
        .chunks_exact(4)
        .map(|p| range.clamp([p[0], p[1], p[2], p[3]]))
        .collect();
    PremulImage {
        width: w,
        height: h,
        texels,
    }
}

/// Shelf packing of frames of `sizes` into pages of side `page_px`: frames
/// sorted by height (then width, then input order), placed left to right on
/// shelves; each frame starts [`ALIGN`] texels from the page's top-left
/// and from its neighbours. The last page is cut to the rows it uses.
/// Returns each frame's place (input order) and each page's size.
pub fn pack(sizes: &[[usize; 2]], page_px: usize) -> Result<(Vec<AtlasFrame>, Vec<[usize; 2]>)> {
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by(|&a, &b| {
        sizes[b][1]
            .cmp(&sizes[a][1])
            .then(sizes[b][0].cmp(&sizes[a][0]))
            .then(a.cmp(&b))
    });
    if page_px > u16::MAX as usize {
        return Err(Error::Input(format!(
            "atlas pages of {page_px} texels: at most {} per side",
            u16::MAX
        )));
    }
    let mut frames = vec![AtlasFrame::default(); sizes.len()];
    let mut pages: Vec<[usize; 2]> = Vec::new();
    let (mut x, mut y, mut shelf) = (ALIGN, ALIGN, 0usize);
    for i in order {
        let [w, h] = sizes[i];
        if w + 2 * ALIGN > page_px || h + 2 * ALIGN > page_px {
            return Err(Error::Input(format!(
                "a {w}×{h} frame does not fit an atlas page of {page_px} texels"
            )));
        }
        if pages.is_empty() {
            pages.push([page_px, 0]);
        }
        if x + w + ALIGN > page_px {
            // Next shelf.
            x = ALIGN;
            y += shelf + ALIGN;
            shelf = 0;
        }
        if y + h + ALIGN > page_px {
            pages.push([page_px, 0]);
            x = ALIGN;
            y = ALIGN;
            shelf = 0;
        }
        let page = pages.len() - 1;
        let too_many = || Error::Input(format!("more than {} atlas pages", u16::MAX));
        frames[i] = AtlasFrame {
            page: u16::try_from(page).map_err(|_| too_many())?,
            // All below `page_px`, which fits 16 bits (checked above).
            x: x as u16,
            y: y as u16,
            width: w as u16,
            height: h as u16,
        };
        pages[page][1] = pages[page][1].max(y + h + ALIGN);
        shelf = shelf.max(h);
        x += w + ALIGN;
    }
    Ok((frames, pages))
}

/// A node's view rendered from its members' models instead of composed:
/// the reference the composition is measured against.
pub fn render_node_view(
    node: &Node,
    members: &[ClusterObject],
    view: ImpostorView,
    [w, h]: [usize; 2],
    models: &[Model],
) -> PremulImage {
    let scene: Vec<Placed> = members
        .iter()
        .map(|o| Placed {
            model: &models[o.class as usize],
            foot: o.foot,
            diameter: o.diameter,
            height: o.height,
        })
        .collect();
    let size = size_of_node(node);
    let centre = [0, 1, 2].map(|k| (node.min[k] + node.max[k]) / 2.0);
    let min = [0, 1, 2].map(|k| centre[k] - size[k] / 2.0);
    let max = [0, 1, 2].map(|k| centre[k] + size[k] / 2.0);
    render_view(&scene, view, min, max, w, h)
}

/// Nodes whose frames were baked.
pub fn baked(tree: &Quadtree) -> impl Iterator<Item = &Node> {
    tree.nodes.iter().filter(|n| n.frames != NONE)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::cluster::checks;
    use crate::cluster::model::TreeKind;

    /// Objects scattered over a 2 km square in clumps, on a gentle slope,
    /// of two classes.
    pub(crate) fn scattered(count: usize) -> Vec<ClusterObject> {
        let mut random = checks::uniform(0x2545_F491_4F6C_DD1D);
        let mut next = move || random() as f32;
        (0..count)
            .map(|i| {
                let (cx, cy) = (
                    ((i / 40) % 7) as f32 * 280.0 + 60.0,
                    ((i / 280) % 7) as f32 * 280.0 + 60.0,
                );
                let (x, y) = (cx + next() * 160.0, cy + next() * 160.0);
                let diameter = 6.0 + next() * 8.0;
                let class = (i % 3 == 0) as u32;
                ClusterObject {
                    foot: [x, y, 100.0 + 0.05 * x],
                    diameter,
                    height: diameter * if class == 0 { 1.3 } else { 2.4 },
                    class,
                    row: i as u32,
                }
            })
            .collect()
    }

    pub(crate) fn sources() -> Vec<ClassSource> {
        [TreeKind::Broadleaf, TreeKind::Conifer]
            .iter()
            .map(|k| ClassSource {
                name: k.name().into(),
                source: ModelSource::Procedural(*k),
                model: k.model(1),
            })
            .collect()
    }

    pub(crate) fn small_options() -> BakeOptions {
        BakeOptions {
            class_frame_px: 64,
            max_frame_px: 64,
            page_px: 1024,
            ..BakeOptions::default()
        }
    }

    pub(crate) fn baked_clusters(count: usize) -> Clusters {
        bake(
            sources(),
            scattered(count),
            [0.0; 2],
            2048.0,
            &small_options(),
            &|_, _| {},
        )
        .unwrap()
    }

    #[test]
    fn bakes_are_identical_across_runs_and_thread_counts() {
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| baked_clusters(600))
        };
        let one = on(1);
        assert_eq!(one, on(4));
        assert_eq!(one, on(1));
        assert!(one.frames.len() > 100, "{} frames", one.frames.len());
        assert!(one.report.atlas_bytes <= one.report.budget_bytes);
        assert_eq!(one.report.left_out(), 0);
    }

    #[test]
    fn atlas_texels_have_no_fringe_at_any_level() {
        let clusters = baked_clusters(600);
        let range = checks::source_colour_range(&clusters);
        assert!(range.hi[1] > range.lo[1], "{range:?}");
        let (partial, problems) = checks::fringe_problems(&clusters);
        assert_eq!(problems, Vec::<String>::new());
        assert!(partial > 1000, "{partial} partly covered texels");
        // The check sees a fringe: a white border blended into one cluster view.
        let mut fringed = clusters.clone();
        let f = fringed.frames[0];
        let page = &mut fringed.pages[f.page as usize];
        for y in f.y..f.y + f.height {
            for x in f.x..f.x + f.width {
                let t = &mut page.texels[y as usize * page.width + x as usize];
                if t[3] > 0 && t[3] < 200 {
                    *t = [t[3]; 4];
                }
            }
        }
        assert!(!checks::fringe_problems(&fringed).1.is_empty());
    }

    #[test]
    fn composed_cluster_views_are_close_to_rendering_the_members() {
        let clusters = baked_clusters(600);
        let models: Vec<Model> = sources().into_iter().map(|c| c.model).collect();
        let (mean, count) = checks::composition_difference(&clusters, &models, 12);
        // Coverage differs only where members overlap and at resampled edges.
        assert!(
            count > 10_000 && mean < 0.06,
            "mean |Δα| {mean} over {count} texels"
        );
    }

    #[test]
    fn a_budget_too_small_and_an_empty_database_are_refused() {
        let tiny = BakeOptions {
            budget_bytes: 10_000,
            ..small_options()
        };
        let e = bake(
            sources(),
            scattered(50),
            [0.0; 2],
            2048.0,
            &tiny,
            &|_, _| {},
        )
        .unwrap_err();
        assert!(e.to_string().contains("budget of 10000 bytes"), "{e}");
        let e = bake(
            sources(),
            Vec::new(),
            [0.0; 2],
            2048.0,
            &small_options(),
            &|_, _| {},
        )
        .unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
        // A budget between: cluster textures are capped, clusters whose
        // parent is capped too are left out, and the report says so.
        let full = baked_clusters(600);
        assert_eq!(full.report.density_cap, None);
        let half = BakeOptions {
            budget_bytes: full.report.atlas_bytes / 2,
            ..small_options()
        };
        let cut = bake(
            sources(),
            scattered(600),
            [0.0; 2],
            2048.0,
            &half,
            &|_, _| {},
        )
        .unwrap();
        let r = &cut.report;
        assert!(r.atlas_bytes <= half.budget_bytes);
        assert!(r.density_cap.is_some() && r.sharp_from_m.is_some());
        assert!(r.levels.iter().any(|l| l.reduced > 0));
        assert!(r.left_out() > 0, "{:?}", r.levels);
        assert!(baked(&cut.tree).count() < baked(&full.tree).count());

        // A budget that holds the class impostors and nothing more: no
        // cluster, said so, and every object is still drawn (one by one).
        let bare = BakeOptions {
            budget_bytes: full.report.class_bytes + 1_000,
            ..small_options()
        };
        let none = bake(
            sources(),
            scattered(600),
            [0.0; 2],
            2048.0,
            &bare,
            &|_, _| {},
        )
        .unwrap();
        assert_eq!(none.report.density_cap, Some(0.0));
        assert_eq!(none.report.sharp_from_m, None);
        assert_eq!(baked(&none.tree).count(), 0);
        assert!(none.frames.is_empty());
    }
}
