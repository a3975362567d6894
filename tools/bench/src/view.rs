//! Viewer figures: frame time of every mode of `relevo-view`'s renderer on
//! the GPU it finds (lavapipe without one), measured from the start of a
//! frame until the GPU has finished it, over eight headings; with the
//! breakdown of the seed's tables 8.1/8.2 (raycast, colour and depth
//! upload, objects) and the comparison of table 3.1/8.3 (raycast against
//! each Z-buffer representation).

use crate::measure::{emit, median};
use anyhow::{Context, Result};
use relevo::prep::prep;
use relevo::prep::region::RegionSpec;
use relevo_core::bundle::{write_terrain_bundle, Crs};
use relevo_core::geo::GeoTransform;
use relevo_core::grid::{fractal_heights, HeightGrid};
use relevo_core::horizon::Arithmetic;
use relevo_core::zbuffer::{self, Representation};
use relevo_view::flight::Flight;
use relevo_view::gpu::{FrameStats, Renderer};
use relevo_view::headless::{device, wait_for_gpu};
use relevo_view::scene::Scene;
use relevo_view::settings::{Settings, TerrainMode, VegetationSelection};
use serde_json::json;
use std::path::Path;
use std::time::Instant;

/// Headings flown per figure, degrees.
pub(crate) const HEADINGS: [f64; 8] = [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0];

pub fn view(
    repo: &Path,
    data: &Path,
    runs: usize,
    max_side: usize,
    json_lines: bool,
) -> Result<()> {
    let scratch = crate::measure::tempfile_dir()?;
    let (device, queue, adapter) = device()?;
    emit(
        json_lines,
        json!({"bench": "view-adapter", "adapter": adapter}),
        format!("adapter: {adapter}"),
    );

    let bundles = bench_bundles(repo, data, &scratch, max_side)?;

    for (name, path, objects) in &bundles {
        let mut scene = Scene::open(path)?;
        let side = scene.frame.side;
        let home = Flight::home(&scene);
        for size in [[1280u32, 720u32], [1920, 1080]] {
            let mut renderer = Renderer::new(&device, &queue, &scene, size);
            let mut configs = terrain_configurations(side);
            // The vegetation, from the quadtree cut and, for comparison,
            // from the plain list.
            if scene.vegetation.is_some() {
                for mode in [TerrainMode::Mesh, TerrainMode::Raycast] {
                    for selection in [VegetationSelection::Quadtree, VegetationSelection::List] {
                        configs.push((
                            format!("{mode} + vegetation {selection}"),
                            Settings {
                                mode,
                                vegetation: selection,
                                ..Default::default()
                            },
                        ));
                    }
                }
            }
            // Table 8.1: with objects, the raycast's depth is uploaded too
            // (the bundle's vegetation is drawn with them).
            if let Some(placement) = objects {
                scene
                    .load_objects(placement)
                    .with_context(|| placement.display().to_string())?;
                for mode in [TerrainMode::Mesh, TerrainMode::Raycast] {
                    configs.push((
                        format!("{mode} + objects"),
                        Settings {
                            mode,
                            ..Default::default()
                        },
                    ));
                }
            }
            for (label, mut settings) in configs {
                settings.objects = label.ends_with("objects") || label.contains("vegetation");
                let (frame_ms, stats) = frame_time(
                    &device,
                    &queue,
                    &mut renderer,
                    &mut scene,
                    &home,
                    &settings,
                    size,
                    runs,
                )?;
                emit(
                    json_lines,
                    json!({"bench": "view", "bundle": name, "size": size, "config": label, "mode": settings.mode,
                           "frame_ms": frame_ms, "fps": 1e3 / frame_ms, "triangles": stats.triangles,
                           "object_triangles": stats.object_triangles, "impostors": stats.impostors,
                           "impostor_views": stats.impostor_views, "cut_ms": stats.cut_ms, "refine_ms": stats.refine_ms,
                           "mesh_upload_ms": stats.mesh_upload_ms, "raycast_ms": stats.raycast_ms,
                           "colour_upload_ms": stats.colour_upload_ms, "depth_upload_ms": stats.depth_upload_ms,
                           "runs": runs}),
                    format!(
                        "{name} {}×{} {label}: {frame_ms:.1} ms ({:.1} fps), {} primitives; refine {:.1}, raycast {:.1}, colour upload {:.1}, depth upload {:.1} ms",
                        size[0], size[1], 1e3 / frame_ms, stats.triangles, stats.refine_ms, stats.raycast_ms,
                        stats.colour_upload_ms, stats.depth_upload_ms
                    ),
                );
            }
            scene.objects = None;
        }
    }
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// Median time of one frame (CPU work, submission and the GPU finishing
/// it) over the eight headings, `runs` rounds after one warm-up round; the
/// figures of the last frame.
#[allow(clippy::too_many_arguments)]
fn frame_time(
    device: &relevo_view::gpu::Device,
    queue: &relevo_view::gpu::Queue,
    renderer: &mut Renderer,
    scene: &mut Scene,
    home: &Flight,
    settings: &Settings,
    size: [u32; 2],
    runs: usize,
) -> Result<(f64, FrameStats)> {
    let mut times = Vec::new();
    let mut stats = FrameStats::default();
    for round in 0..=runs {
        for heading in HEADINGS {
            let flight = Flight {
                heading_deg: heading,
                ..*home
            };
            let camera = flight.camera(scene, size);
            let start = Instant::now();
            stats = renderer.render(device, queue, scene, &camera, settings)?;
            wait_for_gpu(device)?;
            if round > 0 {
                times.push(start.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
    Ok((median(&times), stats))
}

/// The bundles the viewer is timed over: the sample regions (Olinda with
/// its objects) and, when `max_side` allows, a 4097² fractal terrain for
/// scale; each with its name and the objects to composite.
pub fn bench_bundles(
    repo: &Path,
    data: &Path,
    scratch: &Path,
    max_side: usize,
) -> Result<Vec<(&'static str, std::path::PathBuf, Option<std::path::PathBuf>)>> {
    let mut bundles = Vec::new();
    let olinda = scratch.join("olinda.relevo");
    prep(
        &RegionSpec::load(&repo.join("data/olinda/REGION.toml"))?,
        &olinda,
        true,
    )?;
    bundles.push((
        "olinda 129²",
        olinda,
        Some(repo.join("data/olinda/objects.geojson")),
    ));
    let grenoble_toml = scratch.join("grenoble.toml");
    let copernicus = data.join("dem/Copernicus_DSM_10_N45_00_E005_00_DEM.tif");
    std::fs::write(
        &grenoble_toml,
        format!("[dem]\nfiles = [{:?}]\n", copernicus.display().to_string()),
    )?;
    let grenoble = scratch.join("grenoble.relevo");
    prep(&RegionSpec::load(&grenoble_toml)?, &grenoble, true)?;
    bundles.push(("grenoble", grenoble, None));
    if max_side >= 4097 {
        let side = 4097;
        let grid = HeightGrid {
            side,
            heights: fractal_heights(side, 1),
            mask: vec![1; side * side],
            geotransform: GeoTransform::north_up(0.0, side as f64 * 30.0, 30.0, 30.0),
        };
        let crs = Crs {
            wkt: String::new(),
            epsg: None,
        };
        let fractal = write_terrain_bundle(
            &scratch.join("fractal.relevo"),
            "fractal",
            &grid,
            30.0,
            crs,
            true,
        )?;
        bundles.push(("fractal 4097²", fractal, None));
    }
    Ok(bundles)
}

/// The terrain's configurations: mesh at τ = 1 and 2 px, the raycast as it
/// is, in fixed point and with detailed bands, and the Z-buffer baselines on
/// grids they can hold.
fn terrain_configurations(side: usize) -> Vec<(String, Settings)> {
    let mut configs: Vec<(String, Settings)> = Vec::new();
    for tau in [1.0, 2.0] {
        configs.push((
            format!("mesh tau {tau}"),
            Settings {
                mode: TerrainMode::Mesh,
                tau_px: tau,
                ..Default::default()
            },
        ));
    }
    configs.push((
        "raycast".into(),
        Settings {
            mode: TerrainMode::Raycast,
            ..Default::default()
        },
    ));
    let mut fixed = Settings {
        mode: TerrainMode::Raycast,
        ..Default::default()
    };
    fixed.raycast.arithmetic = Arithmetic::Fixed;
    configs.push(("raycast fixed".into(), fixed));
    let mut bands = Settings {
        mode: TerrainMode::Raycast,
        ..Default::default()
    };
    bands.raycast.bands = relevo_view::settings::detailed_bands();
    configs.push(("raycast bands+sub".into(), bands));
    if side * side <= zbuffer::MAX_VERTICES {
        for r in Representation::ALL {
            configs.push((
                format!("zbuffer {} {r:?}", r.letter()),
                Settings {
                    mode: TerrainMode::ZBuffer(r),
                    ..Default::default()
                },
            ));
        }
    }
    configs
}
