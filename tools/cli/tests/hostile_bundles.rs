//! Bundles edited by someone who also fixed up the manifest's hashes: every
//! reader must refuse them by name — never loop, overflow its stack, panic,
//! hang or allocate what a header merely declares.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{forged, rehash, relevo, relevo_ok, sample_bundle};
use std::path::{Path, PathBuf};

/// Size of one `clusters/nodes.bin` record and where its children sit.
const NODE_BYTES: usize = 68;
const CHILDREN_AT: usize = 48;

/// Edit `clusters/index.json` as JSON.
fn index_edit(edit: impl Fn(&mut serde_json::Value)) -> impl Fn(&mut Vec<u8>) {
    move |bytes| {
        let mut index: serde_json::Value = serde_json::from_slice(bytes).unwrap();
        edit(&mut index);
        *bytes = serde_json::to_vec(&index).unwrap();
    }
}

/// The first child slot of node `node` that holds a child.
fn set_first_child(bytes: &mut [u8], node: usize, to: u32) {
    let at = node * NODE_BYTES + CHILDREN_AT;
    let slot = (0..4)
        .map(|k| at + 4 * k)
        .find(|&o| bytes[o..o + 4] != [0xff; 4])
        .unwrap();
    bytes[slot..slot + 4].copy_from_slice(&to.to_le_bytes());
}

/// A PNG that is only a header declaring `width`×`height` and the start of
/// its data: a few hundred bytes that would decode to gigabytes.
fn png_header(width: u32, height: u32) -> Vec<u8> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(png::ColorType::Rgba);
    let mut writer = encoder.write_header().unwrap();
    writer
        .write_chunk(png::chunk::IDAT, &[0x78, 0x9c, 0, 0, 0, 0])
        .unwrap();
    drop(writer);
    out
}

/// Run `relevo ARGS…`, expecting a refusal (not a crash) that says every
/// needle.
fn refused(args: &[&str], needles: &[&str]) {
    let out = relevo(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.code().is_some_and(|c| c != 0),
        "{args:?}: {:?}\n{stderr}",
        out.status
    );
    assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    for n in needles {
        assert!(
            stderr.contains(n),
            "{args:?}: stderr lacks {n:?}:\n{stderr}"
        );
    }
}

#[test]
fn cluster_files_that_would_loop_crash_or_explode_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let nodes = "clusters/nodes.bin";
    let index = "clusters/index.json";
    let cases: Vec<(PathBuf, &str)> = vec![
        // A child pointing back at the root: a walk would never end.
        (
            forged(&bundle, "cycle.relevo", nodes, &|b| {
                set_first_child(b, 0, 0);
            }),
            "not a later node",
        ),
        (
            forged(&bundle, "range.relevo", nodes, &|b| {
                set_first_child(b, 0, 1 << 30);
            }),
            "not a later node",
        ),
        // One node claimed by two parents.
        (
            forged(&bundle, "shared.relevo", nodes, &|b| {
                let child = b[CHILDREN_AT..CHILDREN_AT + 16]
                    .chunks(4)
                    .find(|c| c != &[0xff; 4])
                    .unwrap()
                    .to_vec();
                b[CHILDREN_AT..CHILDREN_AT + 16].copy_from_slice(&child.repeat(4));
            }),
            "the child of two nodes",
        ),
        (
            forged(
                &bundle,
                "nopages.relevo",
                index,
                &index_edit(|i| {
                    i["pages"] = serde_json::json!([]);
                }),
            ),
            "outside its page",
        ),
        (
            forged(
                &bundle,
                "class.relevo",
                index,
                &index_edit(|i| {
                    i["classes"] = serde_json::json!([]);
                }),
            ),
            "class 0 of 0",
        ),
        (
            forged(
                &bundle,
                "bands.relevo",
                index,
                &index_edit(|i| {
                    i["options"]["cut"]["bands"] = serde_json::json!([]);
                }),
            ),
            "no distance bands",
        ),
        // A page header far larger than the index says.
        (
            forged(&bundle, "bomb.relevo", "clusters/atlas_000.png", &|b| {
                *b = png_header(40000, 40000);
            }),
            "40000×40000, the index says 2048×",
        ),
    ];
    for (forgery, needle) in &cases {
        let path = forgery.to_str().unwrap();
        refused(&["validate", path], &["clusters", needle]);
        // `bake` builds the clusters anew from the vegetation database and
        // reads only the models from the old index: it repairs the bundle,
        // or refuses by name what it cannot use.
        let bake = relevo(["bake", path]);
        let stderr = String::from_utf8_lossy(&bake.stderr);
        assert!(bake.status.code().is_some(), "{path}: {stderr}");
        if bake.status.success() {
            relevo_ok(["validate", path]);
        } else {
            assert!(
                stderr.contains(path) && !stderr.contains("panicked"),
                "{stderr}"
            );
        }
    }
    // The original still validates: the forgeries were copies.
    relevo_ok(["validate", bundle.to_str().unwrap()]);
}

#[test]
fn atlas_pages_are_decoded_only_within_the_budget_and_the_process_limits() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    // Index and header agree on a 16384² page: 2 GiB to decode.
    let big = forged(&bundle, "big.relevo", "clusters/atlas_000.png", &|b| {
        *b = png_header(16384, 16384);
    });
    let index = big.join("clusters/index.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&index).unwrap()).unwrap();
    json["pages"][0]["width"] = 16384.into();
    json["pages"][0]["height"] = 16384.into();
    std::fs::write(&index, serde_json::to_vec(&json).unwrap()).unwrap();
    rehash(&big, "clusters/index.json");
    let path = big.to_str().unwrap();
    refused(
        &["--max-memory", "1G", "validate", path],
        &[
            "decoding the cluster atlas pages",
            "memory budget is 1.0 GiB",
        ],
    );
    // No --max-memory, but a 1.5 GiB address-space limit: the budget
    // follows the limit instead of the machine's free memory.
    let out = std::process::Command::new("bash")
        .args(["-c", "ulimit -v 1572864 && exec \"$0\" validate \"$1\""])
        .arg(env!("CARGO_BIN_EXE_relevo"))
        .arg(path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("decoding the cluster atlas pages"),
        "{stderr}"
    );
}

/// Make a FIFO at `path`.
fn mkfifo(path: &Path) {
    let status = std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .unwrap();
    assert!(status.success());
}

/// Run `relevo ARGS…` under a 60 s timeout, expecting a refusal that says
/// every needle (a hang fails as exit 124).
fn refused_in_time(args: &[&str], needles: &[&str]) {
    let out = std::process::Command::new("timeout")
        .arg("60")
        .arg(env!("CARGO_BIN_EXE_relevo"))
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
    for n in needles {
        assert!(
            stderr.contains(n),
            "{args:?}: stderr lacks {n:?}:\n{stderr}"
        );
    }
}

#[test]
fn fifos_and_devices_are_refused_by_name_wherever_a_file_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let b = bundle.to_str().unwrap();
    // Heights that are a FIFO: no command may wait on it.
    let heights = bundle.join("height.f32");
    let kept = dir.path().join("height.f32.kept");
    std::fs::rename(&heights, &kept).unwrap();
    mkfifo(&heights);
    let png = dir.path().join("x.png");
    let glb = dir.path().join("x.glb");
    for args in [
        vec!["validate", b],
        vec![
            "render",
            b,
            "--camera",
            "290000,9112000,400,45,300",
            "--out",
            png.to_str().unwrap(),
        ],
        vec![
            "mesh",
            b,
            "--max-error",
            "5",
            "--out",
            glb.to_str().unwrap(),
        ],
    ] {
        refused_in_time(
            &args,
            &["height.f32", "is a FIFO (named pipe), not a regular file"],
        );
    }
    assert!(!png.exists() && !glb.exists());
    std::fs::remove_file(&heights).unwrap();
    std::fs::rename(&kept, &heights).unwrap();

    // A model that is a device, a material library that is a FIFO, and
    // samples that are a FIFO.
    let device = dir.path().join("zero.obj");
    std::os::unix::fs::symlink("/dev/zero", &device).unwrap();
    refused_in_time(
        &[
            "bake",
            b,
            "--model",
            &format!("forest={}", device.display()),
        ],
        &["zero.obj", "is a device"],
    );
    std::fs::write(
        dir.path().join("tree.obj"),
        "mtllib bark.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl bark\nf 1 2 3\n",
    )
    .unwrap();
    mkfifo(&dir.path().join("bark.mtl"));
    let tree = dir.path().join("tree.obj");
    refused_in_time(
        &["bake", b, "--model", &format!("forest={}", tree.display())],
        &["tree.obj", "bark.mtl", "FIFO"],
    );
    let samples = dir.path().join("marks.csv");
    mkfifo(&samples);
    let crop = common::shared("trees/SOAP_061.png");
    refused_in_time(
        &[
            "veg",
            "detect",
            crop.to_str().unwrap(),
            "--pixel-size",
            "0.1",
            "--samples",
            samples.to_str().unwrap(),
            "--out",
            dir.path().join("trees.csv").to_str().unwrap(),
        ],
        &["marks.csv", "FIFO"],
    );
    relevo_ok(["validate", b]);
}

/// A NaN height at a vertex with data (a bundle edited after prep, hashes
/// fixed up) is refused by every reader, naming the file and the vertex:
/// `mesh` used to exit 0 with a NaN position in the glTF, and `validate`
/// to accept it only when the range check happened to catch it.
#[test]
fn a_nan_height_at_a_data_vertex_is_refused_by_every_reader() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let mask = std::fs::read(bundle.join("mask.u8")).unwrap();
    let vertex = mask.iter().position(|&m| m == 1).unwrap();
    let broken = forged(&bundle, "nan.relevo", "height.f32", &|bytes| {
        bytes[vertex * 4..vertex * 4 + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    });
    let b = broken.to_str().unwrap();
    let glb = dir.path().join("m.glb");
    let png = dir.path().join("r.png");
    for args in [
        vec!["validate", b],
        vec![
            "mesh",
            b,
            "--max-error",
            "5",
            "--out",
            glb.to_str().unwrap(),
        ],
        vec![
            "render",
            b,
            "--camera",
            "290000,9112000,400,45,300",
            "--out",
            png.to_str().unwrap(),
        ],
    ] {
        refused(&args, &["height.f32", "is not a finite number"]);
    }
    assert!(!glb.exists() && !png.exists());
}
