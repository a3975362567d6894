//! The viewer's renderer in process on Mesa's lavapipe: headless frames of
//! the sample region in each mode against reviewed references, and the
//! seed's central claim — the raycast's depth is the GPU mesh's depth.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use relevo_core::bundle::BundleFiles;
use relevo_core::horizon::{distance_of_depth, DistanceBand};
use relevo_tests::forge::forged;
use relevo_tests::{compare_with_reference, prep_region, repo};
use relevo_view::flight::Flight;
use relevo_view::gpu::FrameStats;
use relevo_view::headless::{device, render_once, Shot};
use relevo_view::scene::Scene;
use relevo_view::settings::{Settings, TerrainMode};
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
fn fine_bands() -> Vec<DistanceBand> {
    vec![DistanceBand {
        until_m: f64::INFINITY,
        slices_per_cell: 8.0,
        subvoxel: true,
    }]
}

/// The terrain-only frames of the snapshot test (objects and vegetation
/// off): mesh, wireframe, raycast, raycast with bands, Z-buffer [c] and [g].
fn terrain_only_cases() -> Vec<(&'static str, Settings)> {
    let cases = [
        (
            "mesh",
            Settings {
                mode: TerrainMode::Mesh,
                tau_px: 1.0,
                ..Default::default()
            },
        ),
        (
            "mesh_wireframe",
            Settings {
                mode: TerrainMode::Mesh,
                tau_px: 4.0,
                wireframe: true,
                texture: false,
                ..Default::default()
            },
        ),
        (
            "raycast",
            Settings {
                mode: TerrainMode::Raycast,
                ..Default::default()
            },
        ),
        ("raycast_bands", {
            let mut s = Settings {
                mode: TerrainMode::Raycast,
                ..Default::default()
            };
            s.raycast.bands = relevo_view::settings::detailed_bands();
            s
        }),
    ];
    let zbuffer = |letter| Settings {
        mode: TerrainMode::parse(&format!("zbuffer:{letter}")).unwrap(),
        ..Default::default()
    };
    cases
        .into_iter()
        .chain([("zbuffer_c", zbuffer('c')), ("zbuffer_g", zbuffer('g'))])
        .map(|(name, settings)| {
            (
                name,
                Settings {
                    objects: false,
                    ..settings
                },
            )
        })
        .collect()
}

/// References: `data/golden/viewer/NAME.png` — mesh, mesh wireframe,
/// raycast, raycast with bands, Z-buffer baselines [c] and [g], the sample
/// placement composited in mesh and raycast modes (with the region's
/// vegetation), and the forest up close as billboards in both modes, as
/// sprites, and from the two baselines (plain list, blobs) — made on lavapipe
/// and looked at before they were committed. Tolerance: at most 1 % of
/// pixels with a channel more than 24 levels off, and a mean difference
/// under 1.5 levels.
#[test]
fn headless_frames_of_each_mode_match_their_references() {
    let d = tempfile::tempdir().unwrap();
    let mut scene = olinda(d.path());
    let (device, queue) = lavapipe();
    let flight = Flight::home(&scene);

    let terrain_only = terrain_only_cases()
        .into_iter()
        .map(|(name, settings)| (name, settings, flight));
    // The sample placement seen from 1.2 km closer, 60 m above the ground.
    scene
        .load_objects(&repo("data/olinda/objects.geojson"))
        .unwrap();
    let pose = relevo_core::scene::CameraPose::parse("290963,9112753,0,35,135").unwrap();
    let mut near = Flight::from_pose(&scene, &pose, SIZE[1]).unwrap();
    near.position.z = scene
        .ground_height(near.position.x, near.position.y)
        .unwrap()
        + 60.0;
    let with_objects = [
        (
            "mesh_objects",
            Settings {
                mode: TerrainMode::Mesh,
                tau_px: 1.0,
                ..Default::default()
            },
            near,
        ),
        (
            "raycast_objects",
            Settings {
                mode: TerrainMode::Raycast,
                ..Default::default()
            },
            near,
        ),
    ];
    // The sample region's forest from 120 m above the ground: billboards in
    // both modes, and sprites.
    let pose = relevo_core::scene::CameraPose::parse("292000,9113000,0,30,135").unwrap();
    let mut forest = Flight::from_pose(&scene, &pose, SIZE[1]).unwrap();
    forest.position.z = scene
        .ground_height(forest.position.x, forest.position.y)
        .unwrap()
        + 120.0;
    let vegetation = |mode, sprites| Settings {
        mode,
        tau_px: 1.0,
        sprites,
        ..Default::default()
    };
    // The same forest from 300 m above the ground, looking 20° down for
    // real (centred plane): the raycast marches lines through the nadir,
    // and the impostors composite through its pitched depth.
    let mut down = forest;
    down.position.z += 180.0;
    down.pitch_deg = -20.0;
    down.horizon_frac = 0.5;
    let with_vegetation = [
        (
            "mesh_vegetation",
            vegetation(TerrainMode::Mesh, false),
            forest,
        ),
        (
            "mesh_vegetation_pitched",
            vegetation(TerrainMode::Mesh, false),
            down,
        ),
        (
            "raycast_vegetation_pitched",
            vegetation(TerrainMode::Raycast, false),
            down,
        ),
        (
            "raycast_vegetation",
            vegetation(TerrainMode::Raycast, false),
            forest,
        ),
        ("mesh_sprites", vegetation(TerrainMode::Mesh, true), forest),
        (
            "mesh_vegetation_list",
            Settings {
                vegetation: relevo_view::settings::VegetationSelection::List,
                ..vegetation(TerrainMode::Mesh, false)
            },
            forest,
        ),
        (
            "mesh_vegetation_blobs",
            Settings {
                vegetation: relevo_view::settings::VegetationSelection::Blobs { side_m: 1000.0 },
                ..vegetation(TerrainMode::Mesh, false)
            },
            forest,
        ),
    ];
    for (name, settings, flight) in terrain_only.chain(with_objects).chain(with_vegetation) {
        let (frame, stats) = render_once(
            &device,
            &queue,
            &mut scene,
            &flight,
            &settings,
            &Shot::new(SIZE),
        )
        .unwrap();
        let reference = repo(&format!("data/golden/viewer/{name}.png"));
        let d = compare_with_reference(&frame.rgba, SIZE, &reference, 24, |d| {
            d.pixels_off * 100 <= (SIZE[0] * SIZE[1]) as usize && d.mean < 1.5
        });
        eprintln!(
            "{name}: {} pixels off, mean {:.3} levels; {} terrain, {} object triangles",
            d.pixels_off, d.mean, stats.triangles, stats.object_triangles
        );
        if settings.mode == TerrainMode::Mesh {
            assert!(
                stats.triangles > 100,
                "{name}: {} triangles",
                stats.triangles
            );
        }
        if settings.objects {
            assert!(
                stats.object_triangles > 90,
                "{name}: {} object triangles",
                stats.object_triangles
            );
        }
    }
}

/// The raycast's depth (eq. 5.11, per slice level, per row pitched) and
/// the GPU's depth of the full-resolution mesh (τ = 0, no culling, no
/// morphing) agree per pixel, level with the plane shifted and pitched for
/// real down and up: compared as distances along the view axis, in cells.
#[test]
fn raycast_depth_agrees_with_the_full_resolution_mesh() {
    let d = tempfile::tempdir().unwrap();
    let mut scene = olinda(d.path());
    let (device, queue) = lavapipe();
    let mesh = Settings {
        mode: TerrainMode::Mesh,
        tau_px: 0.0,
        morph: false,
        cull: false,
        ..Default::default()
    };
    let mut raycast = Settings {
        mode: TerrainMode::Raycast,
        ..Default::default()
    };
    raycast.raycast.bands = fine_bands();
    for (pitch, horizon) in [
        (0.0, None),
        (-20.0, Some(0.5)),
        (-45.0, Some(0.5)),
        (4.0, Some(0.5)),
    ] {
        let mut flight = Flight::home(&scene);
        flight.pitch_deg = pitch;
        if let Some(h) = horizon {
            flight.horizon_frac = h;
        }
        let (mesh_frame, _) = render_once(
            &device,
            &queue,
            &mut scene,
            &flight,
            &mesh,
            &Shot::new(SIZE),
        )
        .unwrap();
        let (ray_frame, _) = render_once(
            &device,
            &queue,
            &mut scene,
            &flight,
            &raycast,
            &Shot::new(SIZE),
        )
        .unwrap();
        let camera = flight.camera(&scene, SIZE);
        assert_eq!(camera.pitch_deg, pitch);
        let cell = scene.frame.cell_size_m;
        let (errors, disagree) =
            depth_differences(&camera, &mesh_frame.depth, &ray_frame.depth, |_| cell);
        let at = |q: f64| errors[((errors.len() - 1) as f64 * q) as usize];
        let pixels = (SIZE[0] * SIZE[1]) as usize;
        eprintln!(
            "pitch {pitch}°: raycast vs mesh depth over {} terrain pixels: median {:.3}, p90 {:.3}, p95 {:.3}, p99 {:.3} cells; {disagree} of {pixels} pixels disagree on terrain/sky",
            errors.len(), at(0.5), at(0.9), at(0.95), at(0.99)
        );
        assert!(
            errors.len() > pixels / 3,
            "pitch {pitch}°: {} terrain pixels",
            errors.len()
        );
        assert!(
            at(0.5) <= 0.15 && at(0.95) <= 0.3,
            "pitch {pitch}°: median {}, p95 {}",
            at(0.5),
            at(0.95)
        );
        assert!(
            disagree * 100 <= pixels,
            "pitch {pitch}°: {disagree} pixels disagree"
        );
    }
}

/// Where both depth buffers (GPU depth in [0, 1], 1 = sky) hold terrain:
/// the difference of their distances along `camera`'s view axis in units
/// of `unit(nearer distance)` metres, sorted; and how many pixels are
/// terrain in one and sky in the other.
fn depth_differences(
    camera: &relevo_core::camera::Camera,
    a: &[f32],
    b: &[f32],
    unit: impl Fn(f64) -> f64,
) -> (Vec<f64>, usize) {
    let (mut differences, mut disagree) = (Vec::new(), 0usize);
    for (&a, &b) in a.iter().zip(b) {
        match (a < 1.0, b < 1.0) {
            (true, true) => {
                let (a, b) = (
                    distance_of_depth(camera, a as f64),
                    distance_of_depth(camera, b as f64),
                );
                differences.push((a - b).abs() / unit(a.min(b)));
            }
            (false, false) => {}
            _ => disagree += 1,
        }
    }
    differences.sort_by(f64::total_cmp);
    (differences, disagree)
}

/// The sample region's vegetation, from relevo-core's quadtree cut, in
/// mesh and raycast modes: every view of the draw list becomes one GPU
/// instance, and impostors show exactly where they are nearer than the
/// terrain — the pixels of the composited frame that differ from the
/// terrain alone are those where the vegetation drawn alone is in front.
#[test]
fn vegetation_is_drawn_from_the_cut_and_composited_through_the_depth() {
    let d = tempfile::tempdir().unwrap();
    let mut scene = olinda(d.path());
    let (device, queue) = lavapipe();
    let pose = relevo_core::scene::CameraPose::parse("292000,9113000,0,30,135").unwrap();
    let mut flight = Flight::from_pose(&scene, &pose, SIZE[1]).unwrap();
    flight.position.z = scene
        .ground_height(flight.position.x, flight.position.y)
        .unwrap()
        + 120.0;
    for mode in [TerrainMode::Mesh, TerrainMode::Raycast] {
        let settings = Settings {
            mode,
            tau_px: 1.0,
            ..Default::default()
        };
        let (with, stats) = render_once(
            &device,
            &queue,
            &mut scene,
            &flight,
            &settings,
            &Shot::new(SIZE),
        )
        .unwrap();
        let list = &scene.vegetation.as_ref().unwrap().list;
        let views: usize = list.instances().map(|i| i.views().len()).sum();
        assert_eq!(
            stats.impostor_views, views,
            "{mode}: one GPU instance per view"
        );
        assert_eq!(stats.impostors, list.len());
        assert!(stats.vegetation_represented > 1000, "{mode}: {stats:?}");
        let off = Settings {
            objects: false,
            ..settings.clone()
        };
        let (terrain, _) =
            render_once(&device, &queue, &mut scene, &flight, &off, &Shot::new(SIZE)).unwrap();
        let alone = Settings {
            terrain: false,
            ..settings.clone()
        };
        let (vegetation, _) = render_once(
            &device,
            &queue,
            &mut scene,
            &flight,
            &alone,
            &Shot::new(SIZE),
        )
        .unwrap();
        let (mut shown, mut mismatched) = (0usize, 0usize);
        for i in 0..with.depth.len() {
            let differs = with.rgba[4 * i..4 * i + 4] != terrain.rgba[4 * i..4 * i + 4];
            let in_front = vegetation.depth[i] < terrain.depth[i];
            shown += differs as usize;
            mismatched += (differs != in_front) as usize;
        }
        eprintln!("{mode}: {shown} vegetation pixels, {mismatched} where the depth says otherwise");
        assert!(shown > 2000, "{mode}: {shown} vegetation pixels");
        assert!(
            mismatched * 100 <= shown,
            "{mode}: {mismatched} of {shown} pixels mismatched"
        );

        // The plain list draws every object one by one: the clusters stand
        // in for them with about the same coverage, with far fewer draws.
        let list = Settings {
            vegetation: relevo_view::settings::VegetationSelection::List,
            ..settings.clone()
        };
        let (each, list_stats) = render_once(
            &device,
            &queue,
            &mut scene,
            &flight,
            &list,
            &Shot::new(SIZE),
        )
        .unwrap();
        let covered = |frame: &relevo_view::gpu::Readback| {
            (0..frame.depth.len())
                .filter(|&i| frame.rgba[4 * i..4 * i + 4] != terrain.rgba[4 * i..4 * i + 4])
                .count()
        };
        let (clustered, one_by_one) = (covered(&with), covered(&each));
        eprintln!(
            "{mode}: quadtree {} impostors cover {clustered} pixels, list {} cover {one_by_one}",
            stats.impostors, list_stats.impostors
        );
        assert!(list_stats.impostors > 3 * stats.impostors);
        assert!(
            clustered.abs_diff(one_by_one) * 20 <= one_by_one,
            "{mode}: {clustered} against {one_by_one} pixels"
        );
    }
}

/// The HUD's "objects represented" is the number of database objects
/// inside the frustum and the last band, for each selection, mode and
/// several cameras over the sample region (the draw list's count, printed
/// in the HUD line); in mesh mode every impostor stands on the refined mesh
/// drawn (relevo-core's `mesh_height` at its foot), which lies off the grid
/// the bake placed it on.
#[test]
fn the_hud_counts_the_objects_in_view_and_impostors_stand_on_the_mesh_drawn() {
    use relevo_core::cluster::cut::{box_distance, box_in_frustum};
    use relevo_view::settings::VegetationSelection;
    let d = tempfile::tempdir().unwrap();
    let mut scene = olinda(d.path());
    let (device, queue) = lavapipe();
    let mut lifted = 0;
    for (k, text) in [
        "292000,9113000,0,30,135",
        "290000,9112000,0,70,100",
        "294500,9116500,0,210,160",
        "291000,9119000,0,150,135",
    ]
    .iter()
    .enumerate()
    {
        let pose = relevo_core::scene::CameraPose::parse(text).unwrap();
        let mut flight = Flight::from_pose(&scene, &pose, SIZE[1]).unwrap();
        flight.position.z = scene
            .ground_height(flight.position.x, flight.position.y)
            .unwrap()
            + [120.0, 400.0, 60.0, 1500.0][k];
        for selection in [
            VegetationSelection::Quadtree,
            VegetationSelection::List,
            VegetationSelection::Blobs { side_m: 1000.0 },
        ] {
            for mode in [TerrainMode::Mesh, TerrainMode::Raycast] {
                let settings = Settings {
                    mode,
                    vegetation: selection,
                    ..Default::default()
                };
                let (_, stats) = render_once(
                    &device,
                    &queue,
                    &mut scene,
                    &flight,
                    &settings,
                    &Shot::new(SIZE),
                )
                .unwrap();
                let camera = flight.camera(&scene, SIZE);
                let vegetation = scene.vegetation.as_ref().unwrap();
                let last = vegetation.cut.last_distance();
                let planes = camera.frustum_planes();
                let in_view = vegetation
                    .clusters
                    .tree
                    .objects
                    .iter()
                    .filter(|o| {
                        let [min, max] = o.bounds();
                        box_in_frustum(&planes, min, max)
                            && box_distance(camera.position, min, max) <= last
                    })
                    .count();
                let what = format!("camera {text}, {selection}, {mode}");
                assert!(in_view > 50, "{what}: {in_view} objects in view");
                assert_eq!(stats.vegetation_represented, in_view, "{what}");
                let hud = hud_text(&settings, &stats, &scene, &flight);
                assert!(
                    hud.contains(&format!("{in_view} objects represented")),
                    "{what}: {hud}"
                );
                if mode == TerrainMode::Mesh {
                    let hierarchy = scene.lp.as_ref().unwrap().hierarchy();
                    let params = settings.refine_params(&camera);
                    for instance in scene.vegetation.as_ref().unwrap().list.instances() {
                        let [x, y, z] = instance.foot.map(f64::from);
                        let (x, y) = (x as f32 as f64, y as f32 as f64);
                        // Off the data (a cluster's centre over the
                        // padding) the impostor is left where it was.
                        let offset = relevo_core::lp::refine::mesh_height(
                            &relevo_core::lp::refine::GridArrays::new(
                                &hierarchy,
                                scene.terrain.heights(),
                            ),
                            &params,
                            x,
                            y,
                        )
                        .zip(scene.ground_height(x, y))
                        .map_or(0.0, |(mesh, grid)| mesh - grid);
                        let placed = match instance.drawn {
                            relevo_core::cluster::cut::Drawn::Object(o) => {
                                scene.vegetation.as_ref().unwrap().clusters.tree.objects[o as usize]
                                    .foot[2] as f64
                            }
                            relevo_core::cluster::cut::Drawn::Node(n) => {
                                scene.vegetation.as_ref().unwrap().clusters.tree.nodes[n as usize]
                                    .min[2] as f64
                            }
                        };
                        // Raised by exactly the mesh's offset from the grid.
                        assert!(
                            (z - placed - offset).abs() < 0.01,
                            "{what}: foot at {z}, placed at {placed}, mesh offset {offset}"
                        );
                        lifted += usize::from(offset.abs() > 0.5);
                    }
                }
            }
        }
    }
    assert!(lifted > 100, "{lifted} impostors moved by more than 0.5 m");
}

/// A building placed behind a ridge of the Alps is hidden exactly where
/// the terrain is in front of it, in both modes: the pixels where the
/// composited frame shows the building are those where the building alone
/// is nearer than the terrain alone.
#[test]
fn composited_objects_are_hidden_exactly_where_the_terrain_covers_them() {
    use relevo_tests::{prep_dem, shared};
    let d = tempfile::tempdir().unwrap();
    let bundle = prep_dem(
        &shared("dem/Copernicus_DSM_10_N45_00_E005_00_DEM.tif"),
        d.path(),
    );
    assert_objects_hidden_where_the_terrain_covers_them(
        &mut Scene::open(&bundle).unwrap(),
        d.path(),
    );
}

/// The same over a pyramid (the Grenoble sample region in 64-cell tiles):
/// the mesh refined through its tiles and the raycast over its levels
/// composite objects as a single grid does.
#[test]
fn objects_composite_over_a_pyramid_as_over_a_single_grid() {
    let d = tempfile::tempdir().unwrap();
    let (_, mut tiled) = grenoble_both(d.path());
    assert!(tiled.paged.is_some());
    assert_objects_hidden_where_the_terrain_covers_them(&mut tiled, d.path());
}

/// Olinda prepared as a pyramid of 32-cell tiles (its clusters baked on
/// the tiles' ground) draws the vegetation as the single-grid bundle does:
/// from the home view and a low pass, the vegetation alone renders the
/// same pixels, and over the terrain (mesh through the tiles, all loaded)
/// it shows at the same pixels.
#[test]
fn vegetation_over_a_pyramid_draws_as_over_a_single_grid() {
    let d = tempfile::tempdir().unwrap();
    let toml = repo("data/olinda/REGION.toml");
    let region = relevo::prep::region::RegionSpec::load(&toml).unwrap();
    let options = relevo::prep::tiled::TiledOptions {
        tile_cells: Some(32),
        force: false,
        resume: false,
    };
    let tiled = relevo::prep::tiled::prep_tiled(&region, &d.path().join("t.relevo"), options)
        .unwrap()
        .bundle;
    let mut single = olinda(d.path());
    let mut pyramid = Scene::open(&tiled).unwrap();
    assert!(pyramid.paged.is_some() && pyramid.vegetation.is_some());
    let (device, queue) = lavapipe();
    let mut low = Flight::home(&single);
    low.position.z -= 150.0;
    for flight in [Flight::home(&single), low] {
        let settings = Settings {
            tau_px: 1.0,
            ..Default::default()
        };
        let alone = Settings {
            terrain: false,
            ..settings.clone()
        };
        let terrain_only = Settings {
            objects: false,
            ..settings.clone()
        };
        let render = |scene: &mut Scene, s: &Settings| {
            render_once(&device, &queue, scene, &flight, s, &Shot::new(SIZE))
                .unwrap()
                .0
        };
        // Alone, the pyramid's impostors stand where the bake put them
        // (no mesh drawn to stand on), the single grid's on its mesh: the
        // same objects, a few pixels apart.
        let (a, b) = (render(&mut single, &alone), render(&mut pyramid, &alone));
        let drawn = |r: &relevo_view::gpu::Readback| r.depth.iter().filter(|&&z| z < 1.0).count();
        let (na, nb) = (drawn(&a), drawn(&b));
        assert!(
            na > 2000 && na.abs_diff(nb) * 20 < na,
            "{na} and {nb} pixels"
        );
        // Over the terrain, both on the mesh drawn: shown at the same pixels.
        let shown = |scene: &mut Scene| {
            let (both, terrain) = (render(scene, &settings), render(scene, &terrain_only));
            (0..both.depth.len())
                .map(|i| both.depth[i] < terrain.depth[i])
                .collect::<Vec<bool>>()
        };
        let (sa, sb) = (shown(&mut single), shown(&mut pyramid));
        let n = sa.iter().filter(|&&v| v).count();
        let off = sa.iter().zip(&sb).filter(|(x, y)| x != y).count();
        assert!(n > 2000 && off * 200 <= n, "{off} of {n} pixels differ");
    }
}

/// A 1 km² building 1 500 m tall, 3 km beyond the ground below the screen's
/// centre seen low over the valley floor, composited in mesh and raycast
/// modes: shown exactly where it alone is nearer than the terrain alone
/// (all but 0.5 % of its pixels), and partly hidden.
fn assert_objects_hidden_where_the_terrain_covers_them(scene: &mut Scene, dir: &Path) {
    let (device, queue) = lavapipe();
    // Low over the valley floor, looking level at the mountains.
    let mut flight = Flight::home(scene);
    flight.position.z = scene
        .ground_height(flight.position.x, flight.position.y)
        .unwrap()
        + 30.0;
    flight.horizon_frac = 0.5;
    let camera = flight.camera(scene, SIZE);
    // The ground just below the screen's centre, and 3 km beyond it.
    let (px, py) = (SIZE[0] as f64 / 2.0, SIZE[1] as f64 * 0.55);
    let distance =
        relevo_core::horizon::pick(&scene.terrain, &camera, px, py).expect("terrain at the centre");
    let ray = relevo_core::horizon::pixel_ray(&camera, px, py);
    let heading = flight.heading_deg.to_radians();
    let centre = [
        camera.position.x + ray[0] * distance + heading.sin() * 3000.0,
        camera.position.y + ray[1] * distance + heading.cos() * 3000.0,
    ];
    let corner = |dx: f64, dy: f64| {
        let (e, n) = scene
            .frame
            .world_from_terrain(centre[0] + dx, centre[1] + dy);
        format!("[{e}, {n}]")
    };
    let placement = dir.join("tower.geojson");
    std::fs::write(
        &placement,
        format!(
            r#"{{"type": "FeatureCollection", "features": [{{"type": "Feature",
               "properties": {{"height_m": 1500, "color": [255, 0, 255]}},
               "geometry": {{"type": "Polygon", "coordinates": [[{}, {}, {}, {}, {}]]}}}}]}}"#,
            corner(-500.0, -500.0),
            corner(500.0, -500.0),
            corner(500.0, 500.0),
            corner(-500.0, 500.0),
            corner(-500.0, -500.0)
        ),
    )
    .unwrap();
    scene.load_objects(&placement).unwrap();
    for (name, mode) in [
        ("mesh", TerrainMode::Mesh),
        ("raycast", TerrainMode::Raycast),
    ] {
        let mut settings = Settings {
            mode,
            tau_px: 1.0,
            ..Default::default()
        };
        settings.raycast.bands = fine_bands();
        let terrain_only = Settings {
            objects: false,
            ..settings.clone()
        };
        let objects_only = Settings {
            terrain: false,
            ..settings.clone()
        };
        let render = |scene: &mut Scene, s: &Settings| {
            render_once(&device, &queue, scene, &flight, s, &Shot::new(SIZE))
                .unwrap()
                .0
        };
        let (both, terrain, object) = (
            render(scene, &settings),
            render(scene, &terrain_only),
            render(scene, &objects_only),
        );
        let (mut expected, mut shown, mut wrong, mut ambiguous) = (0usize, 0usize, 0usize, 0usize);
        let mut hidden = 0usize;
        for i in 0..(SIZE[0] * SIZE[1]) as usize {
            if object.depth[i] >= 1.0 {
                continue;
            }
            let nearer = object.depth[i] < terrain.depth[i];
            let visible = both.rgba[i * 4..i * 4 + 3] != terrain.rgba[i * 4..i * 4 + 3];
            expected += usize::from(nearer);
            hidden += usize::from(!nearer);
            shown += usize::from(visible);
            if nearer != visible {
                // Where the two depths are within a hair, either answer is right.
                if (object.depth[i] - terrain.depth[i]).abs() < 1e-5 {
                    ambiguous += 1;
                } else {
                    wrong += 1;
                }
            }
        }
        let total = expected + hidden;
        eprintln!("{name}: building covers {total} px, {expected} nearer than the terrain, {shown} shown, {wrong} wrong, {ambiguous} within 1e-5 of the terrain's depth");
        assert!(
            expected * 20 > total && hidden * 20 > total,
            "{name}: the building should be partly hidden ({expected} of {total} visible)"
        );
        assert!(
            wrong * 200 <= total,
            "{name}: {wrong} of {total} pixels composited wrongly"
        );
    }
}

/// The samples tab's work without the window: rectangles marked on the
/// sample region's drape, detection in the background, accepting writes
/// the samples and the database into the bundle and re-bakes its clusters
/// atomically; the reopened scene draws the new vegetation.
#[test]
fn samples_marked_on_the_drape_detect_accept_and_recluster() {
    use relevo_view::samples::SamplesTab;
    let d = tempfile::tempdir().unwrap();
    let bundle = prep_region(
        &repo("data/olinda/REGION.toml"),
        &d.path().join("olinda.relevo"),
    );
    let mut tab = SamplesTab::new(&bundle);
    let before = tab.detections.len();
    // The tab opens with the samples prep kept: the region's own (marked on
    // the Landsat file, carried onto the drape — the same image on the DEM's
    // grid, within a pixel of it), three forest, four counter-examples.
    let region_samples = [
        ("forest", [60.0, 60.0, 120.0, 110.0]),
        ("forest", [200.0, 190.0, 220.0, 205.0]),
        ("forest", [285.0, 8.0, 315.0, 28.0]),
        ("other", [50.0, 280.0, 100.0, 320.0]),
        ("other", [280.0, 250.0, 320.0, 300.0]),
        ("other", [250.0, 80.0, 290.0, 120.0]),
        ("other", [150.0, 230.0, 200.0, 260.0]),
    ];
    assert_eq!(tab.samples.len(), region_samples.len(), "{}", tab.status);
    for ((class, kept), (want_class, want)) in tab.samples.iter().zip(region_samples) {
        assert_eq!(class, want_class);
        for (k, w) in kept.iter().zip(want) {
            assert!((k - w).abs() <= 1.5, "{kept:?} is not {want:?}");
        }
    }
    tab.detect();
    let start = std::time::Instant::now();
    while tab.running() {
        assert!(start.elapsed().as_secs() < 120, "detection did not finish");
        std::thread::sleep(std::time::Duration::from_millis(20));
        tab.poll();
    }
    assert!(tab.fresh, "{}", tab.status);
    let detected = tab.detections.len();
    assert!(
        detected > before / 2 && detected < before * 2,
        "{detected} against {before}"
    );
    tab.accept().unwrap();

    let reopened = relevo_core::bundle::Bundle::open(&bundle).unwrap();
    assert_eq!(
        relevo_core::validation::validate(&reopened),
        Vec::<String>::new()
    );
    assert_eq!(reopened.vegetation().unwrap().unwrap().len(), detected);
    assert!(reopened
        .manifest
        .artifacts
        .contains_key("vegetation_samples"));
    assert!(
        !reopened
            .manifest
            .exports
            .contains_key("vegetation_geopackage"),
        "stale export kept"
    );
    let scene = Scene::open(&bundle).unwrap();
    let vegetation = scene.vegetation.as_ref().unwrap();
    assert_eq!(vegetation.clusters.tree.objects.len(), detected);
}

/// `relevo-view render --tab samples`: the samples tab's image — detection
/// on the drape, relevo-core's overlay and the marked rectangles.
#[test]
fn the_samples_tab_renders_its_overlay_for_inspection() {
    let d = tempfile::tempdir().unwrap();
    let bundle = prep_region(
        &repo("data/olinda/REGION.toml"),
        &d.path().join("olinda.relevo"),
    );
    let samples = repo("data/olinda/samples.csv");
    let (rgba, [w, h], objects) = relevo_view::samples::render_tab(&bundle, &samples).unwrap();
    let color = relevo_core::bundle::Bundle::open(&bundle)
        .unwrap()
        .manifest
        .color
        .unwrap();
    assert_eq!([w, h], [color.width, color.height]);
    assert_eq!(rgba.len(), w * h * 4);
    // The first sample's outline, white, on its edge pixels: (60, 60)–(120,
    // 110), the maxima exclusive.
    for (x, y) in [(60, 60), (90, 60), (119, 85), (60, 109)] {
        assert_eq!(
            rgba[(y * w + x) * 4..(y * w + x) * 4 + 4],
            [255; 4],
            "({x}, {y})"
        );
    }
    // The region's own samples, read as drape pixels (within a pixel of the
    // Landsat image's), find about what prep found.
    let stored = 11_764;
    assert!(objects.abs_diff(stored) * 10 < stored, "{objects} objects");
    let broken = d.path().join("broken.csv");
    std::fs::write(&broken, "class;xmin;ymin;xmax;ymax\nforest;1;1\n").unwrap();
    let err = relevo_view::samples::render_tab(&bundle, &broken).unwrap_err();
    let message = format!("{err:#}");
    assert!(
        message.contains("broken.csv") && message.contains("line 2"),
        "{message}"
    );
}

/// The viewer opens hostile bundles through relevo-core's checks, as the
/// CLI does: a quadtree whose child points back at the root (the viewer
/// used to overflow its stack), an atlas page that decodes to 40000² (it
/// used to allocate 6.4 GB and abort), heights that are a FIFO (it used to
/// wait for ever) and a NaN height at a data vertex are each refused when
/// the scene opens, naming the file.
#[test]
fn the_viewer_refuses_hostile_bundles_by_name_when_it_opens_them() {
    let d = tempfile::tempdir().unwrap();
    let bundle = prep_region(
        &repo("data/olinda/REGION.toml"),
        &d.path().join("olinda.relevo"),
    );
    let cycle = forged(&bundle, "cycle.relevo", "clusters/nodes.bin", &|b| {
        // Node 0's first child slot (children at byte 48 of 68) → node 0.
        let slot = (0..4)
            .map(|k| 48 + 4 * k)
            .find(|&o| b[o..o + 4] != [0xff; 4])
            .unwrap();
        b[slot..slot + 4].copy_from_slice(&0u32.to_le_bytes());
    });
    let bomb = forged(&bundle, "bomb.relevo", "clusters/atlas_000.png", &|b| {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, 40000, 40000);
        encoder.set_color(png::ColorType::Rgba);
        let mut writer = encoder.write_header().unwrap();
        writer
            .write_chunk(png::chunk::IDAT, &[0x78, 0x9c, 0, 0, 0, 0])
            .unwrap();
        drop(writer);
        *b = out;
    });
    let mask = std::fs::read(bundle.join("mask.u8")).unwrap();
    let vertex = mask.iter().position(|&m| m == 1).unwrap();
    let nan = forged(&bundle, "nan.relevo", "height.f32", &|b| {
        b[vertex * 4..vertex * 4 + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    });
    let fifo = forged(&bundle, "fifo.relevo", "height.f32", &|_| {});
    std::fs::remove_file(fifo.join("height.f32")).unwrap();
    let made = std::process::Command::new("mkfifo")
        .arg(fifo.join("height.f32"))
        .status()
        .unwrap();
    assert!(made.success());
    for (forgery, needles) in [
        (&cycle, ["clusters", "not a later node"]),
        (&bomb, ["atlas_000.png", "40000×40000"]),
        (&nan, ["height.f32", "is not a finite number"]),
        (&fifo, ["height.f32", "FIFO"]),
    ] {
        let message = match Scene::open(forgery) {
            Ok(_) => panic!("{} opened", forgery.display()),
            Err(e) => format!("{e:#}"),
        };
        for needle in needles {
            assert!(message.contains(needle), "{}: {message}", forgery.display());
        }
    }
}

/// The HUD's lines for a frame drawn with `settings` from `flight` over
/// `scene` (no pointer), one text.
fn hud_text(settings: &Settings, stats: &FrameStats, scene: &Scene, flight: &Flight) -> String {
    relevo_view::hud::lines(&relevo_view::hud::Readings {
        fps: 1.0,
        frame_ms: 1.0,
        settings,
        stats,
        scene: Some(scene),
        flight: Some(flight),
        pointer: None,
    })
    .join("\n")
}

/// The Grenoble sample region (Copernicus GLO-30-derived DEM, 1025² grid,
/// its drape derived from the heights) as a single-grid bundle and as a
/// pyramid in tiles of 64 cells (16² tiles at level 0, five levels), both
/// opened for the viewer.
fn grenoble_both(dir: &Path) -> (Scene, Scene) {
    let toml = repo("data/grenoble/REGION.toml");
    let single = prep_region(&toml, &dir.join("single.relevo"));
    let region = relevo::prep::region::RegionSpec::load(&toml).unwrap();
    let options = relevo::prep::tiled::TiledOptions {
        tile_cells: Some(64),
        force: false,
        resume: false,
    };
    let pyramid = relevo::prep::tiled::prep_tiled(&region, &dir.join("tiled.relevo"), options)
        .unwrap()
        .bundle;
    (
        Scene::open(&single).unwrap(),
        Scene::open(&pyramid).unwrap(),
    )
}

/// Views over Grenoble: the home view, a low pass along the valley and a
/// look straight down from above the middle.
fn grenoble_flights(scene: &Scene) -> Vec<Flight> {
    let mut flights = vec![Flight::home(scene)];
    let extent = scene.extent_m();
    for (x, y, above, heading, pitch) in [
        (0.3, 0.45, 300.0, 20.0, -12.0),
        (0.4, 0.6, 2500.0, 135.0, -70.0),
    ] {
        let mut f = Flight::home(scene);
        f.position.x = x * extent;
        f.position.y = y * extent;
        f.position.z = scene.ground_height(f.position.x, f.position.y).unwrap() + above;
        f.heading_deg = heading;
        f.pitch_deg = pitch;
        flights.push(f);
    }
    flights
}

/// A pyramid drawn in mesh mode with every tile the view needs (as
/// headless renders wait for them) is the single grid's mesh: the same
/// triangles, so the depth of every pixel equals the single grid's; the
/// colour differs only by where the drape comes from (each tile's own,
/// normals from each level's lattice).
#[test]
fn a_pyramids_mesh_has_the_single_grids_depth_pixel_for_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let (mut single, mut tiled) = grenoble_both(dir.path());
    let (device, queue) = lavapipe();
    for (k, flight) in grenoble_flights(&single).iter().enumerate() {
        for tau in [1.0, 4.0] {
            let settings = Settings {
                mode: TerrainMode::Mesh,
                tau_px: tau,
                texture: false,
                ..Default::default()
            };
            let shot = Shot::new(SIZE);
            let (a, sa) =
                render_once(&device, &queue, &mut single, flight, &settings, &shot).unwrap();
            let (b, sb) =
                render_once(&device, &queue, &mut tiled, flight, &settings, &shot).unwrap();
            assert_eq!(sa.triangles, sb.triangles, "view {k} τ={tau}");
            let differ = a.depth.iter().zip(&b.depth).filter(|(x, y)| x != y).count();
            assert_eq!(differ, 0, "view {k} τ={tau}: {differ} depths differ");
            let paging = sb.paging.unwrap();
            assert_eq!(paging.loading, 0, "view {k}");
            assert!(paging.leaves > 1, "view {k}: {paging:?}");
        }
    }
}

/// While tiles load — a flight whose frames never wait, with a cache of
/// a few tiles — no frame has a crack: looking down over the region with
/// the sky a colour nothing else uses, no pixel of any frame is sky; and
/// the tiles held besides those the view needs stay under the budget.
#[test]
fn a_pyramid_flown_while_tiles_load_never_shows_a_crack() {
    let dir = tempfile::tempdir().unwrap();
    let (_, mut tiled) = grenoble_both(dir.path());
    let (device, queue) = lavapipe();
    let tile_bytes = 65 * 65 * 17;
    let budget = 40 * tile_bytes;
    tiled.paged.as_mut().unwrap().set_budget(budget);
    let mut settings = Settings {
        mode: TerrainMode::Mesh,
        tau_px: 1.0,
        ..Default::default()
    };
    settings.raycast.sky = [255, 0, 255, 255];
    let mut renderer = relevo_view::gpu::Renderer::new(&device, &queue, &tiled, SIZE);
    let extent = tiled.extent_m();
    let mut flight = Flight::home(&tiled);
    let (mut frames, mut partial) = (0, 0);
    for step in 0..60 {
        let t = step as f64 / 60.0;
        flight.position.x = extent * (0.15 + 0.35 * t);
        flight.position.y = extent * (0.3 + 0.4 * (t * 6.0).sin().abs());
        flight.position.z = tiled
            .ground_height(flight.position.x, flight.position.y)
            .unwrap()
            + 1500.0
            - 1200.0 * t;
        flight.heading_deg = 360.0 * t;
        flight.pitch_deg = -75.0;
        let camera = flight.camera(&tiled, SIZE);
        let stats = renderer
            .render(&device, &queue, &mut tiled, &camera, &settings)
            .unwrap();
        let frame = renderer.targets.read(&device, &queue, false).unwrap();
        let sky = frame
            .rgba
            .chunks_exact(4)
            .filter(|p| p[..3] == [255, 0, 255])
            .count();
        assert_eq!(sky, 0, "frame {step}: {sky} sky pixels below the horizon");
        let paging = stats.paging.unwrap();
        partial += usize::from(paging.loading > 0);
        frames += 1;
        assert!(
            paging.resident_bytes <= budget + 64 * tile_bytes,
            "frame {step}: {paging:?}"
        );
    }
    let paging = tiled.paged.as_ref().unwrap().stats();
    assert!(
        partial >= 5,
        "{partial} of {frames} frames drawn while loading: {paging:?}"
    );
    assert!(paging.evicted_total > 0, "{paging:?}");
}

/// The raycast over a pyramid, whose distance bands read coarser levels
/// farther away (a level's cell at most 2 pixels on screen, one slice a
/// level cell, nearest samples), agrees with the full-resolution mesh
/// drawn through the same pyramid's tiles. A slice every level cell finds
/// the surface up to one slice past it, so the distance along the view
/// axis, in cells of the level the raycast read there, is within 0.75 of a
/// cell at the median and 1.5 at the 95th percentile; at most 2 % of the
/// pixels disagree on terrain or sky. The HUD says how its level windows
/// were read.
#[test]
fn a_pyramids_raycast_over_its_levels_agrees_with_its_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let (_, mut tiled) = grenoble_both(dir.path());
    let (device, queue) = lavapipe();
    let mesh = Settings {
        mode: TerrainMode::Mesh,
        tau_px: 0.0,
        morph: false,
        cull: false,
        ..Default::default()
    };
    let raycast = Settings {
        mode: TerrainMode::Raycast,
        ..Default::default()
    };
    let cell = tiled.grid.cell_size_m;
    for (k, mut flight) in grenoble_flights(&tiled).into_iter().enumerate() {
        flight.pitch_deg = flight.pitch_deg.max(-30.0);
        let shot = Shot::new(SIZE);
        let (m, _) = render_once(&device, &queue, &mut tiled, &flight, &mesh, &shot).unwrap();
        let (r, stats) =
            render_once(&device, &queue, &mut tiled, &flight, &raycast, &shot).unwrap();
        // The HUD says how the level windows were read.
        let reads = tiled.level_windows.as_ref().unwrap().reads();
        assert!(reads.waited >= 1, "view {k}: {reads:?}");
        let hud = hud_text(&raycast, &stats, &tiled, &flight);
        let line = format!(
            "level windows: {} read ahead, {} waited for ({} this frame)",
            reads.ahead, reads.waited, stats.level_windows_waited
        );
        assert!(hud.contains(&line), "view {k}: {hud}");
        let camera = flight.camera(&tiled, SIZE);
        let bands = relevo_core::pyramid::render::level_bands(
            &tiled.paged.as_ref().unwrap().pyramid,
            &camera,
            2.0,
        );
        let (errors, disagree) = depth_differences(&camera, &m.depth, &r.depth, |d| {
            let level = bands.iter().position(|band| band.until_m > d).unwrap_or(0);
            cell * (1u64 << level) as f64
        });
        let at = |q: f64| errors[((errors.len() - 1) as f64 * q) as usize];
        let pixels = (SIZE[0] * SIZE[1]) as usize;
        eprintln!(
            "view {k}: pyramid raycast vs mesh over {} terrain pixels: median {:.3}, p95 {:.3}, p99 {:.3} level cells; {disagree} of {pixels} disagree",
            errors.len(), at(0.5), at(0.95), at(0.99)
        );
        assert!(
            errors.len() > pixels / 4,
            "view {k}: {} terrain pixels",
            errors.len()
        );
        assert!(
            at(0.5) <= 0.75 && at(0.95) <= 1.5,
            "view {k}: median {}, p95 {}",
            at(0.5),
            at(0.95)
        );
        assert!(
            disagree * 50 <= pixels,
            "view {k}: {disagree} pixels disagree"
        );
    }
}
