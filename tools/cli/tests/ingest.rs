//! End-to-end ingest on real tiles: stitching, reprojection and decoding.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::*;
use relevo::ingest::stitch::{place, StitchOptions};
use relevo_core::raster::mosaic::{feather_weights, mosaic, seam_visibility, Overlap};
use std::path::PathBuf;

/// Cut `srtm_ref.tif` into a 2×2 grid of tiles with gdal_translate, each
/// tile grown by `overlap` cells into its neighbours.
fn cut_srtm(dir: &std::path::Path, overlap: usize) -> Vec<PathBuf> {
    let src = shared("dem/srtm_ref.tif");
    let half = 500;
    let mut tiles = Vec::new();
    for (k, (c, r)) in [(0usize, 0usize), (1, 0), (0, 1), (1, 1)]
        .into_iter()
        .enumerate()
    {
        let x0 = (c * half).saturating_sub(overlap * c);
        let y0 = (r * half).saturating_sub(overlap * r);
        let (w, h) = (half + overlap, half + overlap);
        let out = dir.join(format!("tile{k}.tif"));
        let win = [x0.to_string(), y0.to_string(), w.to_string(), h.to_string()];
        gdal_tool(
            "gdal_translate",
            &[
                "-q",
                "-srcwin",
                &win[0],
                &win[1],
                &win[2],
                &win[3],
                src.to_str().unwrap(),
                out.to_str().unwrap(),
            ],
        );
        tiles.push(out);
    }
    tiles
}

#[test]
fn srtm_tiles_stitch_back_to_the_original_exactly() {
    let original = read(&shared("dem/srtm_ref.tif"));
    for overlap in [0, 40] {
        for rule in ["first", "last", "blend"] {
            let dir = tempfile::tempdir().unwrap();
            let tiles = cut_srtm(dir.path(), overlap);
            let out = dir.path().join("mosaic.tif");
            let mut args: Vec<String> = tiles.iter().map(|p| p.display().to_string()).collect();
            args.extend([
                "--overlap".into(),
                rule.into(),
                "--out".into(),
                out.display().to_string(),
            ]);
            relevo_ok(["stitch"].into_iter().map(String::from).chain(args));
            let m = read(&out);
            assert_eq!(
                (m.width, m.height),
                (1000, 1000),
                "overlap {overlap} {rule}"
            );
            assert_eq!(
                m.geotransform, original.geotransform,
                "overlap {overlap} {rule}"
            );
            assert_eq!(m.nodata, original.nodata);
            assert!(
                m.bands[0] == original.bands[0],
                "values differ: overlap {overlap}, {rule}"
            );
        }
    }
}

#[test]
fn shifted_rgbn_tiles_mosaic_onto_the_first_grid() {
    let a = shared("tiles/rgbn_5m/rgbn_suba.tif");
    let b = shared("tiles/rgbn_5m/rgbn_subb.tif");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rgbn.tif");
    relevo_ok([
        "stitch".as_ref(),
        a.as_os_str(),
        b.as_os_str(),
        "-r".as_ref(),
        "bilinear".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    let m = read(&out);
    let ra = read(&a);
    let rb = read(&b);
    // The grid is suba's, grown to reach subb's far corner (subb is shifted
    // by (0.4, 0.2) cells, so its edge falls inside the last cell).
    assert_eq!(m.geotransform, ra.geotransform);
    let right = rb.geotransform[0] + rb.width as f64 * 5.0;
    let bottom = rb.geotransform[3] - rb.height as f64 * 5.0;
    assert_eq!(
        m.width,
        ((right - ra.geotransform[0]) / 5.0).ceil() as usize
    );
    assert_eq!(
        m.height,
        ((ra.geotransform[3] - bottom) / 5.0).ceil() as usize
    );
    assert_eq!(m.bands.len(), 4);

    // Offsets of subb's cells on the mosaic grid.
    let dx = (rb.geotransform[0] - ra.geotransform[0]) / 5.0; // 154.4
    let dy = (ra.geotransform[3] - rb.geotransform[3]) / 5.0; // 63.2
    let (mut only_a, mut only_a_differ, mut overlap_a, mut overlap_b, mut n_overlap) =
        (0usize, 0usize, 0.0, 0.0, 0usize);
    for r in 0..ra.height {
        for c in 0..ra.width {
            let av = ra.bands[0][r * ra.width + c];
            let mv = m.bands[0][r * m.width + c];
            if av == 0.0 {
                continue;
            }
            // subb sampled bilinearly at this cell centre, when inside and valid.
            let (bx, by) = (c as f64 - dx, r as f64 - dy);
            let inside_b =
                bx >= 0.0 && by >= 0.0 && bx < (rb.width - 1) as f64 && by < (rb.height - 1) as f64;
            let bv = if inside_b {
                bilinear(&rb.bands[0], rb.width, bx, by)
            } else {
                0.0
            };
            // Clear of subb's window (its bilinear footprint reaches one cell past it).
            let clear_of_b =
                bx < -2.0 || by < -2.0 || bx > rb.width as f64 + 1.0 || by > rb.height as f64 + 1.0;
            if clear_of_b {
                only_a += 1;
                only_a_differ += (mv != av) as usize;
            } else if bv != 0.0 {
                overlap_a += (mv - av).abs();
                overlap_b += (mv - bv).abs();
                n_overlap += 1;
            }
        }
    }
    assert!(n_overlap > 10_000, "overlap cells: {n_overlap}");
    // Where subb cannot reach, the mosaic is suba cell for cell.
    assert!(only_a > 10_000, "cells only suba covers: {only_a}");
    assert_eq!(
        only_a_differ, 0,
        "cells only suba covers that differ from it"
    );
    let (mean_a, mean_b) = (overlap_a / n_overlap as f64, overlap_b / n_overlap as f64);
    eprintln!("rgbn overlap: mean |mosaic − suba| = {mean_a:.2}, |mosaic − subb| = {mean_b:.2} DN over {n_overlap} cells");
    // Stated tolerance: within 6 DN of each source on average (both are the
    // same 5 m scene; subb is resampled across a 0.4×0.2-cell shift).
    assert!(mean_a < 6.0 && mean_b < 6.0, "{mean_a} {mean_b}");
}

/// Bilinear sample at cell-centre coordinates (x, y); 0 (no-data) if any corner is 0.
fn bilinear(v: &[f64], width: usize, x: f64, y: f64) -> f64 {
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let at = |c: usize, r: usize| v[r * width + c];
    let corners = [
        at(x0, y0),
        at(x0 + 1, y0),
        at(x0, y0 + 1),
        at(x0 + 1, y0 + 1),
    ];
    if corners.contains(&0.0) {
        return 0.0;
    }
    let top = corners[0] * (1.0 - fx) + corners[1] * fx;
    let bottom = corners[2] * (1.0 - fx) + corners[3] * fx;
    top * (1.0 - fy) + bottom * fy
}

fn landsat(scene: &str, band: &str) -> PathBuf {
    shared(&format!(
        "tiles/landsat8_overlap/LC08_L1TP_{scene}_20200518_20200518_01_RT_{band}.TIF"
    ))
}

#[test]
fn landsat_collar_never_reaches_the_mosaic_and_blend_is_seamless() {
    let paths = vec![landsat("224077", "B4"), landsat("224078", "B4")];
    let opts = StitchOptions {
        src_nodata: Some(0.0),
        ..Default::default()
    };
    let p = place(&paths, &opts).unwrap();
    let (w, h) = (p.grid.width, p.grid.height);
    let first = mosaic(w, h, 1, &p.tiles, Overlap::First);
    let blend = mosaic(w, h, 1, &p.tiles, Overlap::Blend);

    // Per cell: each scene's value on the mosaic grid (NaN = no data).
    let on_grid = |k: usize, c: usize, r: usize| {
        let t = &p.tiles[k];
        let (tc, tr) = (c.wrapping_sub(t.col), r.wrapping_sub(t.row));
        if tc < t.raster.width && tr < t.raster.height {
            t.raster.data[tr * t.raster.width + tc]
        } else {
            f64::NAN
        }
    };
    let mut overlap_cells = 0usize;
    for r in 0..h {
        for c in 0..w {
            let (a, b) = (on_grid(0, c, r), on_grid(1, c, r));
            let v = blend.data[r * w + c];
            assert!(a != 0.0 && b != 0.0, "collar value survived as data");
            match (a.is_nan(), b.is_nan()) {
                (true, true) => assert!(v.is_nan()),
                (false, true) => assert_eq!(v, a),
                (true, false) => assert_eq!(v, b),
                (false, false) => {
                    overlap_cells += 1;
                    assert!(
                        v >= a.min(b) - 1e-9 && v <= a.max(b) + 1e-9,
                        "blend outside its sources"
                    );
                }
            }
        }
    }
    assert!(overlap_cells > 1_000_000, "overlap: {overlap_cells}");

    // Weights: scene A's share changes smoothly and is ~0 at A's own edge.
    let covered: Vec<bool> = (0..w * h).map(|i| !blend.data[i].is_nan()).collect();
    let wa_tile = feather_weights(&p.tiles[0], &covered, w);
    let wb_tile = feather_weights(&p.tiles[1], &covered, w);
    let weight = |k: usize, tile: &[f32], c: usize, r: usize| {
        let t = &p.tiles[k];
        let (tc, tr) = (c.wrapping_sub(t.col), r.wrapping_sub(t.row));
        if tc < t.raster.width && tr < t.raster.height {
            tile[tr * t.raster.width + tc] as f64
        } else {
            0.0
        }
    };
    let share = |c: usize, r: usize| {
        let (wa, wb) = (weight(0, &wa_tile, c, r), weight(1, &wb_tile, c, r));
        (wa + wb > 0.0).then(|| wa / (wa + wb))
    };
    let mut steps = Vec::new();
    let mut edge_share = (0.0, 0usize);
    for r in 0..h - 1 {
        for c in 0..w - 1 {
            let Some(s) = share(c, r) else { continue };
            for (nc, nr) in [(c + 1, r), (c, r + 1)] {
                if let Some(t) = share(nc, nr) {
                    steps.push((s - t).abs());
                    // Crossing out of scene A into B-only cells: A's share at the edge.
                    if (s > 0.0) != (t > 0.0) {
                        edge_share.0 += s.max(t);
                        edge_share.1 += 1;
                    }
                }
            }
        }
    }
    steps.sort_by(f64::total_cmp);
    let p999 = steps[steps.len() * 999 / 1000];
    let edge_mean = edge_share.0 / edge_share.1 as f64;
    assert!(
        p999 < 0.01,
        "99.9th percentile step of scene A's weight: {p999}"
    );
    assert!(
        edge_mean < 0.01,
        "mean weight of scene A at its own edge: {edge_mean}"
    );

    // The two scenes come from one overpass, so their overlap differs little;
    // add a 300 DN offset to the second (a different acquisition's) to see
    // what each rule does with a real radiometric step on real texture.
    let seam_first = seam_visibility(&first, &p.tiles).unwrap();
    let seam_blend = seam_visibility(&blend, &p.tiles).unwrap();
    let mut offset = p.tiles.clone();
    offset[1].raster.data.iter_mut().for_each(|v| *v += 300.0);
    let offset_first = seam_visibility(&mosaic(w, h, 1, &offset, Overlap::First), &offset).unwrap();
    let offset_blend = seam_visibility(&mosaic(w, h, 1, &offset, Overlap::Blend), &offset).unwrap();
    eprintln!(
        "landsat B4 seam visibility: as shot first {seam_first:.3} blend {seam_blend:.3}; \
         +300 DN on 224078: first {offset_first:.3} blend {offset_blend:.3}"
    );
    assert!(
        seam_blend <= seam_first + 1e-3,
        "blend {seam_blend} vs first {seam_first}"
    );
    assert!(
        offset_blend < offset_first / 4.0,
        "blend {offset_blend} vs first {offset_first}"
    );
}

#[test]
fn landsat_stitch_cli_writes_a_georeferenced_mosaic() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b4.tif");
    relevo_ok([
        "stitch".as_ref(),
        landsat("224077", "B4").as_os_str(),
        landsat("224078", "B4").as_os_str(),
        "--src-nodata".as_ref(),
        "0".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    let m = read(&out);
    // Union of the two scenes on their shared 30 m grid.
    assert_eq!(
        m.geotransform,
        [694005.0, 30.0, 0.0, -2766615.0, 0.0, -30.0]
    );
    // West edge of 224077 to east edge of 224078; top of 224077 to bottom of 224078.
    assert_eq!(m.width, (717345 + 2041 * 30 - 694005) / 30);
    assert_eq!(m.height as i64, (-2766615 - (-2776995 - 1860 * 30)) / 30);
    assert_eq!(m.nodata, Some(0.0));
}

/// Tiles in mixed CRSs: the native grid of the tile already in the target
/// CRS wins (30 m, its cell lines), the other tile is resampled onto it.
/// Before, the reprojected tile's finer 28.8 m cell set the grid, the
/// native tile was resampled too and the grid started off its lines.
#[test]
fn mixed_crs_tiles_are_stitched_on_the_native_grid() {
    let dir = tempfile::tempdir().unwrap();
    let geographic = dir.path().join("224078_wgs84.tif");
    let source = landsat("224078", "B4");
    gdal_tool(
        "gdalwarp",
        &[
            "-q",
            "-t_srs",
            "EPSG:4326",
            "-srcnodata",
            "0",
            "-dstnodata",
            "0",
            source.to_str().unwrap(),
            geographic.to_str().unwrap(),
        ],
    );
    let out = dir.path().join("mixed.tif");
    let native = landsat("224077", "B4");
    relevo_ok([
        "stitch".as_ref(),
        native.as_os_str(),
        geographic.as_os_str(),
        "--src-nodata".as_ref(),
        "0".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    let m = read(&out);
    assert_eq!(
        m.geotransform,
        [694005.0, 30.0, 0.0, -2766615.0, 0.0, -30.0]
    );
    let band = &m.bands[0];
    let first_column = (0..m.height).filter(|&r| band[r * m.width] != 0.0).count();
    assert!(
        first_column > m.height / 2,
        "first column: {first_column} cells with data"
    );
    // North-west of the other scene the native tile is copied cell for cell.
    let a = read(&native);
    for r in 0..300 {
        for c in 0..700 {
            assert_eq!(
                band[r * m.width + c],
                a.bands[0][r * a.width + c],
                "cell ({c}, {r})"
            );
        }
    }
}

#[test]
fn geographic_dem_is_reprojected_to_utm_keeping_detail() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("srtm.relevo");
    let json = relevo_ok([
        "prep".as_ref(),
        "--dem".as_ref(),
        shared("dem/srtm_ref.tif").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--json".as_ref(),
    ]);
    let summary: serde_json::Value = serde_json::from_str(&json).unwrap();
    // 3 arc-seconds at 40° N: 92.6 m north-south, 71 m east-west; the finer wins.
    let cell = summary["cell_size_m"].as_f64().unwrap();
    assert!((cell - 71.0).abs() < 1.5, "cell {cell}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    // Eastern Turkey around 40.4° E: UTM zone 37N.
    assert_eq!(manifest["crs"]["epsg"], 32637);
    assert_eq!(summary["side"], 2049);
    relevo_ok(["validate".as_ref(), out.as_os_str()]);
}

#[test]
fn martini_tiles_decode_to_the_reference_terrain() {
    let reference = martini_reference();
    let dir = tempfile::tempdir().unwrap();
    for (name, file, encoding) in MARTINI_TILES {
        let out = prep_martini_tile(dir.path(), file, encoding);
        let expected = reference[name]["terrain"]["sha256"].as_str().unwrap();
        assert_eq!(sha256(&out.join("height.f32")), expected, "{name}");
    }
}

#[test]
fn plain_images_with_world_files_stitch_exactly() {
    let d = tempfile::tempdir().unwrap();
    let src = repo("data/olinda/L7_ETMs.tif");
    // Two overlapping halves as PNG (bands 3,2,1) with world files and no CRS:
    // one keeps GDAL's .wld, the other is renamed to .pgw.
    for (name, x0, w) in [("west", 0, 200), ("east", 150, 199)] {
        let out = d.path().join(format!("{name}.png"));
        gdal_tool(
            "gdal_translate",
            &[
                "-q",
                "-of",
                "PNG",
                "-co",
                "WORLDFILE=YES",
                "-b",
                "3",
                "-b",
                "2",
                "-b",
                "1",
                "-srcwin",
                &x0.to_string(),
                "0",
                &w.to_string(),
                "352",
                src.to_str().unwrap(),
                out.to_str().unwrap(),
            ],
        );
        let _ = std::fs::remove_file(d.path().join(format!("{name}.png.aux.xml")));
    }
    std::fs::rename(d.path().join("east.wld"), d.path().join("east.pgw")).unwrap();
    let out = d.path().join("mosaic.tif");
    relevo_ok([
        "stitch".as_ref(),
        d.path().join("west.png").as_os_str(),
        d.path().join("east.png").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    let m = read(&out);
    let original = read(&src);
    assert_eq!((m.width, m.height), (349, 352));
    for (k, b) in [3usize, 2, 1].into_iter().enumerate() {
        for (i, (&v, &o)) in m.bands[k].iter().zip(&original.bands[b - 1]).enumerate() {
            assert!((v - o).abs() < 1e-9, "band {b} cell {i}: {v} vs {o}");
        }
    }
    for k in 0..6 {
        assert!(
            (m.geotransform[k] - original.geotransform[k]).abs() < 1e-6,
            "{:?} vs {:?}",
            m.geotransform,
            original.geotransform
        );
    }
}
