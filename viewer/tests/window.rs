//! The viewer as a process on Mesa's lavapipe: a real window under Xvfb
//! flies a scripted tour over a real DEM and its screenshot shows terrain
//! and the HUD; bad bundles end with a message naming them and exit 1.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::{grenoble_bundle, grenoble_bundle_with_drape, grenoble_pyramid};
use std::path::Path;
use std::process::{Command, Output};

/// `relevo-view ARGS…` on lavapipe.
fn viewer(args: &[&std::ffi::OsStr], xvfb: bool, runtime: &Path) -> Output {
    let binary = env!("CARGO_BIN_EXE_relevo-view");
    let mut command = if xvfb {
        let mut c = Command::new("xvfb-run");
        c.args(["-a", "-s", "-screen 0 1280x800x24", binary]);
        c
    } else {
        Command::new(binary)
    };
    command
        .args(args)
        .env("VK_ICD_FILENAMES", relevo_view::LAVAPIPE_ICD)
        .env("XDG_RUNTIME_DIR", runtime)
        .output()
        .expect("relevo-view runs (xvfb-run is installed by scripts/setup)")
}

fn decode_png(path: &Path) -> (Vec<u8>, usize, usize) {
    relevo_core::raster::png::decode_rgba(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn a_real_window_flies_a_tour_and_shows_terrain_and_the_hud() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = grenoble_bundle(dir.path());
    fly_a_tour(&bundle, &[], &dir.path().join("window.png"));
}

/// Open `bundle` in a real window with `options`, fly a 45-frame tour and
/// check its screenshot at `shot` (terrain and the HUD) and a clean exit.
fn fly_a_tour(bundle: &Path, options: &[&str], shot: &Path) {
    use std::ffi::OsStr;
    let mut args: Vec<&OsStr> = vec![bundle.as_os_str()];
    args.extend(
        options
            .iter()
            .chain(&["--tour", "45", "--screenshot"])
            .map(OsStr::new),
    );
    args.push(shot.as_os_str());
    let out = viewer(&args, true, shot.parent().unwrap());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{options:?}: {stderr}");
    assert_terrain_and_hud(shot);
}

/// The window's screenshot at `shot`: in the view (left of the side
/// panel) terrain below, and the HUD — a dark translucent panel in the
/// top-left corner with text.
fn assert_terrain_and_hud(shot: &Path) {
    let (rgba, w, h) = decode_png(shot);
    assert!(w >= 640 && h >= 400, "{w}×{h}");
    let pixel = |x: usize, y: usize| &rgba[(y * w + x) * 4..(y * w + x) * 4 + 3];
    let sky = [135u8, 170, 215];
    let lower: Vec<&[u8]> = (h * 3 / 4..h - 10)
        .flat_map(|y| (w / 8..w / 2).map(move |x| (x, y)))
        .map(|(x, y)| pixel(x, y))
        .collect();
    let terrain = lower.iter().filter(|p| **p != sky).count();
    assert!(
        terrain * 10 > lower.len() * 9,
        "{terrain} of {} lower pixels are terrain",
        lower.len()
    );
    let hud: Vec<&[u8]> = (14..60)
        .flat_map(|y| (14..300).map(move |x| (x, y)))
        .map(|(x, y)| pixel(x, y))
        .collect();
    let dark = hud.iter().filter(|p| p.iter().all(|&c| c < 90)).count();
    let bright = hud.iter().filter(|p| p.iter().all(|&c| c > 200)).count();
    assert!(
        dark > hud.len() / 2 && bright > 50,
        "HUD: {dark} dark, {bright} bright pixels"
    );
}

/// A pyramid flown in a real window with a tile cache smaller than the
/// region (tiles dropped and read again), then in raycast mode (its level
/// windows read ahead beside the frames): each tour ends cleanly, the
/// screenshot shows terrain below the horizon and the HUD.
#[test]
fn a_real_window_flies_over_a_pyramid_paging_its_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let pyramid = grenoble_pyramid(dir.path());
    for mode in ["mesh", "raycast"] {
        fly_a_tour(
            &pyramid,
            &["--mode", mode, "--tile-cache", "300K"],
            &dir.path().join(format!("window_{mode}.png")),
        );
    }
}

#[test]
fn headless_renders_can_carry_the_hud() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = grenoble_bundle(dir.path());
    let shot = dir.path().join("hud.png");
    let out = viewer(
        &[
            "render".as_ref(),
            bundle.as_os_str(),
            "--mode".as_ref(),
            "raycast".as_ref(),
            "--hud".as_ref(),
            "--size".as_ref(),
            "640x360".as_ref(),
            "--out".as_ref(),
            shot.as_os_str(),
        ],
        false,
        dir.path(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (rgba, w, _) = decode_png(&shot);
    let pixel = |x: usize, y: usize| &rgba[(y * w + x) * 4..(y * w + x) * 4 + 3];
    let hud: Vec<&[u8]> = (14..60)
        .flat_map(|y| (14..300).map(move |x| (x, y)))
        .map(|(x, y)| pixel(x, y))
        .collect();
    let dark = hud.iter().filter(|p| p.iter().all(|&c| c < 90)).count();
    let bright = hud.iter().filter(|p| p.iter().all(|&c| c > 200)).count();
    assert!(
        dark > hud.len() / 2 && bright > 50,
        "HUD: {dark} dark, {bright} bright pixels"
    );
}

#[test]
fn bad_bundles_are_refused_with_their_name() {
    let dir = tempfile::tempdir().unwrap();
    let out_png = dir.path().join("x.png");
    let broken = dir.path().join("broken.relevo");
    std::fs::create_dir_all(&broken).unwrap();
    std::fs::write(broken.join("manifest.json"), "{ not json").unwrap();
    let truncated = grenoble_bundle(dir.path());
    std::fs::write(truncated.join("height.f32"), [0u8; 16]).unwrap();
    let truncated_pyramid = grenoble_pyramid(dir.path());
    std::fs::write(truncated_pyramid.join("tiles/lp.f32x2"), [0u8; 16]).unwrap();
    for (bundle, needle) in [
        (dir.path().join("missing.relevo"), "missing.relevo"),
        (broken.clone(), "invalid manifest"),
        (truncated.clone(), "height.f32"),
        (truncated_pyramid.clone(), "lp.f32x2"),
    ] {
        let out = viewer(
            &[
                "render".as_ref(),
                bundle.as_os_str(),
                "--out".as_ref(),
                out_png.as_os_str(),
            ],
            false,
            dir.path(),
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{}: {stderr}", bundle.display());
        assert!(
            stderr.contains(needle) && !stderr.contains("panicked"),
            "{stderr}"
        );
        assert!(!out_png.exists());
    }
    // Broken placement files and models: named, exit 1, no image.
    let placements = dir.path().join("placements");
    std::fs::create_dir_all(&placements).unwrap();
    let good = grenoble_bundle(&placements);
    let broken_json = placements.join("broken.geojson");
    std::fs::write(
        &broken_json,
        "{\"type\": \"FeatureCollection\", \"features\": [",
    )
    .unwrap();
    let missing_obj = placements.join("model.geojson");
    std::fs::write(
        &missing_obj,
        r#"{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"model": "tree.obj"},
            "geometry": {"type": "Point", "coordinates": [719000, 5030000]}}]}"#,
    )
    .unwrap();
    for (placement, needle) in [
        (&broken_json, "broken.geojson: not JSON"),
        (&missing_obj, "tree.obj"),
    ] {
        let out = viewer(
            &[
                "render".as_ref(),
                good.as_os_str(),
                "--objects".as_ref(),
                placement.as_os_str(),
                "--out".as_ref(),
                out_png.as_os_str(),
            ],
            false,
            dir.path(),
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(
            stderr.contains(needle) && !stderr.contains("panicked"),
            "{stderr}"
        );
        assert!(!out_png.exists());
    }

    // Bad arguments, refused before any work.
    let good = dir.path().join("good");
    std::fs::create_dir_all(&good).unwrap();
    let bundle = grenoble_bundle(&good);
    for (args, needle) in [
        (vec!["--camera", "1,2"], "--camera"),
        (vec!["--fov", "0"], "--fov"),
        (vec!["--size", "0x5"], "WIDTHxHEIGHT"),
        (vec!["--depth", out_png.to_str().unwrap()], "named twice"),
    ] {
        let mut all: Vec<&std::ffi::OsStr> = vec![
            "render".as_ref(),
            bundle.as_os_str(),
            "--out".as_ref(),
            out_png.as_os_str(),
        ];
        all.extend(args.iter().map(std::ffi::OsStr::new));
        let out = viewer(&all, false, dir.path());
        assert!(!out.status.success());
        assert!(String::from_utf8_lossy(&out.stderr).contains(needle));
    }
}

/// `relevo-view render --tab samples` writes the image at `--size`, the
/// drape fitted in it as the tab shows it (a square drape in a wide frame:
/// background left and right, the drape in the middle).
#[test]
fn the_samples_tab_renders_at_the_size_asked() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = grenoble_bundle_with_drape(dir.path());
    let samples = dir.path().join("samples.csv");
    std::fs::write(
        &samples,
        "class;xmin;ymin;xmax;ymax\nforest;20;20;40;40\nother;100;100;130;130\n",
    )
    .unwrap();
    let shot = dir.path().join("tab.png");
    let out = viewer(
        &[
            "render".as_ref(),
            bundle.as_os_str(),
            "--tab".as_ref(),
            "samples".as_ref(),
            "--samples".as_ref(),
            samples.as_os_str(),
            "--size".as_ref(),
            "320x200".as_ref(),
            "--out".as_ref(),
            shot.as_os_str(),
        ],
        false,
        dir.path(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (rgba, w, h) = decode_png(&shot);
    assert_eq!((w, h), (320, 200));
    let pixel = |x: usize, y: usize| &rgba[(y * w + x) * 4..(y * w + x) * 4 + 4];
    assert_eq!(
        pixel(5, 100),
        [27, 27, 27, 255],
        "background left of the drape"
    );
    assert_eq!(pixel(314, 100), [27, 27, 27, 255], "background right of it");
    assert_ne!(
        pixel(160, 100),
        [27, 27, 27, 255],
        "the drape in the middle"
    );
}

/// The viewer plans its memory as the CLI does: a frame or a bundle
/// estimated beyond `--max-memory`, or beyond what the process's own
/// address-space limit leaves, is refused before anything is drawn (a
/// 16384² render used to take 7.5 GB and abort under a 6 GB limit).
#[test]
fn frames_and_bundles_beyond_the_memory_budget_are_refused_before_drawing() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = grenoble_bundle(dir.path());
    let out_png = dir.path().join("x.png");
    let binary = env!("CARGO_BIN_EXE_relevo-view");
    let cases: [(&[&str], &str); 3] = [
        (
            &["--max-memory", "256M", "--size", "4096x4096"],
            "a 4096×4096 frame needs about",
        ),
        (
            &["--max-memory", "1M", "--size", "64x64"],
            "the raycaster's copy of the 257×257 grid",
        ),
        (
            &["--size", "16384x16384", "--depth", "x.f32"],
            "a 16384×16384 frame needs about",
        ),
    ];
    for (args, needle) in cases {
        let line = format!(
            "ulimit -v 4000000; exec '{binary}' render '{}' --out '{}' {}",
            bundle.display(),
            out_png.display(),
            args.join(" ")
        );
        let out = Command::new("bash")
            .args(["-c", &line])
            .current_dir(dir.path())
            .env("VK_ICD_FILENAMES", relevo_view::LAVAPIPE_ICD)
            .env("XDG_RUNTIME_DIR", dir.path())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains(needle) && stderr.contains("memory budget"),
            "{args:?}: {stderr}"
        );
        assert!(!out_png.exists() && !dir.path().join("x.f32").exists());
    }
}
