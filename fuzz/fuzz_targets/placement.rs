//! The GeoJSON placement of objects (buildings, cables, OBJ models) on a
//! 257×257 terrain of 30 m cells around the sample region's objects;
//! models are looked up in a folder holding one small model, `tree.obj`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relevo_core::geo::{GeoTransform, TerrainFrame};
use relevo_core::objects::parse_placement;
use std::path::PathBuf;
use std::sync::OnceLock;

/// A folder with `tree.obj` (`fuzz/seeds/tree.obj`) for placements that
/// name it.
fn folder() -> &'static PathBuf {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let model = include_str!("../seeds/tree.obj");
        std::fs::write(dir.path().join("tree.obj"), model).expect("the model");
        let path = dir.path().to_path_buf();
        (dir, path)
    })
    .1
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let frame = TerrainFrame {
        side: 257,
        cell_size_m: 30.0,
        geotransform: GeoTransform::north_up(288_000.0, 9_116_000.0, 30.0, 30.0),
    };
    let extent = 256.0 * 30.0;
    let ground = |x: f64, y: f64| {
        ((0.0..=extent).contains(&x) && (0.0..=extent).contains(&y)).then_some(100.0 + 0.01 * x)
    };
    let _ = parse_placement(text, folder(), &frame, &ground);
});
