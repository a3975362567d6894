//! A pyramid (a 65² grid of the real Copernicus Grenoble crop in 16-cell
//! tiles: three levels, 21 tiles) of which the fuzzer's input replaces the
//! manifest (first byte even) or a stretch of one tile file (first byte
//! odd: the file from the next byte, a 4-byte offset, then the bytes
//! written there): opening it, every tile, the tiles cameras meet, the
//! level-0 window and validation must end in a value or an error, never a
//! panic or an abort.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relevo_core::bundle::{Crs, GridInfo};
use relevo_core::camera::Camera;
use relevo_core::geo::GeoTransform;
use relevo_core::grid::HeightGrid;
use relevo_core::lp::window::Rect;
use relevo_core::lp::ErrorMetric;
use relevo_core::pyramid::{self, reader, BuildOptions, Pyramid, PyramidDescription, WriteOptions};
use std::path::PathBuf;
use std::sync::OnceLock;

const FILES: [&str; 4] = [
    "tiles/height.f32",
    "tiles/mask.u8",
    "tiles/lp.f32x2",
    "tiles/drape.rgba8",
];

/// The pyramid (once per process) and its files' original bytes
/// (manifest first).
fn pyramid_dir() -> &'static (tempfile::TempDir, PathBuf, Vec<Vec<u8>>) {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf, Vec<Vec<u8>>)> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let bytes = std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../data/crops/copernicus_grenoble_257.f32"
        ))
        .expect("the committed crop");
        let crop: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let side = 65;
        let heights: Vec<f32> = (0..side * side)
            .map(|i| crop[(i / side) * 257 + i % side])
            .collect();
        let grid = HeightGrid {
            side,
            heights,
            mask: vec![1; side * side],
            geotransform: GeoTransform::north_up(700000.0, 5000000.0, 30.0, 30.0),
        };
        let target = dir.path().join("fuzz.relevo");
        let description = PyramidDescription {
            region: "fuzz".into(),
            crs: Crs {
                wkt: String::new(),
                epsg: None,
            },
            grid: GridInfo::of(&grid, 30.0, 1.0).expect("data"),
            inputs: Vec::new(),
            parameters: Default::default(),
        };
        let options = WriteOptions {
            tile_cells: 16,
            build: BuildOptions {
                metric: ErrorMetric::Bound,
                cell_size_m: 30.0,
                drape: true,
            },
            force: true,
            resume: false,
        };
        pyramid::write_pyramid(&target, &grid, description, options, &|_| {}).expect("a pyramid");
        let mut originals = vec![std::fs::read(target.join("manifest.json")).expect("manifest")];
        originals.extend(
            FILES
                .iter()
                .map(|f| std::fs::read(target.join(f)).expect("tile file")),
        );
        (dir, target, originals)
    })
}

fn read_everything(dir: &std::path::Path) {
    let Ok(p) = Pyramid::open(dir) else {
        return;
    };
    let p = std::sync::Arc::new(p);
    for level in 0..p.layout.levels() {
        for key in p.layout.tiles(level) {
            let _ = p.tile(key);
        }
        for (position, heading_deg, pitch_deg) in [
            ([700960.0, 4999000.0, 1500.0], 0.0, -20.0),
            ([700960.0, 5000960.0, 30_000.0], 0.0, -89.0),
        ] {
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
            let _ = p.tiles_meeting(&camera, level);
        }
    }
    // A raycast from above the grid's centre, its bands on the levels.
    let g = &p.manifest.grid;
    let middle = (g.side - 1) as f64 / 2.0 * g.cell_size_m;
    let camera = Camera {
        position: glam::DVec3::new(middle, middle, g.height_range_m[1] as f64 + 300.0),
        heading_deg: 30.0,
        pitch_deg: -20.0,
        incl_px: 120.0,
        fov_x_deg: 60.0,
        width: 160,
        height: 120,
        near_m: 1.0,
        far_m: 50_000.0,
    };
    let levels = relevo_core::pyramid::render::LevelOptions {
        max_cell_px: 4.0,
        hillshade: Some([315.0, 35.0]),
    };
    let options = relevo_core::horizon::RenderOptions::default();
    let _ = relevo_core::pyramid::render::render(&p, &camera, &options, levels);
    let _ = p.level0_window(Rect::whole(p.layout.side));
    if let Ok(source) = relevo_core::pyramid::mesh::PyramidMesh::new(&p) {
        let window = Rect {
            c0: 3,
            r0: 5,
            width: 40,
            height: 21,
        };
        for (max_error, window) in [(0.5, None), (5.0, Some(window))] {
            let _ = relevo_core::lp::export::build(&source, max_error, false, window);
        }
    }
    let _ = reader::validate(&p, true);
    let _ = reader::validate(&p, false);
}

fuzz_target!(|data: &[u8]| {
    let (_, dir, originals) = pyramid_dir();
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    if which % 2 == 0 {
        if std::fs::write(dir.join("manifest.json"), rest).is_ok() {
            read_everything(dir);
        }
        let _ = std::fs::write(dir.join("manifest.json"), &originals[0]);
        return;
    }
    let Some((&file, rest)) = rest.split_first() else {
        return;
    };
    if rest.len() < 4 {
        return;
    }
    let (offset, bytes) = rest.split_at(4);
    let i = file as usize % FILES.len();
    let mut content = originals[i + 1].clone();
    let at =
        u32::from_le_bytes([offset[0], offset[1], offset[2], offset[3]]) as usize % content.len();
    let end = (at + bytes.len()).min(content.len());
    content[at..end].copy_from_slice(&bytes[..end - at]);
    if std::fs::write(dir.join(FILES[i]), &content).is_ok() {
        read_everything(dir);
    }
    let _ = std::fs::write(dir.join(FILES[i]), &originals[i + 1]);
});
