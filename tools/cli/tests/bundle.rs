//! `relevo prep` as a process: determinism across thread counts, atomic
//! writes, existing bundles kept. Golden hashes: `tests/tests/pipeline.rs`.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::*;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

fn manifest(bundle: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(bundle.join("manifest.json")).unwrap()).unwrap()
}

/// Artifact name → sha256, recomputed from the files (not trusted from the manifest).
fn artifact_hashes(bundle: &Path) -> BTreeMap<String, String> {
    manifest(bundle)["artifacts"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(name, a)| {
            (
                name.clone(),
                sha256(&bundle.join(a["file"].as_str().unwrap())),
            )
        })
        .collect()
}

fn prep_with_threads(args: &[&str], out: &Path, threads: &str) {
    let status = Command::new(env!("CARGO_BIN_EXE_relevo"))
        .args(args)
        .args(["--out", out.to_str().unwrap()])
        .env("RAYON_NUM_THREADS", threads)
        .env("GDAL_NUM_THREADS", threads)
        .status()
        .unwrap();
    assert!(status.success());
}

#[test]
fn bundles_are_identical_across_thread_counts() {
    let d = tempfile::tempdir().unwrap();
    let srtm = shared("dem/srtm_ref.tif");
    let region = repo("data/olinda/REGION.toml");
    let cases: [Vec<&str>; 2] = [
        vec!["prep", region.to_str().unwrap()],
        vec!["prep", "--dem", srtm.to_str().unwrap()],
    ];
    for (k, args) in cases.iter().enumerate() {
        let one = d.path().join(format!("{k}-1.relevo"));
        let two = d.path().join(format!("{k}-2.relevo"));
        prep_with_threads(args, &one, "1");
        prep_with_threads(args, &two, "2");
        assert_eq!(artifact_hashes(&one), artifact_hashes(&two), "{args:?}");
        assert_eq!(manifest(&one)["artifacts"], manifest(&two)["artifacts"]);
    }
}

#[test]
fn existing_bundles_are_kept_unless_forced() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("lux.relevo");
    let dem = shared("dem/luxembourg_elev.tif");
    let args = [
        "prep",
        "--dem",
        dem.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    relevo_ok(args);
    std::fs::write(out.join("marker"), "old").unwrap();
    let again = relevo(args);
    assert!(!again.status.success());
    assert!(out.join("marker").exists(), "existing bundle was touched");
    let before = std::fs::read(out.join("manifest.json")).unwrap();
    relevo_ok(args.iter().chain(&["--force"]));
    let after = std::fs::read(out.join("manifest.json")).unwrap();
    assert_ne!(before, after, "--force did not replace the bundle");
    // A file the bundle does not list is the user's: replacing the bundle
    // carries it over instead of deleting it.
    assert_eq!(std::fs::read_to_string(out.join("marker")).unwrap(), "old");
    assert_eq!(listing(d.path()), ["lux.relevo"]);
}

#[test]
fn stale_staging_is_cleared_and_failures_leave_nothing() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("lux.relevo");
    let dem = shared("dem/luxembourg_elev.tif");
    let args = [
        "prep",
        "--dem",
        dem.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    // A folder in the staging place that Relevo did not make is refused by
    // name and left alone.
    std::fs::create_dir_all(d.path().join("lux.relevo.tmp/junk")).unwrap();
    let refused = relevo(args);
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(stderr.contains("lux.relevo.tmp") && stderr.contains("not made by Relevo"));
    assert!(d.path().join("lux.relevo.tmp/junk").exists());
    // Debris of a killed run carries the staging mark and is cleared.
    std::fs::write(d.path().join("lux.relevo.tmp/.relevo-staging"), "").unwrap();
    let cleared = relevo(args);
    let stderr = String::from_utf8_lossy(&cleared.stderr);
    assert!(cleared.status.success(), "{stderr}");
    assert!(
        stderr.contains("lux.relevo.tmp: left by a run of Relevo that did not finish"),
        "{stderr}"
    );
    assert_eq!(listing(d.path()), ["lux.relevo"]);
    assert!(!out.join("junk").exists());

    // A run that fails in a late stage (imagery that is not a raster).
    std::fs::write(d.path().join("bad.tif"), "x").unwrap();
    let failed = relevo([
        "prep",
        "--dem",
        dem.to_str().unwrap(),
        "--image",
        d.path().join("bad.tif").to_str().unwrap(),
        "--out",
        d.path().join("other.relevo").to_str().unwrap(),
    ]);
    assert!(!failed.status.success());
    assert!(String::from_utf8_lossy(&failed.stderr).contains("stage drape"));
    assert_eq!(listing(d.path()), ["bad.tif", "lux.relevo"]);
}

#[test]
fn a_killed_prep_never_leaves_a_partial_bundle() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("srtm.relevo");
    let srtm = shared("dem/srtm_ref.tif");
    for delay_ms in [20, 150, 400] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_relevo"))
            .args([
                "prep",
                "--dem",
                srtm.to_str().unwrap(),
                "--force",
                "--out",
                out.to_str().unwrap(),
            ])
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        let _ = child.kill();
        let _ = child.wait();
        // Either there is no bundle, or it is complete and valid.
        if out.exists() {
            relevo_ok(["validate", out.to_str().unwrap()]);
        }
    }
}

#[test]
fn single_band_imagery_drapes_as_grey() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("mn.relevo");
    // A 1 m LiDAR DEM draped with itself: one band.
    let dem = shared("dem/lidar_minnesota_1m.tif");
    relevo_ok([
        "prep",
        "--dem",
        dem.to_str().unwrap(),
        "--image",
        dem.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let m = manifest(&out);
    assert_eq!(m["color"]["bands"], serde_json::json!([1, 1, 1]));
    let rgba = std::fs::read(out.join("color.rgba8")).unwrap();
    assert!(rgba.chunks(4).all(|p| p[0] == p[1] && p[1] == p[2]));
    assert!(
        rgba.chunks(4).any(|p| p[0] > 200) && rgba.chunks(4).any(|p| p[0] < 50),
        "stretched to the full range"
    );
}
