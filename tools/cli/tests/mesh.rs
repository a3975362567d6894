//! `relevo mesh`: valid glTF and OBJ, the mask honoured, martini's counts.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::*;
use relevo_core::bundle::Bundle;
use relevo_core::lp::extract::extract;
use serde_json::Value;
use std::path::Path;

/// The JSON chunk of a .glb.
fn glb_json(path: &Path) -> Value {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[0..4], b"glTF");
    let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    assert_eq!(&bytes[16..20], b"JSON");
    serde_json::from_slice(&bytes[20..20 + len]).unwrap()
}

#[test]
fn sample_region_exports_valid_textured_gltf() {
    let d = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(d.path());
    for max_error in ["0", "2", "10"] {
        let glb = d.path().join(format!("olinda_{max_error}.glb"));
        relevo_ok([
            "mesh".as_ref(),
            bundle.as_os_str(),
            "--max-error".as_ref(),
            max_error.as_ref(),
            "--out".as_ref(),
            glb.as_os_str(),
        ]);
        let report = khronos_validate(&glb);
        assert_eq!(report["numErrors"], 0);
        assert_eq!(report["numWarnings"], 0, "{report}");
        let doc = glb_json(&glb);
        let attributes = &doc["meshes"][0]["primitives"][0]["attributes"];
        assert!(attributes.get("NORMAL").is_some() && attributes.get("TEXCOORD_0").is_some());
        assert_eq!(doc["images"][0]["mimeType"], "image/png");
    }
}

#[test]
fn the_mask_is_honoured_and_the_data_is_covered() {
    let d = tempfile::tempdir().unwrap();
    let b = Bundle::open(&sample_bundle(d.path())).unwrap();
    let side = b.manifest.grid.side;
    let mask = b.mask().unwrap();
    let lp = b.lp().unwrap();
    let h = lp.hierarchy().into_owned();
    for max_error in [0.0, 1.0, 5.0, 1000.0] {
        let m = extract(&h, max_error, Some(&mask));
        let mut area2 = 0i64;
        for t in &m.triangles {
            let p = t
                .map(|i| m.vertices[i as usize])
                .map(|v| (v[0] as i64, v[1] as i64));
            for (c, r) in p {
                assert_eq!(
                    mask[r as usize * side + c as usize],
                    1,
                    "triangle over padding at {max_error} m"
                );
            }
            area2 += ((p[1].0 - p[0].0) * (p[2].1 - p[0].1)
                - (p[1].1 - p[0].1) * (p[2].0 - p[0].0))
                .abs();
        }
        // The 111×111 DEM spans 110×110 cells of vertices: all of it is meshed.
        assert_eq!(area2, 2 * 110 * 110, "data not covered at {max_error} m");
    }
}

#[test]
fn keep_padding_reproduces_martini_counts_through_the_cli() {
    let reference = martini_reference();
    let d = tempfile::tempdir().unwrap();
    let bundle = prep_martini_tile(d.path(), "fuji.png", "terrain-rgb");
    for max_error in ["5", "50"] {
        let glb = d.path().join(format!("fuji{max_error}.glb"));
        relevo_ok([
            "mesh".as_ref(),
            bundle.as_os_str(),
            "--max-error".as_ref(),
            max_error.as_ref(),
            "--keep-padding".as_ref(),
            "--out".as_ref(),
            glb.as_os_str(),
        ]);
        khronos_validate(&glb);
        let doc = glb_json(&glb);
        let expected = &reference["fuji"]["meshes"][max_error];
        assert_eq!(
            doc["accessors"][0]["count"].as_u64().unwrap() * 2,
            expected["vertices"]["length"].as_u64().unwrap()
        );
        let indices = doc["meshes"][0]["primitives"][0]["indices"]
            .as_u64()
            .unwrap() as usize;
        assert_eq!(
            doc["accessors"][indices]["count"],
            expected["triangles"]["length"]
        );
    }
}

#[test]
fn obj_export_writes_mesh_material_and_texture() {
    let d = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(d.path());
    let obj = d.path().join("olinda.obj");
    relevo_ok([
        "mesh".as_ref(),
        bundle.as_os_str(),
        "--max-error".as_ref(),
        "3".as_ref(),
        "--out".as_ref(),
        obj.as_os_str(),
    ]);
    let text = std::fs::read_to_string(&obj).unwrap();
    let count = |prefix: &str| text.lines().filter(|l| l.starts_with(prefix)).count();
    assert!(count("v ") > 100);
    assert_eq!(count("v "), count("vn "));
    assert_eq!(count("v "), count("vt "));
    assert!(count("f ") > 100);
    assert!(text.contains("mtllib olinda.mtl"));
    assert!(std::fs::read_to_string(d.path().join("olinda.mtl"))
        .unwrap()
        .contains("map_Kd olinda.png"));
    assert_eq!(
        &std::fs::read(d.path().join("olinda.png")).unwrap()[1..4],
        b"PNG"
    );
}

#[test]
fn bad_mesh_requests_fail_cleanly() {
    let d = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(d.path());
    for (args, needle) in [
        (vec!["--max-error", "-1", "--out", "x.glb"], "--max-error"),
        (vec!["--max-error", "1", "--out", "x.stl"], "--format"),
    ] {
        let out = relevo(["mesh", bundle.to_str().unwrap()].into_iter().chain(args));
        assert!(!out.status.success());
        assert!(String::from_utf8_lossy(&out.stderr).contains(needle));
    }
    let out = relevo([
        "mesh",
        d.path().join("nope.relevo").to_str().unwrap(),
        "--max-error",
        "1",
        "--out",
        d.path().join("x.glb").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("nope.relevo"));
    assert!(!d.path().join("x.glb").exists());
}

/// `--max-error` is a bound: on srtm_ref (a real DEM, not used to tune
/// anything) every grid point under the mesh is within the tolerance, as
/// `mesh` reports it; with martini's midpoint metric the same tolerance
/// leaves points farther away, and `mesh` says it is no bound.
#[test]
fn max_error_bounds_the_distance_of_every_grid_point() {
    let d = tempfile::tempdir().unwrap();
    let dem = shared("dem/srtm_ref.tif");
    let farthest = |metric: &str, max_error: f64| {
        let bundle = d.path().join(format!("srtm_{metric}.relevo"));
        if !bundle.exists() {
            relevo_ok([
                "prep".as_ref(),
                "--dem".as_ref(),
                dem.as_os_str(),
                "--error-metric".as_ref(),
                metric.as_ref(),
                "--out".as_ref(),
                bundle.as_os_str(),
            ]);
        }
        let glb = d.path().join(format!("srtm_{metric}_{max_error}.glb"));
        let out = relevo([
            "mesh".as_ref(),
            bundle.as_os_str(),
            "--max-error".as_ref(),
            max_error.to_string().as_ref(),
            "--out".as_ref(),
            glb.as_os_str(),
        ]);
        assert!(out.status.success());
        let stderr = String::from_utf8_lossy(&out.stderr).to_string();
        let reported = stderr
            .split("no grid point is more than ")
            .nth(1)
            .and_then(|rest| rest.split(' ').next())
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or_else(|| panic!("no distance reported: {stderr}"));
        (reported, stderr)
    };
    let mut midpoint_worst = 0.0f64;
    for max_error in [2.0, 5.0, 20.0] {
        let (bound, stderr) = farthest("bound", max_error);
        assert!(bound <= max_error, "{bound} m at --max-error {max_error}");
        assert!(!stderr.contains("not a bound"), "{stderr}");
        let (midpoint, stderr) = farthest("midpoint", max_error);
        assert!(stderr.contains("not a bound"), "{stderr}");
        midpoint_worst = midpoint_worst.max(midpoint / max_error);
    }
    assert!(
        midpoint_worst > 1.2,
        "midpoint meshes stay within {midpoint_worst}×"
    );
}
