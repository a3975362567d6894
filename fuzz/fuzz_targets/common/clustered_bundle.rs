//! The cluster files of a small bundle (made once per fuzzing process),
//! which the cluster targets replace, and the checks and walks a reader
//! makes over what it opens.

use relevo_core::bundle::{write_terrain_bundle, Bundle, BundleLock, Crs};
use relevo_core::camera::Camera;
use relevo_core::cluster::bake::BakeOptions;
use relevo_core::cluster::cut::{DrawList, ObjectList, QuadtreeCut, Selection};
use relevo_core::cluster::image::PremulImage;
use relevo_core::cluster::quadtree::{ClusterObject, Node, Quadtree};
use relevo_core::cluster::store::{self, NewVegetation};
use relevo_core::cluster::{checks, AtlasFrame, Clusters};
use relevo_core::geo::GeoTransform;
use relevo_core::grid::HeightGrid;
use relevo_core::veg::db::VegObject;
use std::sync::OnceLock;

/// The bundle's cluster files as read from disk, and its decoded pages.
pub struct Clustered {
    /// `clusters/index.json`, `nodes.bin`, `objects.bin`, `frames.bin`.
    pub files: [Vec<u8>; 4],
    pub pages: Vec<PremulImage>,
}

/// A 65×65 slope 1.28 km across with 60 trees of two classes, baked into
/// small atlas pages (made once per fuzzing process).
pub fn clustered_bundle() -> &'static Clustered {
    static BUNDLE: OnceLock<Clustered> = OnceLock::new();
    BUNDLE.get_or_init(|| {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let side = 65;
        let grid = HeightGrid {
            side,
            heights: (0..side * side).map(|i| (i / side) as f32 * 2.0).collect(),
            mask: vec![1; side * side],
            geotransform: GeoTransform::north_up(0.0, 1280.0, 20.0, 20.0),
        };
        let path = dir.path().join("fuzz.relevo");
        let crs = Crs {
            wkt: String::new(),
            epsg: None,
        };
        write_terrain_bundle(&path, "fuzz", &grid, 20.0, crs, false).expect("a bundle");
        let database: Vec<VegObject> = (0..60)
            .map(|k| VegObject {
                id: k + 1,
                x: 40.0 + (k % 10) as f64 * 120.0,
                y: 40.0 + (k / 10) as f64 * 200.0,
                class: if k % 3 == 0 { "conifer" } else { "broadleaf" }.into(),
                size: 6.0 + (k % 4) as f64,
                score: 0.9,
            })
            .collect();
        let options = BakeOptions {
            budget_bytes: 1 << 20,
            class_frame_px: 32,
            max_frame_px: 32,
            page_px: 256,
            ..BakeOptions::default()
        };
        let lock = BundleLock::acquire(&path).expect("the lock");
        let bundle = Bundle::open(&path).expect("the bundle");
        let new = NewVegetation {
            database: Some(&database),
            samples_csv: None,
        };
        let (_, clusters, _) = store::rewrite_bundle(
            lock,
            &bundle,
            &new,
            &Default::default(),
            &options,
            &|_, _| {},
        )
        .expect("clusters");
        let file = |name: &str| std::fs::read(path.join("clusters").join(name)).expect("a file");
        Clustered {
            files: [
                file("index.json"),
                file("nodes.bin"),
                file("objects.bin"),
                file("frames.bin"),
            ],
            pages: clusters.pages,
        }
    })
}

/// Open cluster files as `store::read` does — the index parsed, the
/// records counted, the structure checked, the pages' sizes compared — but
/// from memory, with the bundle's decoded pages; then walk what was
/// accepted. `counts_from_lengths` makes the index's counts match the
/// records given, so that every input reaches the structure checks.
pub fn open_and_walk(files: [&[u8]; 4], counts_from_lengths: bool) {
    let Ok(text) = std::str::from_utf8(files[0]) else {
        return;
    };
    let Ok(mut index) = store::parse_index(text) else {
        return;
    };
    if counts_from_lengths {
        index.nodes = files[1].len() / size_of::<Node>();
        index.objects = files[2].len() / size_of::<ClusterObject>();
    }
    let (Ok(nodes), Ok(objects), Ok(frames)) = (
        store::parse_records::<Node>(files[1], index.nodes),
        store::parse_records::<ClusterObject>(files[2], index.objects),
        store::parse_records::<AtlasFrame>(files[3], index.frames),
    ) else {
        return;
    };
    let tree = Quadtree { nodes, objects };
    if store::structure_problem(&index, &tree, &frames).is_some() {
        return;
    }
    let pages = &clustered_bundle().pages;
    let sizes_match = index.pages.len() == pages.len()
        && index
            .pages
            .iter()
            .zip(pages)
            .all(|(p, q)| (p.width, p.height) == (q.width, q.height));
    if !sizes_match {
        return;
    }
    let clusters = Clusters {
        classes: index.classes.clone(),
        tree,
        frames,
        pages: pages.clone(),
        report: index.report.clone(),
    };
    let _ = checks::fringe_problems(&clusters);
    walk(&clusters, &index.options.cut);
}

fn walk(clusters: &Clusters, options: &relevo_core::cluster::cut::CutOptions) {
    let cameras = [
        ([640.0, -3000.0, 1000.0], 0.0, -20.0),
        ([640.0, 640.0, 40.0], 90.0, -5.0),
        ([640.0, 640.0, 20_000.0], 0.0, -89.0),
        ([-50.0, 1500.0, 5.0], 135.0, 0.0),
    ];
    let (mut cut, mut list) = (DrawList::default(), DrawList::default());
    for (position, heading_deg, pitch_deg) in cameras {
        let camera = Camera {
            position: glam::DVec3::from_array(position),
            heading_deg,
            pitch_deg,
            incl_px: 120.0,
            fov_x_deg: 60.0,
            width: 320,
            height: 240,
            near_m: 1.0,
            far_m: 50_000.0,
        };
        QuadtreeCut(clusters).select(&camera, options, &mut cut);
        ObjectList(clusters).select(&camera, options, &mut list);
        let _ = checks::cut_problems(clusters, &cut, &camera, options);
    }
}
