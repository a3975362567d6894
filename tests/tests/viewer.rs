//! The viewer's renderer in process on Mesa's lavapipe: headless frames of
//! the sample region in each mode against reviewed references, and the
//! seed's central claim — the raycast's depth is the GPU mesh's depth.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use relevo_core::horizon::{distance_of_depth, Band};
use relevo_tests::{compare_with_reference, prep_region, repo};
use relevo_view::flight::Flight;
use relevo_view::gpu::{Mode, Settings};
use relevo_view::headless::{device, render_once};
use relevo_view::scene::Scene;
use std::path::Path;

const SIZE: [u32; 2] = [480, 270];

/// The sample region's bundle, opened for the viewer.
fn olinda(dir: &Path) -> Scene {
    let bundle = prep_region(&repo("data/olinda/REGION.toml"), &dir.join("olinda.relevo"));
    Scene::open(&bundle).unwrap()
}

/// A device on lavapipe, the rasterizer the references were made with.
fn lavapipe() -> (relevo_view::gpu::Device, relevo_view::gpu::Queue) {
    if std::env::var_os("VK_ICD_FILENAMES").is_none() {
        std::env::set_var("VK_ICD_FILENAMES", relevo_view::LAVAPIPE_ICD);
    }
    let (device, queue, adapter) = device().unwrap();
    assert!(
        adapter.contains("llvmpipe"),
        "references are made on lavapipe, got {adapter}"
    );
    (device, queue)
}

/// Eight slices per cell with sub-voxels: the raycast at its finest.
fn fine_bands() -> Vec<Band> {
    vec![Band {
        until_m: f64::INFINITY,
        slices_per_cell: 8.0,
        subvoxel: true,
    }]
}

/// References: `data/golden/viewer/NAME.png`, made on lavapipe and looked
/// at before they were committed. Tolerance: at most 1 % of pixels with a
/// channel more than 24 levels off, and a mean difference under 1.5 levels.
#[test]
fn headless_frames_of_each_mode_match_their_references() {
    let d = tempfile::tempdir().unwrap();
    let mut scene = olinda(d.path());
    let (device, queue) = lavapipe();
    let flight = Flight::home(&scene);
    let bands = vec![
        Band {
            until_m: 3000.0,
            slices_per_cell: 4.0,
            subvoxel: true,
        },
        Band {
            until_m: f64::INFINITY,
            slices_per_cell: 1.0,
            subvoxel: false,
        },
    ];
    let cases = [
        (
            "mesh",
            Settings {
                mode: Mode::Mesh,
                tau_px: 1.0,
                ..Default::default()
            },
        ),
        (
            "mesh_wireframe",
            Settings {
                mode: Mode::Mesh,
                tau_px: 4.0,
                wireframe: true,
                texture: false,
                ..Default::default()
            },
        ),
        (
            "raycast",
            Settings {
                mode: Mode::Raycast,
                ..Default::default()
            },
        ),
        ("raycast_bands", {
            let mut s = Settings {
                mode: Mode::Raycast,
                ..Default::default()
            };
            s.raycast.bands = bands;
            s
        }),
    ];
    for (name, settings) in cases {
        let (frame, stats) =
            render_once(&device, &queue, &mut scene, &flight, &settings, SIZE).unwrap();
        let reference = repo(&format!("data/golden/viewer/{name}.png"));
        let d = compare_with_reference(&frame.rgba, SIZE, &reference, 24, |d| {
            d.pixels_off * 100 <= (SIZE[0] * SIZE[1]) as usize && d.mean < 1.5
        });
        eprintln!(
            "{name}: {} pixels off, mean {:.3} levels; {} triangles",
            d.pixels_off, d.mean, stats.triangles
        );
        if settings.mode == Mode::Mesh {
            assert!(
                stats.triangles > 100,
                "{name}: {} triangles",
                stats.triangles
            );
        }
    }
}

/// At pitch 0 the raycast's depth (eq. 5.11 per slice) and the GPU's depth
/// of the full-resolution mesh (τ = 0, no culling, no morphing) agree per
/// pixel: compared as distances along the view axis, in grid cells.
#[test]
fn raycast_depth_agrees_with_the_full_resolution_mesh() {
    let d = tempfile::tempdir().unwrap();
    let mut scene = olinda(d.path());
    let (device, queue) = lavapipe();
    let flight = Flight::home(&scene);
    let mesh = Settings {
        mode: Mode::Mesh,
        tau_px: 0.0,
        morph: false,
        cull: false,
        ..Default::default()
    };
    let mut raycast = Settings {
        mode: Mode::Raycast,
        ..Default::default()
    };
    raycast.raycast.bands = fine_bands();
    let (mesh_frame, _) = render_once(&device, &queue, &mut scene, &flight, &mesh, SIZE).unwrap();
    let (ray_frame, _) = render_once(&device, &queue, &mut scene, &flight, &raycast, SIZE).unwrap();
    let camera = flight.camera(&scene, SIZE);
    let cell = scene.frame.cell_size_m;
    let (mut errors, mut disagree) = (Vec::new(), 0usize);
    for (&m, &r) in mesh_frame.depth.iter().zip(&ray_frame.depth) {
        match (m < 1.0, r < 1.0) {
            (true, true) => errors.push(
                (distance_of_depth(&camera, m as f64) - distance_of_depth(&camera, r as f64)).abs()
                    / cell,
            ),
            (false, false) => {}
            _ => disagree += 1,
        }
    }
    errors.sort_by(f64::total_cmp);
    let at = |q: f64| errors[((errors.len() - 1) as f64 * q) as usize];
    let pixels = (SIZE[0] * SIZE[1]) as usize;
    eprintln!(
        "raycast vs mesh depth over {} terrain pixels: median {:.3}, p90 {:.3}, p95 {:.3}, p99 {:.3} cells; {disagree} of {pixels} pixels disagree on terrain/sky",
        errors.len(), at(0.5), at(0.9), at(0.95), at(0.99)
    );
    assert!(errors.len() > pixels / 3, "{} terrain pixels", errors.len());
    assert!(
        at(0.5) <= 0.15 && at(0.95) <= 0.3,
        "median {}, p95 {}",
        at(0.5),
        at(0.95)
    );
    assert!(disagree * 100 <= pixels, "{disagree} pixels disagree");
}
