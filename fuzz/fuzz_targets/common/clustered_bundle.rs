//! A small bundle with vegetation clusters (made once per fuzzing process)
//! whose cluster files the cluster targets replace, and the walks a reader
//! makes over what it opens.

use relevo_core::bundle::{write_terrain_bundle, Bundle, BundleLock, Crs};
use relevo_core::camera::Camera;
use relevo_core::cluster::bake::BakeOptions;
use relevo_core::cluster::cut::{DrawList, ObjectList, QuadtreeCut, Selection};
use relevo_core::cluster::store::{self, NewVegetation};
use relevo_core::cluster::Clusters;
use relevo_core::geo::GeoTransform;
use relevo_core::grid::HeightGrid;
use relevo_core::veg::db::VegObject;
use std::path::PathBuf;
use std::sync::OnceLock;

/// The bundle, and the bytes of its `clusters/` files by name.
pub struct Clustered {
    _dir: tempfile::TempDir,
    pub path: PathBuf,
    pub original: Vec<(&'static str, Vec<u8>)>,
}

/// The cluster files a target may replace.
pub const FILES: [&str; 4] = [
    "clusters/index.json",
    "clusters/nodes.bin",
    "clusters/objects.bin",
    "clusters/frames.bin",
];

/// A 65×65 slope 1.28 km across with 60 trees of two classes, baked into
/// one small atlas page.
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
        let crs = Crs { wkt: String::new(), epsg: None };
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
        let new = NewVegetation { database: Some(&database), samples_csv: None };
        store::rewrite_bundle(lock, &bundle, &new, &Default::default(), &options, &|_, _| {})
            .expect("clusters");
        let original = FILES
            .iter()
            .map(|&f| (f, std::fs::read(path.join(f)).expect("a cluster file")))
            .collect();
        Clustered { _dir: dir, path, original }
    })
}

/// Put every cluster file back, then write `file` with `bytes`.
pub fn replace(bundle: &Clustered, file: &str, bytes: &[u8]) -> bool {
    for (name, original) in &bundle.original {
        let content = if *name == file { bytes } else { original };
        if std::fs::write(bundle.path.join(name), content).is_err() {
            return false;
        }
    }
    true
}

/// Read the clusters as every reader does, and walk what was accepted: the
/// cut and the object list from cameras near, far, above and inside, and
/// `validate`. None of it may panic, loop or abort.
pub fn read_and_walk(bundle: &Clustered) {
    let Ok(opened) = Bundle::open(&bundle.path) else {
        return;
    };
    let _ = store::validate(&opened);
    let Ok(Some((index, clusters))) = store::read(&opened) else {
        return;
    };
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
        let _ = relevo_core::cluster::checks::represented_objects(clusters, &cut);
    }
}
