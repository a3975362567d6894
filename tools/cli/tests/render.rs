//! `relevo render` on real bundles: depth against the exact surface,
//! snapshots with tolerance, bad arguments.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::*;
use relevo_core::bundle::Bundle;
use relevo_core::horizon::{distance_of_depth, pick, Terrain};
use relevo_core::scene::{camera, View};
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

/// A view from the south-west quarter of the data, looking north-east.
fn view_of(b: &Bundle, size: [u32; 2]) -> View {
    let [x0, y0, x1, y1] = b.manifest.grid.valid_extent;
    let top = b.manifest.grid.height_range_m[1] as f64;
    View {
        eye: [x0 + 0.15 * (x1 - x0), y0 + 0.1 * (y1 - y0), top + 150.0],
        heading_deg: 35.0,
        incl_px: Some(size[1] as f64 * 0.75),
        fov_x_deg: 60.0,
        size,
        far_cells: 1024.0,
    }
}

fn camera_arg(v: &View) -> String {
    format!(
        "{},{},{},{},{}",
        v.eye[0],
        v.eye[1],
        v.eye[2],
        v.heading_deg,
        v.incl_px.unwrap()
    )
}

fn decode_png(path: &Path) -> Vec<u8> {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    buf
}

#[test]
fn depth_of_real_terrain_matches_the_exact_surface() {
    let d = tempfile::tempdir().unwrap();
    let path = bundle_of("dem/srtm_ref.tif", d.path());
    let b = Bundle::open(&path).unwrap();
    let view = view_of(&b, [240, 135]);
    let (png, depth) = (d.path().join("s.png"), d.path().join("s.f32"));
    relevo_ok([
        "render".as_ref(),
        path.as_os_str(),
        "--camera".as_ref(),
        camera_arg(&view).as_ref(),
        "--size".as_ref(),
        "240x135".as_ref(),
        "--bands".as_ref(),
        "inf:8:sub".as_ref(),
        "--depth".as_ref(),
        depth.as_os_str(),
        "--out".as_ref(),
        png.as_os_str(),
    ]);
    let depth: Vec<f32> = std::fs::read(&depth)
        .unwrap()
        .chunks(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let heights = b.heights().unwrap();
    let mask = b.mask().unwrap();
    let g = &b.manifest.grid;
    let frame = b.frame();
    let color = b.drape().unwrap().and_then(|d| d.color_source(&frame));
    let terrain = Terrain::new(g.side, g.cell_size_m, &heights, &mask, color);
    let cam = camera(&frame, &view).unwrap();
    let spacing = g.cell_size_m / 8.0;
    let (mut errors, mut disagree) = (Vec::new(), 0);
    for py in 0..135 {
        for px in 0..240 {
            let dv = depth[py * 240 + px];
            match (dv < 1.0, pick(&terrain, &cam, px as f64, py as f64)) {
                (true, Some(s)) => {
                    errors.push((distance_of_depth(&cam, dv as f64) - s).abs() / spacing);
                }
                (false, None) => {}
                _ => disagree += 1,
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    let (median, p95) = (errors[errors.len() / 2], errors[errors.len() * 95 / 100]);
    eprintln!("srtm_ref: depth vs exact surface median {median:.3}, p95 {p95:.3} slice spacings; {disagree} of {} pixels disagree on terrain/sky", 240 * 135);
    assert!(errors.len() > 20_000, "{} terrain pixels", errors.len());
    assert!(median <= 1.0 && p95 <= 2.0, "median {median}, p95 {p95}");
    assert!(disagree * 100 < 240 * 135, "{disagree} pixels disagree");
}

#[test]
fn renders_of_real_bundles_are_stable() {
    let d = tempfile::tempdir().unwrap();
    for (name, dem, extra) in [
        ("olinda", "data/olinda/REGION.toml", vec![]),
        (
            "olinda_bands",
            "data/olinda/REGION.toml",
            vec![
                "--bands",
                "3000:4:sub,inf:1",
                "--prefilter",
                "--hillshade",
                "315,40",
            ],
        ),
        (
            "srtm_ref",
            "dem/srtm_ref.tif",
            vec!["--hillshade", "315,40"],
        ),
    ] {
        let dir = d.path().join(name);
        std::fs::create_dir_all(&dir).unwrap();
        let path = bundle_of(dem, &dir);
        let b = Bundle::open(&path).unwrap();
        let view = view_of(&b, [320, 180]);
        let png = dir.join("shot.png");
        let mut args = vec![
            "render".to_string(),
            path.display().to_string(),
            "--camera".into(),
            camera_arg(&view),
            "--size".into(),
            "320x180".into(),
            "--out".into(),
            png.display().to_string(),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        relevo_ok(args);
        let golden = repo(&format!("data/golden/renders/{name}.png"));
        if std::env::var_os("RELEVO_BLESS").is_some() {
            std::fs::create_dir_all(golden.parent().unwrap()).unwrap();
            std::fs::copy(&png, &golden).unwrap();
        }
        let (now, want) = (decode_png(&png), decode_png(&golden));
        assert_eq!(now.len(), want.len(), "{name}: size changed");
        let off = now
            .chunks(4)
            .zip(want.chunks(4))
            .filter(|(a, b)| a.iter().zip(b.iter()).any(|(x, y)| x.abs_diff(*y) > 16))
            .count();
        let mean = now
            .iter()
            .zip(&want)
            .map(|(a, b)| a.abs_diff(*b) as f64)
            .sum::<f64>()
            / now.len() as f64;
        // Tolerance: at most 0.5 % of pixels off by more than 16 levels, mean difference under 1 level.
        assert!(
            off * 200 <= now.len() / 4 && mean < 1.0,
            "{name}: {off} pixels differ, mean {mean:.2}; rerun with RELEVO_BLESS=1 if intended"
        );
        // Terrain and sky are both in view.
        let sky = now.chunks(4).filter(|p| p == &[135, 170, 215, 255]).count();
        assert!(sky > 0 && sky < now.len() / 4, "{name}: {sky} sky pixels");
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
