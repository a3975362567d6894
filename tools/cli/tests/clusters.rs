//! `relevo prep` bakes vegetation clusters and `relevo bake` re-bakes them:
//! deterministic across runs and thread counts, and refused cleanly —
//! bundle untouched — on bad models and budgets.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{file_hashes, relevo, relevo_ok, repo, sample_bundle};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

fn cluster_files(bundle: &Path) -> BTreeMap<String, String> {
    file_hashes(bundle)
        .into_iter()
        .filter(|(name, _)| name.starts_with("clusters/"))
        .collect()
}

#[test]
fn bake_repeats_prep_byte_for_byte_on_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let info = relevo_ok(["info".as_ref(), bundle.as_os_str()]);
    assert!(info.contains("clusters     11764 objects"), "{info}");
    assert!(
        info.contains("class forest") && info.contains("procedural:stand"),
        "{info}"
    );
    let baked = cluster_files(&bundle);
    assert!(baked.len() >= 5, "{:?}", baked.keys());
    for threads in ["1", "3"] {
        let out = Command::new(env!("CARGO_BIN_EXE_relevo"))
            .args(["bake".as_ref(), bundle.as_os_str()])
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            cluster_files(&bundle) == baked,
            "bake on {threads} thread(s) differs from prep"
        );
    }
    relevo_ok(["validate".as_ref(), bundle.as_os_str()]);

    // Another model and a smaller budget: different atlases, still valid,
    // the rest of the bundle as it was.
    let before = file_hashes(&bundle);
    let report = relevo_ok([
        "bake".as_ref(),
        bundle.as_os_str(),
        "--model".as_ref(),
        "forest=conifer".as_ref(),
        "--budget-mib".as_ref(),
        "32".as_ref(),
        "--json".as_ref(),
    ]);
    let report: serde_json::Value = serde_json::from_str(&report).unwrap();
    assert!(report["atlas_bytes"].as_u64().unwrap() <= 32 << 20);
    let after = file_hashes(&bundle);
    for (name, bytes) in &before {
        if !name.starts_with("clusters/") && name != "manifest.json" {
            assert!(after.get(name) == Some(bytes), "{name} changed");
        }
    }
    assert!(cluster_files(&bundle) != baked);
    let info = relevo_ok(["info".as_ref(), bundle.as_os_str()]);
    assert!(
        info.contains("procedural:conifer") && info.contains("left out"),
        "{info}"
    );
    relevo_ok(["validate".as_ref(), bundle.as_os_str()]);
}

#[test]
fn bad_models_and_budgets_are_refused_leaving_the_bundle_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let before = file_hashes(&bundle);
    let write = |name: &str, bytes: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p.display().to_string()
    };
    let not_obj = write("photo.obj", &[0x89, b'P', b'N', b'G', 0, 0, 0xff, 0xfe]);
    let no_faces = write("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n");
    write("bark.mtl", b"newmtl bark\nmap_Kd bark.png\n");
    let no_texture = write(
        "tree.obj",
        b"mtllib bark.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl bark\nf 1 2 3\n",
    );
    let missing = dir.path().join("nowhere.obj").display().to_string();
    let cases: [(Vec<String>, &[&str]); 5] = [
        (
            vec!["--model".into(), format!("forest={missing}")],
            &["nowhere.obj", "no such model file"],
        ),
        (
            vec!["--model".into(), format!("forest={not_obj}")],
            &["photo.obj"],
        ),
        (
            vec!["--model".into(), format!("forest={no_faces}")],
            &["points.obj", "no faces"],
        ),
        (
            vec!["--model".into(), format!("forest={no_texture}")],
            &["tree.obj", "bark.png"],
        ),
        (
            vec!["--budget-mib".into(), "0.1".into()],
            &["budget", "class impostors need"],
        ),
    ];
    for (flags, words) in cases {
        let mut args = vec!["bake".to_string(), bundle.display().to_string()];
        args.extend(flags.iter().cloned());
        let out = relevo(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{flags:?} succeeded");
        for w in words {
            assert!(stderr.contains(w), "{flags:?}: {w:?} not in {stderr}");
        }
        assert!(
            file_hashes(&bundle) == before,
            "{flags:?} changed the bundle"
        );
        assert!(
            !dir.path().join("olinda.relevo.tmp").exists(),
            "{flags:?} left a staging folder"
        );
    }
    let out = relevo(["bake", "--bands", "300:1,200:4", bundle.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("distances must increase"));

    // A bundle without vegetation has nothing to bake.
    let bare = dir.path().join("bare.relevo");
    relevo_ok([
        "prep".as_ref(),
        "--dem".as_ref(),
        repo("data/olinda/olinda_dem_utm25s.tif").as_os_str(),
        "--out".as_ref(),
        bare.as_os_str(),
    ]);
    let out = relevo(["bake".as_ref(), bare.as_os_str()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no vegetation database"));
}
