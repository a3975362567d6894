//! `relevo-view bench` on lavapipe over the real Grenoble crop: one record
//! a mode with consistent figures, the same flight (cameras) in every mode
//! and every run, and bad requests refused by name; every subcommand's
//! help shows examples.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};

fn bench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_relevo-view"))
        .arg("bench")
        .args(args)
        .env("VK_ICD_FILENAMES", relevo_view::LAVAPIPE_ICD)
        .output()
        .unwrap()
}

/// The records of a `--json` run with `in_flight` frames in flight.
fn records(bundle: &Path, in_flight: &str) -> Vec<Value> {
    let out = bench(&[
        bundle.to_str().unwrap(),
        "--frames",
        "4",
        "--size",
        "320x180",
        "--json",
        "--in-flight",
        in_flight,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn a_scripted_flight_gives_one_consistent_record_a_mode() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = common::grenoble_bundle(dir.path());
    let first = records(&bundle, "1");
    assert_eq!(first[0]["bench"], "view-adapter");
    let adapter = first[0]["adapter"].as_str().unwrap();
    assert!(!adapter.is_empty());
    let flights = &first[1..];
    let configs: Vec<&str> = flights
        .iter()
        .map(|r| r["config"].as_str().unwrap())
        .collect();
    assert_eq!(configs, ["mesh tau 1", "mesh tau 2", "raycast"]);
    for r in flights {
        let f = |k: &str| r[k].as_f64().unwrap();
        assert_eq!(r["frames"], 16, "{r}");
        assert_eq!(r["in_flight"], 1, "{r}");
        assert_eq!(r["adapter"], adapter);
        assert!(
            0.0 < f("frame_ms_p50")
                && f("frame_ms_p50") <= f("frame_ms_p95")
                && f("frame_ms_p95") <= f("frame_ms_p99")
                && f("frame_ms_p99") <= f("frame_ms_max"),
            "{r}"
        );
        assert!((f("fps_p50") - 1e3 / f("frame_ms_p50")).abs() < 1e-6);
        assert!(f("triangles_p50") <= f("triangles_max"), "{r}");
        assert_eq!(r["paging_stalls"], 0);
        // One flight for every mode: the same first and last cameras.
        assert_eq!(r["start_camera"], flights[0]["start_camera"]);
        assert_eq!(r["end_camera"], flights[0]["end_camera"]);
        assert_ne!(r["start_camera"], r["end_camera"]);
    }
    // The mesh at τ = 1 px draws more than at 2 px; the raycast's work is
    // the CPU march, the mesh's the refinement.
    let tri = |i: usize| flights[i]["triangles_p50"].as_f64().unwrap();
    assert!(tri(0) > tri(1) && tri(1) > 0.0, "{} vs {}", tri(0), tri(1));
    assert!(flights[2]["raycast_ms_p50"].as_f64().unwrap() > 0.0);
    assert!(flights[0]["refine_ms_p50"].as_f64().unwrap() > 0.0);
    // Another run flies the same path.
    let again = records(&bundle, "1");
    assert_eq!(again[1]["start_camera"], first[1]["start_camera"]);
    assert_eq!(again[1]["end_camera"], first[1]["end_camera"]);
    // Two frames in flight (the next refined while the GPU draws): the
    // same frames, one time each.
    let pipelined = records(&bundle, "2");
    for (p, r) in pipelined[1..].iter().zip(flights) {
        assert_eq!(p["in_flight"], 2, "{p}");
        for key in ["frames", "config", "start_camera", "end_camera"] {
            assert_eq!(p[key], r[key], "{key}: {p} vs {r}");
        }
        assert_eq!(p["triangles_max"], r["triangles_max"], "{p} vs {r}");
    }
}

/// `--fractal`: the fractal written as a pyramid in a scratch folder (no
/// bundle, no GDAL), flown in every mode with its tiles paged, and the
/// folder removed afterwards.
#[test]
fn a_fractal_pyramid_is_made_flown_and_removed() {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_relevo-view"))
        .args([
            "bench",
            "--fractal",
            "257",
            "--frames",
            "3",
            "--size",
            "160x90",
        ])
        .arg("--json")
        .env("VK_ICD_FILENAMES", relevo_view::LAVAPIPE_ICD)
        .env("TMPDIR", tmp.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("fractal 257²: pyramid written"), "{stderr}");
    let flights: Vec<Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap())
        .filter(|r| r["bench"] == "view-flight")
        .collect();
    assert_eq!(flights.len(), 3);
    for r in &flights {
        assert_eq!(r["bundle"], "fractal 257²", "{r}");
        assert_eq!(r["frames"], 12, "{r}");
    }
    assert!(
        flights[0]["tiles_loaded"].as_u64().unwrap() > 0,
        "{}",
        flights[0]
    );
    assert!(flights[0]["triangles_p50"].as_u64().unwrap() > 0);
    let left: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn bad_requests_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.relevo");
    let bundle = common::grenoble_bundle(dir.path());
    for (args, needle) in [
        (vec![missing.to_str().unwrap()], "missing.relevo"),
        (
            vec![bundle.to_str().unwrap(), "--frames", "0"],
            "--frames must be at least 1",
        ),
        (vec![bundle.to_str().unwrap(), "--size", "0x10"], "size"),
        (
            vec![bundle.to_str().unwrap(), "--in-flight", "3"],
            "--in-flight",
        ),
        (vec!["--fractal", "100"], "2^n + 1"),
        (vec![], "BUNDLE"),
    ] {
        let out = bench(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(needle),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn every_subcommand_shows_examples_in_its_help() {
    for args in [
        vec!["--help"],
        vec!["render", "--help"],
        vec!["bench", "--help"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_relevo-view"))
            .args(&args)
            .output()
            .unwrap();
        let help = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && help.contains("Examples:\n  relevo-view"),
            "{args:?}: {help}"
        );
    }
}
