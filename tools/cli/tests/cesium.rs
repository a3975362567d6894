//! A real client: the sample region exported as quantized-mesh terrain,
//! served from localhost and loaded by CesiumJS (npm `cesium`, pinned in
//! tools/js/package.json) in Debian's headless Chromium (WebGL through
//! SwiftShader), driven by puppeteer-core — all installed by
//! scripts/setup-test; the driver script starts and stops the server and
//! the browser itself.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{grid_points_on_the_ellipsoid, relevo_ok, repo, sample_bundle};
use serde_json::{json, Value};
use std::process::Command;

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
    let request = dir.path().join("request.json");
    std::fs::write(
        &request,
        json!({
            // From the south-west, 2.5 km up, looking north-east and down.
            "view": [-34.93, -8.09, 2500.0, 30.0, -20.0],
            "points": points.iter().map(|p| [p[0], p[1]]).collect::<Vec<_>>(),
        })
        .to_string(),
    )
    .unwrap();
    let screenshot = dir.path().join("cesium.png");
    let out = Command::new("node")
        .arg(repo("tools/js/cesium-check.mjs"))
        .args([&terrain, &request, &screenshot])
        .output()
        .expect("node is installed by scripts/setup-test");
    let result: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|_| {
        panic!(
            "driver output: {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    });
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
