//! A real client: the sample region exported as quantized-mesh terrain and
//! as 3D Tiles, served from localhost and loaded by CesiumJS (npm `cesium`, pinned in
//! tools/js/package.json) in Debian's headless Chromium (WebGL through
//! SwiftShader), driven by puppeteer-core — all installed by
//! scripts/setup-test; the driver script starts and stops the server and
//! the browser itself.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{gdaltransform, grid_points_on_the_ellipsoid, relevo_ok, repo, sample_bundle};
use serde_json::{json, Value};
use std::path::Path;
use std::process::Command;

/// Run the driver (tools/js/cesium-check.mjs) on `request`: its result.
fn drive(terrain: &Path, request: &Value, screenshot: &Path, tiles: Option<&Path>) -> Value {
    let request_path = screenshot.with_extension("json");
    std::fs::write(&request_path, request.to_string()).unwrap();
    let mut command = Command::new("node");
    command
        .arg(repo("tools/js/cesium-check.mjs"))
        .args([terrain, &request_path, screenshot]);
    if let Some(t) = tiles {
        command.arg(t);
    }
    let out = command
        .output()
        .expect("node is installed by scripts/setup-test");
    serde_json::from_slice(&out.stdout).unwrap_or_else(|_| {
        panic!(
            "driver output: {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

/// The view every scene is seen from: from the south-west, 2.5 km up,
/// looking north-east and down.
const VIEW: [f64; 5] = [-34.93, -8.09, 2500.0, 30.0, -20.0];

#[test]
fn cesium_loads_the_terrain_draws_the_relief_and_samples_relevos_heights() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let terrain = dir.path().join("terrain");
    relevo_ok([
        "export".as_ref(),
        "quantized-mesh".as_ref(),
        bundle.as_os_str(),
        "--out".as_ref(),
        terrain.as_os_str(),
    ]);
    // 50 grid points spread over the region, with PROJ's ellipsoidal heights.
    let all = grid_points_on_the_ellipsoid(&bundle, 2);
    let points: Vec<[f64; 3]> = (0..50).map(|k| all[k * all.len() / 50]).collect();
    let screenshot = dir.path().join("cesium.png");
    let request = json!({
        "view": VIEW,
        "points": points.iter().map(|p| [p[0], p[1]]).collect::<Vec<_>>(),
    });
    let result = drive(&terrain, &request, &screenshot, None);
    // No error from the page, the console or any tile request.
    assert_eq!(result["errors"], json!([]), "{result}");

    // Heights CesiumJS samples from the finest tiles are Relevo's, within
    // their quantization (height: range / 32767; a vertex's place: half a
    // 1/32767 of a level-12 tile, on slopes up to 1).
    let sampled = result["sampled"].as_array().unwrap();
    assert_eq!(sampled.len(), 50);
    let allowed_m = 95.0 / 32767.0 + (180.0 / 4096.0) * 111_320.0 / 32767.0 / 2.0 + 0.001;
    for (p, s) in points.iter().zip(sampled) {
        let s = s.as_f64().unwrap();
        assert!(
            (s - p[2]).abs() <= allowed_m,
            "at {p:?} CesiumJS samples {s} m"
        );
    }

    // The relief shows: over the bare ellipsoid the view is one flat grey;
    // over the terrain the low light shades the slopes apart.
    let luminance = |which: &str| -> Vec<i64> {
        result[which]["luminance"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_i64().unwrap())
            .collect()
    };
    let (relief, flat) = (luminance("relevo"), luminance("ellipsoid"));
    let spread = |v: &[i64]| v.iter().max().unwrap() - v.iter().min().unwrap();
    assert!(spread(&flat) <= 4, "the ellipsoid view: {flat:?}");
    assert!(spread(&relief) >= 30, "the terrain view: {relief:?}");
    let differing = relief
        .iter()
        .zip(&flat)
        .filter(|(a, b)| (*a - *b).abs() > 8)
        .count();
    assert!(
        differing * 10 >= relief.len(),
        "{differing} of {} cells differ",
        relief.len()
    );
    assert!(std::fs::metadata(&screenshot).unwrap().len() > 10_000);
}

#[test]
fn cesium_draws_the_vegetation_where_the_database_has_trees_and_the_3d_tiles_terrain() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let (terrain, tiles) = (dir.path().join("terrain"), dir.path().join("tiles"));
    for (format, out) in [("quantized-mesh", &terrain), ("3dtiles", &tiles)] {
        relevo_ok([
            "export".as_ref(),
            format.as_ref(),
            bundle.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
        ]);
    }
    // The database's trees on the Earth, by PROJ.
    let manifest: Value =
        serde_json::from_slice(&std::fs::read(bundle.join("manifest.json")).unwrap()).unwrap();
    let wkt = dir.path().join("crs.wkt");
    std::fs::write(&wkt, manifest["crs"]["wkt"].as_str().unwrap()).unwrap();
    let database = std::fs::read_to_string(bundle.join("vegetation.csv")).unwrap();
    let positions: String = database
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(';').collect();
            format!("{} {}\n", f[1], f[2])
        })
        .collect();
    let trees: Vec<[f64; 3]> = gdaltransform(
        &[
            "-s_srs",
            wkt.to_str().unwrap(),
            "-t_srs",
            "+proj=longlat +datum=WGS84",
        ],
        &positions,
    )
    .lines()
    .map(|l| {
        let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
        // Projected 10 m above the ground, inside the crowns.
        [v[0], v[1], 10.0]
    })
    .collect();
    let screenshot = dir.path().join("vegetation.png");
    let request = json!({
        "view": VIEW,
        "points": [],
        "scenes": [
            {"name": "terrain", "terrain": true},
            {"name": "vegetation", "terrain": true, "tilesets": ["vegetation/tileset.json"],
             "project": trees, "screenshot": true},
            {"name": "tiles", "terrain": false, "tilesets": ["tileset.json"],
             "screenshot": dir.path().join("tiles.png")},
            {"name": "ellipsoid", "terrain": false},
        ],
    });
    let result = drive(&terrain, &request, &screenshot, Some(&tiles));
    // No error from the page, the console, a tile or a request.
    assert_eq!(result["errors"], json!([]), "{}", result["errors"]);

    let grid = |scene: &str, what: &str| -> Vec<i64> {
        result[scene][what]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_i64().unwrap())
            .collect()
    };
    // Cells where the vegetation changes the view: darker, lighter or greener.
    let (bare, grown) = (
        grid("terrain", "luminance"),
        grid("vegetation", "luminance"),
    );
    let (bare_green, grown_green) = (grid("terrain", "green"), grid("vegetation", "green"));
    let changed: Vec<usize> = (0..bare.len())
        .filter(|&i| (grown[i] - bare[i]).abs() > 8 || grown_green[i] - bare_green[i] > 10)
        .collect();
    // Cells the database's trees project into (96 × 54, row-major).
    let mut trees_in = vec![0usize; bare.len()];
    for c in grid("vegetation", "projected") {
        if c >= 0 {
            trees_in[c as usize] += 1;
        }
    }
    let near_a_tree = |i: usize| {
        let (x, y) = ((i % 96) as i64, (i / 96) as i64);
        (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                let (x, y) = (x + dx, y + dy);
                (0..96).contains(&x) && (0..54).contains(&y) && trees_in[(y * 96 + x) as usize] > 0
            })
        })
    };
    // The trees show, green, where the database has them: nearly every
    // changed cell at a tree, and a good share of the cells with trees
    // changed (from 4 km, the tiles' refinement draws a spread sample of
    // the farther trees).
    assert!(changed.len() >= 100, "{} cells changed", changed.len());
    let at_trees = changed.iter().filter(|&&i| near_a_tree(i)).count();
    assert!(
        at_trees * 100 >= changed.len() * 95,
        "{at_trees} of {} changed cells at trees",
        changed.len()
    );
    let dense: Vec<usize> = (0..bare.len()).filter(|&i| trees_in[i] >= 3).collect();
    let dense_changed = dense.iter().filter(|i| changed.contains(i)).count();
    assert!(
        dense_changed * 100 >= dense.len() * 40,
        "{dense_changed} of {} cells with trees changed",
        dense.len()
    );
    let greener: i64 = changed
        .iter()
        .map(|&i| grown_green[i] - bare_green[i])
        .sum();
    assert!(
        greener > 5 * changed.len() as i64,
        "the changed cells are not greener: {greener}"
    );

    // The 3D Tiles terrain with its drape, over the bare ellipsoid.
    let (tiles_view, flat) = (grid("tiles", "luminance"), grid("ellipsoid", "luminance"));
    let differing = (0..flat.len())
        .filter(|&i| (tiles_view[i] - flat[i]).abs() > 8)
        .count();
    assert!(
        differing * 100 >= flat.len() * 15,
        "{differing} of {} cells differ",
        flat.len()
    );
    let spread = tiles_view.iter().max().unwrap() - tiles_view.iter().min().unwrap();
    assert!(spread >= 30, "{spread}");
    assert!(std::fs::metadata(&screenshot).unwrap().len() > 10_000);
}
