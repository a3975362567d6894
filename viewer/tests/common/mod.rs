//! A real terrain for the viewer's tests, written by relevo-core (no GDAL).

use relevo_core::bundle::{write_terrain_bundle, Crs};
use relevo_core::geo::GeoTransform;
use relevo_core::grid::HeightGrid;
use std::path::{Path, PathBuf};

/// A terrain-only bundle of the committed Copernicus crop of Grenoble
/// (257², 150 m nominal cells, 179–1908 m).
pub fn grenoble_bundle(dir: &Path) -> PathBuf {
    let crop =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/crops/copernicus_grenoble_257.f32");
    let heights: Vec<f32> = std::fs::read(crop)
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let side = 257;
    let grid = HeightGrid {
        side,
        heights,
        mask: vec![1; side * side],
        geotransform: GeoTransform::north_up(700_000.0, 5_050_000.0, 150.0, 150.0),
    };
    let crs = Crs {
        wkt: String::new(),
        epsg: None,
    };
    write_terrain_bundle(
        &dir.join("grenoble.relevo"),
        "grenoble",
        &grid,
        150.0,
        crs,
        false,
    )
    .unwrap()
}

/// The Grenoble crop with a drape derived from its heights (tint and
/// hillshade, one pixel per vertex), for the samples tab.
#[allow(dead_code)] // used by the UI and window tests, not the flight tests
pub fn grenoble_bundle_with_drape(dir: &Path) -> PathBuf {
    use relevo_core::bundle::{Bundle, BundleLock, BundleWriter, ColorInfo};
    let path = grenoble_bundle(dir);
    let bundle = Bundle::open(&path).unwrap();
    let side = bundle.manifest.grid.side;
    let heights = bundle.heights().unwrap();
    let mask = bundle.mask().unwrap();
    let rgba = relevo_core::raster::tint::terrain_drape(
        &heights,
        &mask,
        side,
        bundle.manifest.grid.cell_size_m,
        bundle.manifest.grid.height_range_m,
    );
    let mut writer =
        BundleWriter::rewrite(BundleLock::acquire(&bundle.dir).unwrap(), &bundle, |_| true)
            .unwrap();
    let info = ColorInfo {
        width: side,
        height: side,
        geotransform: bundle.manifest.grid.geotransform,
        bands: [0, 0, 0],
    };
    writer.write_drape(&rgba, info).unwrap();
    drop((heights, mask, bundle));
    writer.commit().unwrap()
}

/// The Grenoble crop as a pyramid of 32-cell tiles (8² tiles at level 0,
/// four levels), written by relevo-core, its drape derived from the
/// heights.
#[allow(dead_code)] // used by the window tests, not the flight tests
pub fn grenoble_pyramid(dir: &Path) -> PathBuf {
    use relevo_core::bundle::GridInfo;
    use relevo_core::pyramid::{write_pyramid, BuildOptions, PyramidDescription, WriteOptions};
    let source = dir.join("pyramid_source");
    std::fs::create_dir_all(&source).unwrap();
    let single = relevo_core::bundle::Bundle::open(&grenoble_bundle(&source)).unwrap();
    let g = &single.manifest.grid;
    let grid = HeightGrid {
        side: g.side,
        heights: single.heights().unwrap().to_vec(),
        mask: single.mask().unwrap().to_vec(),
        geotransform: g.geotransform,
    };
    let description = PyramidDescription {
        region: "grenoble".into(),
        crs: single.manifest.crs.clone(),
        grid: GridInfo::of(&grid, g.cell_size_m, 1.0).unwrap(),
        inputs: Vec::new(),
        parameters: Default::default(),
    };
    let options = WriteOptions {
        tile_cells: 32,
        build: BuildOptions {
            metric: single.manifest.lp_error_metric,
            cell_size_m: g.cell_size_m,
            drape: true,
        },
        force: false,
        resume: false,
    };
    write_pyramid(
        &dir.join("grenoble_tiled.relevo"),
        &grid,
        description,
        options,
        &|_| {},
    )
    .unwrap()
}
