//! The `clusters/` folder of a bundle (see `docs/formats.md#clusters`):
//!
//! - `index.json`: options, classes with their frames, pages, the bake
//!   report;
//! - `nodes.bin`, `objects.bin`, `frames.bin`: little-endian records of
//!   [`Node`], [`ClusterObject`] and [`AtlasFrame`] (68, 28 and 10 bytes);
//! - `atlas_NNN.png`: the pages, level 0, RGBA8 **premultiplied**.
//!
//! Everything is deterministic, so the files enter the golden hashes.

use super::bake::{BakeOptions, ALIGN, MIP_LEVELS};
use super::image::PremulImage;
use super::model::ModelSource;
use super::quadtree::{ClusterObject, Node, Quadtree, NONE};
use super::{AtlasFrame, BakeReport};
use super::{ClassImpostor, Clusters};
use crate::bundle::names;
use crate::bundle::{Bundle, BundleFiles, BundleLock, BundleWriter, StagedFiles};
use crate::horizon::Terrain;
use crate::raster::png;
use crate::{files, memory};
use crate::{Error, Result};
use std::collections::BTreeMap;

/// Version of the `clusters/` layout.
pub const VERSION: u32 = 1;

/// `clusters/index.json`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClusterIndex {
    pub version: u32,
    pub options: BakeOptions,
    pub classes: Vec<ClassImpostor>,
    pub pages: Vec<Page>,
    pub nodes: usize,
    pub objects: usize,
    /// Database objects left out because they stand off the terrain.
    pub off_terrain: usize,
    pub frames: usize,
    /// Texels of alignment and gutter between frames, and the mip levels a
    /// reader should build from level 0.
    pub align: usize,
    pub mip_levels: usize,
    pub report: BakeReport,
}

/// One atlas page.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Page {
    pub file: String,
    pub width: usize,
    pub height: usize,
}

/// File and manifest key of atlas page `i`.
fn page_name(i: usize) -> (String, String) {
    (
        format!("{}{i:03}", names::CLUSTER_PAGE_PREFIX),
        format!("{}/atlas_{i:03}.png", names::CLUSTERS_DIR),
    )
}

/// Write `clusters` into the bundle being built, of either format (the
/// index, the quadtree's records and the atlas pages), each recorded in
/// its manifest.
pub fn write(
    writer: &mut StagedFiles,
    clusters: &Clusters,
    options: &BakeOptions,
    off_terrain: usize,
) -> Result<()> {
    let mut pages = Vec::new();
    for (i, page) in clusters.pages.iter().enumerate() {
        let (key, file) = page_name(i);
        let bytes = png::encode_rgba(page.bytes(), page.width, page.height)?;
        writer.put_keyed_file(&key, &file, &bytes)?;
        pages.push(Page {
            file,
            width: page.width,
            height: page.height,
        });
    }
    for (name, bytes) in [
        (
            names::CLUSTER_NODES,
            bytemuck::cast_slice::<Node, u8>(&clusters.tree.nodes),
        ),
        (
            names::CLUSTER_OBJECTS,
            bytemuck::cast_slice::<ClusterObject, u8>(&clusters.tree.objects),
        ),
        (
            names::CLUSTER_FRAMES,
            bytemuck::cast_slice::<AtlasFrame, u8>(&clusters.frames),
        ),
    ] {
        writer.put_file(name, bytes)?;
    }
    let index = ClusterIndex {
        version: VERSION,
        options: options.clone(),
        classes: clusters.classes.clone(),
        pages,
        nodes: clusters.tree.nodes.len(),
        objects: clusters.tree.objects.len(),
        off_terrain,
        frames: clusters.frames.len(),
        align: ALIGN,
        mip_levels: MIP_LEVELS,
        report: clusters.report.clone(),
    };
    let mut json = serde_json::to_string_pretty(&index)
        .map_err(|e| Error::Input(format!("cluster index: {e}")))?;
    json.push('\n');
    writer.put_file(names::CLUSTER_INDEX, json.as_bytes())
}

/// What [`rewrite_bundle`] replaces besides the clusters.
#[derive(Debug, Clone, Default)]
pub struct NewVegetation<'a> {
    /// A new vegetation database (its exports, made with GDAL, are dropped
    /// from the bundle as out of date).
    pub database: Option<&'a [crate::veg::db::VegObject]>,
    /// The samples it was detected from, as CSV rectangles on the drape.
    pub samples_csv: Option<&'a str>,
}

/// Re-bake `bundle`'s clusters — from `new.database` when given, else from
/// its own — with `models` and `options`, and replace them (and the
/// database and samples) in place, atomically: a failure leaves the bundle
/// as it was. `lock` is the bundle's, taken before it was opened.
/// `progress(done, total)` counts clusters composed. Returns the bundle's
/// path, the clusters and the objects left off the terrain.
pub fn rewrite_bundle(
    lock: BundleLock,
    bundle: &Bundle,
    new: &NewVegetation,
    models: &BTreeMap<String, ModelSource>,
    options: &BakeOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<(std::path::PathBuf, Clusters, usize)> {
    let stored;
    let database = match new.database {
        Some(d) => d,
        None => {
            stored = bundle.vegetation()?.ok_or_else(|| {
                Error::invalid(
                    &bundle.dir,
                    "the bundle has no vegetation database to cluster",
                )
            })?;
            &stored
        }
    };
    let (heights, mask) = (bundle.heights()?, bundle.mask()?);
    let frame = bundle.frame();
    let ground = Terrain::new(frame.side, frame.cell_size_m, &heights[..], &mask[..], None);
    let (clusters, off_terrain) =
        super::stage::bake_database(database, &frame, &ground, models, options, progress)?;
    let replaced = |key: &str| {
        is_cluster_artifact(key)
            || (new.database.is_some()
                && [
                    names::VEGETATION.key,
                    names::VEGETATION_GEOPACKAGE.key,
                    names::VEGETATION_LABELS.key,
                ]
                .contains(&key))
            || (new.samples_csv.is_some() && key == names::VEGETATION_SAMPLES.key)
    };
    let mut writer = BundleWriter::rewrite(lock, bundle, |key| !replaced(key))?;
    if let Some(database) = new.database {
        writer.staged().write_vegetation(database)?;
    }
    if let Some(samples) = new.samples_csv {
        writer.staged().write_vegetation_samples(samples)?;
    }
    write(writer.staged(), &clusters, options, off_terrain)?;
    drop(ground);
    drop((heights, mask));
    let path = writer.commit_checked(&|b: &Bundle| validate(b))?;
    Ok((path, clusters, off_terrain))
}

/// Is a manifest key one of the clusters' artifacts?
pub fn is_cluster_artifact(key: &str) -> bool {
    key.starts_with(names::CLUSTERS_PREFIX)
}

/// The bundle's cluster index, when it has clusters.
pub fn read_index(bundle: &dyn BundleFiles) -> Result<Option<ClusterIndex>> {
    let Some(artifact) = bundle.files().get(names::CLUSTER_INDEX.key) else {
        return Ok(None);
    };
    let path = bundle.dir().join(&artifact.file);
    let text = files::read_to_string(&path)?;
    parse_index(&text)
        .map(Some)
        .map_err(|e| Error::invalid(&path, e))
}

/// `clusters/index.json` from its text, of this build's layout version.
pub fn parse_index(text: &str) -> Result<ClusterIndex, String> {
    let index: ClusterIndex =
        serde_json::from_str(text).map_err(|e| format!("not a cluster index: {e}"))?;
    if index.version != VERSION {
        return Err(format!(
            "cluster layout version {}, this build reads {VERSION}",
            index.version
        ));
    }
    Ok(index)
}

/// Records of type `T` from a cluster artifact, `count` of them.
fn records<T: bytemuck::Pod>(bundle: &dyn BundleFiles, key: &str, count: usize) -> Result<Vec<T>> {
    let artifact = bundle.artifact(key)?;
    let path = bundle.dir().join(&artifact.file);
    parse_records(&files::read(&path)?, count).map_err(|e| Error::invalid(&path, e))
}

/// `count` little-endian records of type `T` from `bytes`, which must hold
/// exactly that many.
pub fn parse_records<T: bytemuck::Pod>(bytes: &[u8], count: usize) -> Result<Vec<T>, String> {
    if count.checked_mul(size_of::<T>()) != Some(bytes.len()) {
        return Err(format!(
            "{} bytes, expected {count} records of {} bytes",
            bytes.len(),
            size_of::<T>()
        ));
    }
    Ok(bytemuck::pod_collect_to_vec(bytes))
}

/// The bundle's cluster index, quadtree and frames, checked, without the
/// atlas pages, when it has them.
pub fn read_tree(
    bundle: &dyn BundleFiles,
) -> Result<Option<(ClusterIndex, Quadtree, Vec<AtlasFrame>)>> {
    let Some(index) = read_index(bundle)? else {
        return Ok(None);
    };
    let nodes = records::<Node>(bundle, names::CLUSTER_NODES.key, index.nodes)?;
    let objects = records::<ClusterObject>(bundle, names::CLUSTER_OBJECTS.key, index.objects)?;
    let frames = records::<AtlasFrame>(bundle, names::CLUSTER_FRAMES.key, index.frames)?;
    let tree = Quadtree { nodes, objects };
    if let Some(problem) = structure_problem(&index, &tree, &frames) {
        let path = bundle.dir().join(names::CLUSTERS_DIR);
        return Err(Error::invalid(
            &path,
            format!("{problem}; the clusters cannot be read"),
        ));
    }
    Ok(Some((index, tree, frames)))
}

/// The bundle's clusters with their pages decoded, when it has them.
pub fn read(bundle: &dyn BundleFiles) -> Result<Option<(ClusterIndex, Clusters)>> {
    let Some((index, tree, frames)) = read_tree(bundle)? else {
        return Ok(None);
    };
    let texels: u64 = index
        .pages
        .iter()
        .map(|p| (p.width * p.height) as u64)
        .sum();
    memory::check(
        "decoding the cluster atlas pages",
        texels,
        8,
        "bake the clusters again with a smaller --budget-mib",
    )?;
    let mut pages = Vec::with_capacity(index.pages.len());
    for (i, page) in index.pages.iter().enumerate() {
        let (key, _) = page_name(i);
        let artifact = bundle.artifact(&key)?;
        let path = bundle.dir().join(&artifact.file);
        let bytes = files::read(&path)?;
        let invalid = |e: Error| Error::invalid(&path, e.to_string());
        let (width, height) = png::size(&bytes).map_err(invalid)?;
        if (width, height) != (page.width, page.height) {
            return Err(Error::invalid(
                &path,
                format!(
                    "{width}×{height}, the index says {}×{}",
                    page.width, page.height
                ),
            ));
        }
        let (rgba, _, _) = png::decode_rgba(&bytes).map_err(invalid)?;
        pages.push(PremulImage {
            width,
            height,
            texels: rgba
                .chunks_exact(4)
                .map(|p| [p[0], p[1], p[2], p[3]])
                .collect(),
        });
    }
    let clusters = Clusters {
        classes: index.classes.clone(),
        tree,
        frames,
        pages,
        report: index.report.clone(),
    };
    Ok(Some((index, clusters)))
}

/// Largest atlas page side a reader accepts, texels (a GPU's usual 2D
/// texture limit).
const MAX_PAGE_PX: usize = 16384;

/// What makes the clusters unsafe to walk or draw, if anything: checked by
/// [`read`] before any reader (the cut, the viewer, `validate`, `bake`)
/// sees them. The tree must be a tree ([`Quadtree::structure_problem`]),
/// every node's five frames inside the frame table, every frame non-empty
/// and inside a page of a bounded size, and the cut's options sane.
pub fn structure_problem(
    index: &ClusterIndex,
    tree: &Quadtree,
    frames: &[AtlasFrame],
) -> Option<String> {
    if let Some(p) = tree.structure_problem(index.classes.len()) {
        return Some(p);
    }
    if let Err(p) = index.options.cut.check() {
        return Some(format!("cut options: {p}"));
    }
    if let Some((i, p)) = index.pages.iter().enumerate().find(|(_, p)| {
        !(1..=MAX_PAGE_PX).contains(&p.width) || !(1..=MAX_PAGE_PX).contains(&p.height)
    }) {
        return Some(format!(
            "page {i} is {}×{} (1–{MAX_PAGE_PX} texels a side)",
            p.width, p.height
        ));
    }
    if let Some(i) = tree
        .nodes
        .iter()
        .position(|n| n.frames != NONE && u64::from(n.frames) + 5 > frames.len() as u64)
    {
        return Some(format!("node {i}: frames beyond the frame table"));
    }
    let class_frames = index.classes.iter().flat_map(|c| c.frames.iter());
    frames.iter().chain(class_frames).find_map(|f| {
        let inside = index.pages.get(f.page as usize).is_some_and(|p| {
            f.width > 0
                && f.height > 0
                && f.x as usize + f.width as usize <= p.width
                && f.y as usize + f.height as usize <= p.height
        });
        (!inside).then(|| format!("frame {f:?} is empty or lies outside its page"))
    })
}

/// Check the clusters against the vegetation database and themselves:
/// every database object on the terrain appears once, at its place, with
/// its class and size; nodes nest and count their members; frames lie in
/// their pages. One line per problem (at most a few of each kind).
pub fn validate(bundle: &dyn BundleFiles) -> Vec<String> {
    let fail = |e: Error| vec![format!("clusters: {e}")];
    let (index, clusters) = match read(bundle) {
        Ok(Some(c)) => c,
        Ok(None) => return Vec::new(),
        Err(e) => return fail(e),
    };
    let database = match bundle.vegetation() {
        Ok(Some(d)) => d,
        Ok(None) => {
            return vec!["clusters: the bundle has clusters but no vegetation database".into()]
        }
        Err(e) => return fail(e),
    };
    let mut problems = Vec::new();
    let mut report = |p: String| {
        if problems.len() < 10 {
            problems.push(format!("clusters: {p}"));
        }
    };
    if index.objects + index.off_terrain != database.len() {
        report(format!(
            "{} objects and {} off the terrain, but the database has {}",
            index.objects,
            index.off_terrain,
            database.len()
        ));
    }
    let frame = bundle.terrain_frame();
    let mut seen = vec![false; database.len()];
    for (i, o) in clusters.tree.objects.iter().enumerate() {
        let Some(row) = database.get(o.row as usize) else {
            report(format!("object {i}: row {} is not in the database", o.row));
            continue;
        };
        if std::mem::replace(&mut seen[o.row as usize], true) {
            report(format!("object {i}: row {} appears twice", o.row));
        }
        let class = clusters
            .classes
            .get(o.class as usize)
            .map(|c| c.name.as_str());
        if class != Some(row.class.as_str()) {
            report(format!(
                "object {i}: class {class:?}, the database says {:?}",
                row.class
            ));
        }
        let at = frame.terrain_from_world(row.x, row.y);
        let moved = at.is_none_or(|(x, y)| {
            (x - o.foot[0] as f64).abs() > 0.05 || (y - o.foot[1] as f64).abs() > 0.05
        });
        if moved || (o.diameter as f64 - row.size).abs() > 1e-3 {
            report(format!(
                "object {i} (row {}): position or size differs from the database",
                o.row
            ));
        }
    }
    let nodes = &clusters.tree.nodes;
    if nodes.first().map(|n| n.count as usize) != Some(clusters.tree.objects.len()) {
        report("the root does not hold every object".into());
    }
    for (i, n) in nodes.iter().enumerate() {
        let children: Vec<&Node> = n
            .children
            .iter()
            .filter(|&&c| c != NONE)
            .filter_map(|&c| nodes.get(c as usize))
            .collect();
        if !n.is_leaf() && children.iter().map(|c| c.count).sum::<u32>() != n.count {
            report(format!(
                "node {i}: children do not add up to its {} members",
                n.count
            ));
        }
        for o in &clusters.tree.objects[n.members()] {
            let [lo, hi] = o.bounds();
            if (0..3).any(|k| lo[k] < n.min[k] || hi[k] > n.max[k]) {
                report(format!("node {i}: a member lies outside its box"));
                break;
            }
        }
    }
    for p in super::checks::fringe_problems(&clusters).1 {
        report(format!("atlas {p}"));
    }
    problems
}
