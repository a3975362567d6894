//! Flying over a real DEM: the camera stays above the ground, terrain
//! following keeps the height above it, and true pitch looks where the
//! projection-plane shift does at the screen's centre.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use relevo_view::flight::{Controls, Flight, MIN_CLEARANCE_M};
use relevo_view::gpu::{Mode, Settings};
use relevo_view::scene::Scene;

#[test]
fn the_camera_never_goes_below_the_ground_and_follows_it_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::open(&common::grenoble_bundle(dir.path())).unwrap();
    let mut flight = Flight::home(&scene);
    // Sink hard: the eye stops at the clearance above the ground.
    let sink = Controls {
        climb: -1.0,
        ..Default::default()
    };
    for _ in 0..400 {
        flight.fly(&scene, &sink, 0.1);
    }
    let above = flight.height_above_ground(&scene).unwrap();
    assert!(
        (above - MIN_CLEARANCE_M).abs() < 1e-6,
        "{above} m above ground"
    );
    // Following the terrain at 300 m over the Alps keeps 300 m (to the
    // clearance's rounding) wherever the flight goes.
    flight.position.z += 298.0;
    flight.follow_terrain = true;
    let ahead = Controls {
        forward: 1.0,
        turn: 0.2,
        ..Default::default()
    };
    for _ in 0..50 {
        flight.fly(&scene, &ahead, 0.1);
        let above = flight.height_above_ground(&scene).unwrap();
        assert!((above - 300.0).abs() < 1e-3, "{above} m above ground");
    }
}

#[test]
fn true_pitch_looks_where_the_shifted_plane_looks_at_the_centre() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::open(&common::grenoble_bundle(dir.path())).unwrap();
    let mut flight = Flight::home(&scene);
    flight.horizon_frac = 1.6;
    let size = [1280, 720];
    let shifted = flight.camera_for(&scene, size, &Settings::default());
    let pitched = flight.camera_for(
        &scene,
        size,
        &Settings {
            true_pitch: true,
            ..Default::default()
        },
    );
    assert_eq!(shifted.pitch_deg, 0.0);
    assert!(pitched.pitch_deg < -30.0, "{}", pitched.pitch_deg);
    // A point along the pitched camera's axis lands at the centre of both.
    let p = pitched.position + pitched.forward() * 1000.0;
    for camera in [shifted, pitched] {
        let clip = camera.view_projection() * p.extend(1.0);
        let (x, y) = (clip.x / clip.w, clip.y / clip.w);
        assert!(x.abs() < 1e-9 && y.abs() < 1e-9, "({x}, {y})");
    }
    // The raycast never tilts.
    let raycast = Settings {
        mode: Mode::Raycast,
        true_pitch: true,
        ..Default::default()
    };
    assert_eq!(flight.camera_for(&scene, size, &raycast).pitch_deg, 0.0);
}
