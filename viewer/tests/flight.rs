//! Flying over a real DEM: the camera stays above the ground, terrain
//! following keeps the height above it, and looking down tilts the camera
//! within the raycaster's range.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use relevo_core::horizon::pitch_range;
use relevo_view::flight::{Controls, Flight, MIN_CLEARANCE_M};
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
fn looking_down_tilts_within_the_raycasts_range_and_survives_the_camera_string() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::open(&common::grenoble_bundle(dir.path())).unwrap();
    let mut flight = Flight::home(&scene);
    flight.horizon_frac = 0.5;
    let size = [1280, 720];
    let [low, _] = pitch_range(&flight.camera(&scene, size));
    // Hold "look down" for ten seconds: the tilt stops at the range's end.
    let down = Controls {
        look: 1.0,
        ..Default::default()
    };
    for _ in 0..100 {
        flight.fly(&scene, &down, 0.1);
    }
    let camera = flight.camera(&scene, size);
    assert!(
        (camera.pitch_deg - low).abs() < 1e-9,
        "{} vs {low}",
        camera.pitch_deg
    );
    assert!(low < -50.0, "{low}");
    // The camera string carries the pitch back.
    let pose = flight.pose(&scene, size[1]);
    assert!(pose.to_string().contains("deg"), "{pose}");
    let again = Flight::from_pose(&scene, &pose, size[1]).unwrap();
    assert_eq!(again.camera(&scene, size), camera);
    // Every mode draws that camera, the raycast included; half way back up
    // the raycast shows ground in every row.
    flight.pitch_deg = low / 2.0;
    let camera = flight.camera(&scene, size);
    let frame = relevo_core::horizon::render(&scene.terrain, &camera, &Default::default()).unwrap();
    let bottom_and_top = [0, size[1] as usize - 1].map(|y| {
        frame.depth[y * size[0] as usize..(y + 1) * size[0] as usize]
            .iter()
            .filter(|&&d| d < 1.0)
            .count()
    });
    assert!(bottom_and_top.iter().all(|&n| n > 0), "{bottom_and_top:?}");
}
