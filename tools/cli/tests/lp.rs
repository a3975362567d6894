//! Lindstrom–Pascucci hierarchy on real terrain: conformance with
//! @mapbox/martini and the nesting invariants.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::*;
use relevo_core::bundle::{sha256_bytes, Bundle};
use relevo_core::lp::extract::extract;
use relevo_core::lp::{ErrorMetric, Hierarchy};

#[test]
fn errors_and_meshes_match_martini() {
    let reference = martini_reference();
    let d = tempfile::tempdir().unwrap();
    for (name, file, encoding) in MARTINI_TILES {
        let bundle = Bundle::open(&prep_martini_tile(d.path(), file, encoding)).unwrap();
        let r = &reference[name];
        let heights = bundle.heights().unwrap();
        let side = bundle.manifest.grid.side;
        let h = Hierarchy::compute(&heights, side, 1.0, ErrorMetric::Midpoint);
        let errors: Vec<f32> = h.error_radius.iter().map(|e| e[0]).collect();
        assert_eq!(
            sha256_bytes(bytemuck::cast_slice(&errors)),
            r["errors"]["sha256"],
            "{name}: errors"
        );
        // The bundle stores the same errors beside the radii.
        let lp = bundle.lp().unwrap();
        let stored = lp.hierarchy();
        assert!(stored
            .error_radius
            .iter()
            .zip(&errors)
            .all(|(p, e)| p[0] == *e));

        for (max_error, mesh) in r["meshes"].as_object().unwrap() {
            let m = extract(&h, max_error.parse().unwrap(), None);
            let vertices: Vec<u16> = m.vertices.iter().flatten().copied().collect();
            let triangles: Vec<u32> = m.triangles.iter().flatten().copied().collect();
            assert_eq!(
                vertices.len() as u64,
                mesh["vertices"]["length"],
                "{name} @ {max_error}: vertex count"
            );
            assert_eq!(
                triangles.len() as u64,
                mesh["triangles"]["length"],
                "{name} @ {max_error}: triangle count"
            );
            assert_eq!(
                sha256_bytes(bytemuck::cast_slice(&vertices)),
                mesh["vertices"]["sha256"],
                "{name} @ {max_error}"
            );
            assert_eq!(
                sha256_bytes(bytemuck::cast_slice(&triangles)),
                mesh["triangles"]["sha256"],
                "{name} @ {max_error}"
            );
        }
    }
}

#[test]
fn hierarchy_is_nested_on_real_dems() {
    let d = tempfile::tempdir().unwrap();
    for dem in [
        "dem/srtm_ref.tif",
        "dem/Copernicus_DSM_10_N45_00_E005_00_DEM.tif",
        "dem/Gironde.tif",
    ] {
        let out = d.path().join("dem.relevo");
        let path = shared(dem);
        relevo_ok([
            "prep".as_ref(),
            "--dem".as_ref(),
            path.as_os_str(),
            "--force".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
        ]);
        let bundle = Bundle::open(&out).unwrap();
        let heights = bundle.heights().unwrap();
        let lp = bundle.lp().unwrap();
        let h = lp.hierarchy().into_owned();
        assert_eq!(
            h.nesting_violations(&heights, 10),
            Vec::<String>::new(),
            "{dem}"
        );
        assert!(
            h.error_radius.iter().any(|e| e[0] > 1.0),
            "{dem}: no relief?"
        );
        // validate runs the same check on the stored file.
        relevo_ok(["validate".as_ref(), out.as_os_str()]);
    }
}

#[test]
fn hierarchy_command_matches_the_bundle_and_refuses_non_square_input() {
    let d = tempfile::tempdir().unwrap();
    let dem = shared("dem/luxembourg_elev.tif");
    let padded = d.path().join("lux_129.tif");
    relevo_ok([
        "pad".as_ref(),
        dem.as_os_str(),
        "--out".as_ref(),
        padded.as_os_str(),
    ]);
    let lp = d.path().join("lp.tif");
    relevo_ok([
        "hierarchy".as_ref(),
        padded.as_os_str(),
        "--cell-size".as_ref(),
        "30".as_ref(),
        "--out".as_ref(),
        lp.as_os_str(),
    ]);
    let r = read(&lp);
    assert_eq!((r.width, r.height, r.bands.len()), (129, 129, 2));
    let heights: Vec<f32> = read(&padded).bands[0].iter().map(|&v| v as f32).collect();
    let h = Hierarchy::compute(&heights, 129, 30.0, ErrorMetric::default());
    for (i, e) in h.error_radius.iter().enumerate() {
        assert_eq!((r.bands[0][i] as f32, r.bands[1][i] as f32), (e[0], e[1]));
    }
    let out = relevo([
        "hierarchy".as_ref(),
        dem.as_os_str(),
        "--out".as_ref(),
        d.path().join("x.tif").as_os_str(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("(2^n+1)²"));
}
