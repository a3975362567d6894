//! `relevo render` as a process: it writes what the library renders, and
//! refuses bad arguments. Depth and snapshot tests: `tests/tests/render.rs`.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::*;
use relevo_core::bundle::Bundle;
use relevo_core::horizon::RenderOptions;
use relevo_core::scene::{self, View};
use std::path::{Path, PathBuf};

fn bundle_of(dem: &str, dir: &Path) -> PathBuf {
    let out = dir.join("b.relevo");
    let path = if dem.ends_with(".toml") {
        repo(dem)
    } else {
        shared(dem)
    };
    let mut args = vec!["prep".to_string()];
    if !dem.ends_with(".toml") {
        args.push("--dem".into());
    }
    args.extend([
        path.display().to_string(),
        "--out".into(),
        out.display().to_string(),
    ]);
    relevo_ok(args);
    out
}

fn decode_png(path: &Path) -> Vec<u8> {
    relevo_core::raster::png::decode_rgba(&std::fs::read(path).unwrap())
        .unwrap()
        .0
}

/// The command writes the PNG and depth the library renders for the same
/// camera, level and pitched (the snapshots of those renders are in
/// `tests/tests/render.rs`).
#[test]
fn render_command_writes_what_the_library_renders() {
    let d = tempfile::tempdir().unwrap();
    let path = bundle_of("data/olinda/REGION.toml", d.path());
    let b = Bundle::open(&path).unwrap();
    let home = View::home(&b.manifest.grid, [320, 180]);
    let pitched = View {
        pitch_deg: -30.0,
        incl_px: None,
        ..home
    };
    for view in [home, pitched] {
        let (png, depth) = (d.path().join("s.png"), d.path().join("s.f32"));
        relevo_ok([
            "render".as_ref(),
            path.as_os_str(),
            "--camera".as_ref(),
            view.pose().to_string().as_ref(),
            "--size".as_ref(),
            "320x180".as_ref(),
            "--bands".as_ref(),
            "3000:4:sub,inf:1".as_ref(),
            "--depth".as_ref(),
            depth.as_os_str(),
            "--out".as_ref(),
            png.as_os_str(),
            "--force".as_ref(),
        ]);
        let bands = scene::parse_bands("3000:4:sub,inf:1").unwrap();
        let options = RenderOptions {
            bands,
            ..RenderOptions::default()
        };
        let frame = scene::render_bundle(&b, &view, &options, None)
            .unwrap()
            .to_rows();
        assert_eq!(decode_png(&png), frame.rgba_bytes());
        let written: Vec<f32> = std::fs::read(&depth)
            .unwrap()
            .chunks(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        assert_eq!(written, frame.depth);
    }
}

#[test]
fn bad_render_arguments_fail_cleanly() {
    let d = tempfile::tempdir().unwrap();
    let path = bundle_of("data/olinda/REGION.toml", d.path());
    let out = d.path().join("x.png");
    for (args, needle) in [
        (vec!["--camera", "1,2"], "--camera"),
        (
            vec!["--camera", "290000,9112000,400,45", "--size", "0x10"],
            "WIDTHxHEIGHT",
        ),
        (
            vec!["--camera", "290000,9112000,400,45", "--fov", "200"],
            "--fov",
        ),
        (
            vec!["--camera", "290000,9112000,400,45", "--bands", "10:0"],
            "slices per cell",
        ),
        (
            vec!["--camera", "290000,9112000,400,45,-75deg"],
            "outside the raycast's range",
        ),
        (
            vec![
                "--camera",
                "290000,9112000,400,45,-20deg",
                "--mode",
                "distorted",
            ],
            "level cameras",
        ),
        (
            vec!["--camera", "290000,9112000,400,45,-20dg"],
            "not a number",
        ),
    ] {
        let res = relevo(
            [
                "render",
                path.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ]
            .into_iter()
            .chain(args),
        );
        assert!(!res.status.success());
        assert!(
            String::from_utf8_lossy(&res.stderr).contains(needle),
            "{}",
            String::from_utf8_lossy(&res.stderr)
        );
        assert!(!out.exists());
    }
}
