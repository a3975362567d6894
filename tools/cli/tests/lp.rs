//! Lindstrom–Pascucci hierarchy on real terrain: conformance with
//! @mapbox/martini and the nesting invariants.

mod common;
use common::*;
use relevo_core::bundle::{sha256_bytes, Bundle};
use relevo_core::lp::extract::extract;
use relevo_core::lp::Hierarchy;
use serde_json::Value;

fn prep_tile(dir: &std::path::Path, file: &str, encoding: &str) -> Bundle {
    let out = dir.join(format!("{file}.relevo"));
    let png = shared(&format!("terrain_rgb_martini/{file}"));
    relevo_ok([
        "prep".as_ref(),
        "--dem".as_ref(),
        png.as_os_str(),
        "--encoding".as_ref(),
        encoding.as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    Bundle::open(&out).unwrap()
}

#[test]
fn errors_and_meshes_match_martini() {
    let reference: Value = serde_json::from_str(
        &std::fs::read_to_string(shared("terrain_rgb_martini/martini_js.json")).unwrap(),
    )
    .unwrap();
    let d = tempfile::tempdir().unwrap();
    for (name, file, encoding) in [
        ("fuji", "fuji.png", "terrain-rgb"),
        ("mapbox_st_helens", "mapbox_st_helens.png", "terrain-rgb"),
        ("terrarium", "terrarium.png", "terrarium"),
    ] {
        let bundle = prep_tile(d.path(), file, encoding);
        let r = &reference[name];
        let heights = bundle.array::<f32>("height").unwrap();
        let side = bundle.manifest.grid.side;
        let h = Hierarchy::compute(&heights, side, 1.0);
        let errors: Vec<f32> = h.error_radius.iter().map(|e| e[0]).collect();
        assert_eq!(
            sha256_bytes(bytemuck::cast_slice(&errors)),
            r["errors"]["sha256"],
            "{name}: errors"
        );
        // The bundle stores the same errors beside the radii.
        let lp = bundle.array::<f32>("lp").unwrap();
        assert!(lp.chunks(2).zip(&errors).all(|(p, e)| p[0] == *e));

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
        let heights = bundle.array::<f32>("height").unwrap();
        let lp = bundle.array::<f32>("lp").unwrap();
        let h = Hierarchy {
            side: bundle.manifest.grid.side,
            cell_size_m: bundle.manifest.grid.cell_size_m,
            error_radius: bytemuck::cast_slice(&lp).to_vec(),
        };
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
