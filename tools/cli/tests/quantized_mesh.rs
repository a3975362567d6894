//! `relevo export quantized-mesh` on the sample region, read back by two
//! decoders that share no code with Relevo — HERE's
//! `@here/quantized-mesh-decoder` (npm) and `quantized-mesh-tile` (PyPI),
//! both installed by scripts/setup-test — and checked against the bundle's
//! heights taken to the ellipsoid by PROJ's own command line.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{file_hashes, grid_points_on_the_ellipsoid, relevo, relevo_ok, repo, sample_bundle};
use serde_json::Value;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::process::Command;

type TileKey = (u64, u64, u64);

/// One JSON line a tile from a decoder script, keyed by (z, x, y).
fn decoded(program: &str, script: &str, dir: &Path) -> BTreeMap<TileKey, Value> {
    let mut command = Command::new(program);
    command.arg(repo(script)).arg(dir);
    if program == "python3" {
        let home = std::env::var("HOME").unwrap_or_default();
        command.env("PYTHONPATH", format!("{home}/.cache/relevo/python"));
    }
    let out = command
        .output()
        .expect("the decoders are installed by scripts/setup-test");
    assert!(
        out.status.success(),
        "{script}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| {
            let v: Value = serde_json::from_str(l).unwrap();
            let key = (
                v["z"].as_u64().unwrap(),
                v["x"].as_u64().unwrap(),
                v["y"].as_u64().unwrap(),
            );
            (key, v)
        })
        .collect()
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Degrees of tile (z, x, y) of the geodetic tiling: west, south, east, north.
fn bounds((z, x, y): TileKey) -> [f64; 4] {
    let size = 180.0 / f64::powi(2.0, z as i32);
    let (w, s) = (-180.0 + x as f64 * size, -90.0 + y as f64 * size);
    [w, s, w + size, s + size]
}

/// A tile's vertices as (longitude, latitude, height) from the npm decoder's
/// quantized values.
fn positions(key: TileKey, tile: &Value) -> Vec<[f64; 3]> {
    let [w, s, e, n] = bounds(key);
    let (lo, hi) = (
        tile["header"]["minHeight"].as_f64().unwrap(),
        tile["header"]["maxHeight"].as_f64().unwrap(),
    );
    let q = numbers(&tile["vertices"]);
    let count = q.len() / 3;
    (0..count)
        .map(|i| {
            let f = |k: usize| q[k * count + i] / 32767.0;
            [
                w + f(0) * (e - w),
                s + f(1) * (n - s),
                lo + f(2) * (hi - lo),
            ]
        })
        .collect()
}

/// Height of the tile's surface at (lon, lat), if a triangle holds it.
fn surface_height(points: &[[f64; 3]], triangles: &[f64], p: [f64; 2]) -> Option<f64> {
    for t in triangles.chunks(3) {
        let [a, b, c] = [0, 1, 2].map(|k| points[t[k] as usize]);
        let det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        if det == 0.0 {
            continue;
        }
        let wb = ((p[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (p[1] - a[1])) / det;
        let wc = ((b[0] - a[0]) * (p[1] - a[1]) - (p[0] - a[0]) * (b[1] - a[1])) / det;
        let wa = 1.0 - wb - wc;
        if wa >= -1e-9 && wb >= -1e-9 && wc >= -1e-9 {
            return Some(wa * a[2] + wb * b[2] + wc * c[2]);
        }
    }
    None
}

#[test]
fn the_sample_region_exports_tiles_two_decoders_read_neighbours_meet_and_heights_hold() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let out = dir.path().join("terrain");
    let summary: Value = serde_json::from_str(&relevo_ok([
        "export".as_ref(),
        "quantized-mesh".as_ref(),
        bundle.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--json".as_ref(),
    ]))
    .unwrap();
    let max_zoom = summary["max_zoom"].as_u64().unwrap();
    assert_eq!(max_zoom, 12, "90 m cells at 8° S match level 12");
    assert!(summary["heights"]
        .as_str()
        .unwrap()
        .contains("ellipsoid, from EGM96"));

    // layer.json lists exactly the tiles written.
    let layer: Value =
        serde_json::from_slice(&std::fs::read(out.join("layer.json")).unwrap()).unwrap();
    assert_eq!(layer["format"], "quantized-mesh-1.0");
    assert_eq!(layer["scheme"], "tms");
    let available = layer["available"].as_array().unwrap();
    assert_eq!(available.len() as u64, max_zoom + 1);
    let mut listed = Vec::new();
    for (z, ranges) in available.iter().enumerate() {
        for r in ranges.as_array().unwrap() {
            let g = |k: &str| r[k].as_u64().unwrap();
            for y in g("startY")..=g("endY") {
                for x in g("startX")..=g("endX") {
                    listed.push((z as u64, x, y));
                }
            }
        }
    }
    listed.sort_unstable();

    let js = decoded("node", "tools/js/decode-quantized-mesh.mjs", &out);
    let py = decoded("python3", "tools/py/decode_quantized_mesh.py", &out);
    assert_eq!(js.keys().copied().collect::<Vec<_>>(), listed);
    assert_eq!(py.keys().copied().collect::<Vec<_>>(), listed);

    assert_decoders_agree(&js, &py);
    assert_neighbours_meet(&js);
    let points = grid_points_on_the_ellipsoid(&bundle, 4);
    assert_levels_within_error(&js, &points, max_zoom);
}

/// The two decoders read the same tiles: triangles, edges, positions, and
/// the extensions are there.
fn assert_decoders_agree(js: &BTreeMap<TileKey, Value>, py: &BTreeMap<TileKey, Value>) {
    // The two decoders read the same tiles.
    for (key, a) in js {
        let b = &py[key];
        assert_eq!(
            numbers(&a["triangles"]),
            numbers(&b["triangles"]),
            "{key:?}"
        );
        let edges: Vec<Vec<f64>> = ["west", "south", "east", "north"]
            .iter()
            .map(|e| numbers(&a[*e]))
            .collect();
        let py_edges: Vec<Vec<f64>> = b["edges"].as_array().unwrap().iter().map(numbers).collect();
        assert_eq!(edges, py_edges, "{key:?}");
        let ours = positions(*key, a);
        let theirs: Vec<Vec<f64>> = b["vertices"]
            .as_array()
            .unwrap()
            .iter()
            .map(numbers)
            .collect();
        assert_eq!(ours.len(), theirs.len());
        for (p, q) in ours.iter().zip(&theirs) {
            for k in 0..3 {
                assert!((p[k] - q[k]).abs() < 1e-6, "{key:?}: {p:?} vs {q:?}");
            }
        }
        assert_eq!(
            a["normals"].as_u64().unwrap() as usize,
            2 * ours.len(),
            "octvertexnormals"
        );
        assert!(
            a["waterMaskBytes"].as_u64().unwrap() == 1
                || a["waterMaskBytes"].as_u64().unwrap() == 65536
        );
        // Counter-clockwise, as clients cull, and covering the tile once —
        // no hole, no overlap — in the quantized grid. Rounding each vertex
        // to the grid (half a unit) changes a triangle's doubled area by
        // less than 3 × its longest edge: only a sliver that thin may turn.
        let q = numbers(&a["vertices"]);
        let count = q.len() / 3;
        let uv = |i: f64| [q[i as usize], q[count + i as usize]];
        let mut area = 0.0;
        for t in numbers(&a["triangles"]).chunks(3) {
            let [p, r, s] = [0, 1, 2].map(|k| uv(t[k]));
            let doubled = (r[0] - p[0]) * (s[1] - p[1]) - (s[0] - p[0]) * (r[1] - p[1]);
            let longest = [(p, r), (r, s), (s, p)]
                .iter()
                .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt())
                .fold(0.0, f64::max);
            assert!(
                doubled >= -3.0 * longest,
                "{key:?}: a triangle turns clockwise ({doubled})"
            );
            area += doubled / 2.0;
        }
        let full = 32767.0 * 32767.0;
        assert!(
            (area - full).abs() < 1e-4 * full,
            "{key:?}: {area} of {full}"
        );
    }
}

/// Neighbours of a level share their edge's vertices exactly.
fn assert_neighbours_meet(js: &BTreeMap<TileKey, Value>) {
    // Neighbours of a level share their edge's vertices exactly: quantized
    // place along the edge and quantized height.
    let quantized = |tile: &Value| {
        let q = numbers(&tile["vertices"]);
        let n = q.len() / 3;
        move |i: f64, along: usize| {
            (
                q[along * n + i as usize] as u32,
                q[2 * n + i as usize] as u32,
            )
        }
    };
    let mut pairs = 0;
    for (&(z, x, y), a) in js {
        for (dx, dy, mine, theirs, along) in
            [(1, 0, "east", "west", 1), (0, 1, "north", "south", 0)]
        {
            let Some(b) = js.get(&(z, x + dx, y + dy)) else {
                continue;
            };
            let (qa, qb) = (quantized(a), quantized(b));
            let mut ea: Vec<(u32, u32)> = numbers(&a[mine]).iter().map(|&i| qa(i, along)).collect();
            let mut eb: Vec<(u32, u32)> =
                numbers(&b[theirs]).iter().map(|&i| qb(i, along)).collect();
            ea.sort_unstable();
            eb.sort_unstable();
            assert_eq!(ea, eb, "level {z}: ({x}, {y}) {mine} edge vs its neighbour");
            pairs += 1;
        }
    }
    assert!(pairs >= 12, "{pairs} neighbouring pairs");
}

/// A tile's decoded vertices (longitude, latitude, height) and triangles.
type DecodedTile<'a> = (&'a TileKey, Vec<[f64; 3]>, Vec<f64>);

/// Every level's surface against the bundle's heights at `points`.
fn assert_levels_within_error(js: &BTreeMap<TileKey, Value>, points: &[[f64; 3]], max_zoom: u64) {
    // The surface of every level is within that level's geometric error
    // (plus the quantization) of the bundle's heights, taken to the
    // ellipsoid by PROJ, at grid points with data around them; the finest
    // level keeps every vertex.
    assert!(points.len() > 400, "{} points", points.len());
    let range_m = {
        let t = js.values().next().unwrap();
        t["header"]["maxHeight"].as_f64().unwrap() - t["header"]["minHeight"].as_f64().unwrap()
    };
    let quantum_m = range_m / 32767.0;
    let by_level: HashMap<u64, Vec<DecodedTile>> =
        js.iter().fold(HashMap::new(), |mut m, (k, t)| {
            m.entry(k.0)
                .or_default()
                .push((k, positions(*k, t), numbers(&t["triangles"])));
            m
        });
    for z in 0..=max_zoom {
        let error_m =
            6_378_137.0 * 2.0 * std::f64::consts::PI * 0.25 / 130.0 / f64::powi(2.0, z as i32);
        // A vertex moves by up to half a 1/32767 of the tile across; on
        // slopes up to 1 (45°) its height at a fixed place moves as much.
        let shift_m = 180.0 / f64::powi(2.0, z as i32) * 111_320.0 / 32767.0 / 2.0;
        let allowed = if z == max_zoom { 0.0 } else { error_m } + quantum_m + shift_m + 0.001;
        let mut worst: f64 = 0.0;
        for p in points {
            let tile = by_level[&z].iter().find(|(k, _, _)| {
                let [w, s, e, n] = bounds(**k);
                (w..=e).contains(&p[0]) && (s..=n).contains(&p[1])
            });
            let (_, vertices, triangles) =
                tile.expect("every grid point lies in a tile of every level");
            let h = surface_height(vertices, triangles, [p[0], p[1]])
                .expect("the tile covers the point");
            worst = worst.max((h - p[2]).abs());
        }
        assert!(
            worst <= allowed,
            "level {z}: {worst:.3} m off, allowed {allowed:.3} m"
        );
    }
}

#[test]
fn a_pyramid_exports_the_same_tiles_as_its_single_grid_at_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    // The sample region's DEM alone (a pyramid takes no imagery yet), as a
    // single grid and as a pyramid of 33² tiles, both draped with the tint
    // and hillshade derived from the heights.
    let dem = repo("data/olinda/olinda_dem_utm25s.tif");
    let prep = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec![
            "prep",
            "--dem",
            dem.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
        ];
        args.extend(extra);
        relevo_ok(&args);
        out
    };
    let single = prep("single.relevo", &["--terrain-drape"]);
    let pyramid = prep("tiles.relevo", &["--tiled", "--tile-size", "32"]);
    let export_as = |format: &str, bundle: &Path, name: &str, threads: &str| {
        let out = dir.path().join(name);
        let status = Command::new(env!("CARGO_BIN_EXE_relevo"))
            .args(["export", format])
            .arg(bundle)
            .arg("--out")
            .arg(&out)
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(
            status.status.success(),
            "{}",
            String::from_utf8_lossy(&status.stderr)
        );
        file_hashes(&out)
    };
    let export = |bundle: &Path, name: &str, threads: &str| {
        export_as("quantized-mesh", bundle, name, threads)
    };
    let from_grid = export(&single, "from_grid", "1");
    assert!(from_grid.len() > 20);
    assert_eq!(export(&single, "from_grid_4", "4"), from_grid);
    // The pyramid's errors are the single grid's, bit for bit: so are its
    // tiles (layer.json differs only by the region's name).
    let tiles_only = |mut files: BTreeMap<String, String>| {
        files.remove("layer.json");
        files
    };
    let from_pyramid = export(&pyramid, "from_pyramid", "3");
    assert_eq!(tiles_only(from_pyramid), tiles_only(from_grid));
    let layer = |name: &str| -> Value {
        serde_json::from_slice(&std::fs::read(dir.path().join(name).join("layer.json")).unwrap())
            .unwrap()
    };
    assert_eq!(
        layer("from_pyramid")["available"],
        layer("from_grid")["available"]
    );
    // So are its 3D Tiles, their textures and tilesets included.
    let tiles_from_grid = export_as("3dtiles", &single, "3d_from_grid", "1");
    assert!(tiles_from_grid.keys().any(|f| f.ends_with(".glb")));
    assert_eq!(
        export_as("3dtiles", &pyramid, "3d_from_pyramid", "3"),
        tiles_from_grid
    );
}

#[test]
fn bad_requests_are_refused_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let out = dir.path().join("terrain");
    // Not a bundle.
    let r = relevo([
        "export",
        "quantized-mesh",
        dir.path().join("missing.relevo").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!r.status.success());
    assert!(!out.exists());
    // A folder that is not an export is never replaced.
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let r = relevo([
        "export",
        "quantized-mesh",
        bundle.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--force",
    ]);
    assert!(!r.status.success());
    assert!(
        String::from_utf8_lossy(&r.stderr).contains("no layer.json"),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
    let r = relevo([
        "export",
        "quantized-mesh",
        bundle.to_str().unwrap(),
        "--out",
        dir.path().join("t2").to_str().unwrap(),
        "--max-zoom",
        "30",
    ]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("--max-zoom 30"));
}
