//! `relevo-view bench`: frame times of a scripted flight over a bundle,
//! mode by mode, on whatever GPU the machine has (Mesa's lavapipe without
//! one). The flight — a takeoff, a low pass following the ground, a turn,
//! a climb — advances by a fixed step a frame, so every machine draws the
//! same frames. With one frame in flight (the default) each frame is
//! timed from the start of its CPU work until the GPU has finished it; with
//! two, the next frame is cut, refined and uploaded while the GPU draws the
//! current one (the LP chapter's refinement beside rendering), and a frame
//! takes the time between two frames finished. Nothing here needs GDAL, so
//! the binary runs on a machine that has a GPU and nothing else.

use crate::flight::{Controls, Flight};
use crate::gpu::{frame_bytes_per_pixel, Device, FrameStats, Queue, Renderer};
use crate::headless::{device, wait_for_gpu, wait_for_submission};
use crate::scene::Scene;
use crate::settings::{Settings, TerrainMode, VegetationSelection};
use anyhow::{bail, Context, Result};
use relevo_core::bundle::{Crs, GridInfo};
use relevo_core::geo::GeoTransform;
use relevo_core::grid::HeightGrid;
use relevo_core::lp::ErrorMetric;
use relevo_core::{pyramid, scene};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// The bundle to fly over.
    #[arg(required_unless_present = "fractal")]
    pub bundle: Option<PathBuf>,
    /// Instead of a bundle: write relevo-core's fractal heightfield of this
    /// side (2^n + 1 from 17, e.g. 16385: the heights of the pyramid
    /// benchmark's input, 10 m cells) as a pyramid of 512-cell tiles (a
    /// quarter of a smaller fractal's side) into a scratch folder beside
    /// the system's temporary files, fly over it, and remove it — the
    /// benchmark's pyramid on a machine that has a GPU and no GDAL.
    #[arg(long, conflicts_with = "bundle", value_name = "SIDE")]
    pub fractal: Option<usize>,
    /// Frame size, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = scene::parse_size)]
    pub size: [u32; 2],
    /// Frames in each of the flight's four legs (takeoff, low pass, turn,
    /// climb).
    #[arg(long, default_value_t = 60)]
    pub frames: u32,
    /// Objects to composite too: a GeoJSON placement file (adds the
    /// modes with objects).
    #[arg(long)]
    pub objects: Option<PathBuf>,
    /// One JSON record a line (the adapter, then one a configuration)
    /// instead of text.
    #[arg(long)]
    pub json: bool,
    /// Frames in flight: 1 waits for the GPU to finish each frame before
    /// the next is prepared; 2 prepares the next frame (cut, refinement,
    /// vertices, uploads) while the GPU draws the current one.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub in_flight: u8,
}

/// Seconds of flight a frame advances: the same path at any frame rate.
const STEP_S: f64 = 1.0 / 30.0;

/// Height above the ground of the low pass, metres.
const LOW_PASS_M: f64 = 60.0;

/// One configuration's figures over the flight.
#[derive(Debug, Serialize)]
pub struct Record {
    pub bench: &'static str,
    pub bundle: String,
    pub adapter: String,
    pub config: String,
    pub size: [u32; 2],
    pub frames: usize,
    /// Frames in flight: 1, each frame drawn before the next is prepared;
    /// 2, the next prepared while the GPU draws the current one.
    pub in_flight: u8,
    /// Frame time percentiles (nearest rank), milliseconds.
    pub frame_ms_p50: f64,
    pub frame_ms_p95: f64,
    pub frame_ms_p99: f64,
    pub frame_ms_max: f64,
    pub fps_p50: f64,
    /// Terrain triangles a frame, median and largest.
    pub triangles_p50: usize,
    pub triangles_max: usize,
    /// Vegetation impostors a frame (quadtree clusters and single objects),
    /// median and largest.
    pub impostors_p50: usize,
    pub impostors_max: usize,
    /// Uploads a frame, medians, milliseconds: the refined mesh's vertex
    /// buffer; the raycast's colour and depth.
    pub mesh_upload_ms_p50: f64,
    pub raycast_upload_ms_p50: f64,
    /// The CPU work a frame, medians, milliseconds.
    pub refine_ms_p50: f64,
    pub raycast_ms_p50: f64,
    pub cut_ms_p50: f64,
    /// Frames of a pyramid drawn while a tile they wanted was still
    /// loading (coarser tiles drawn in its place; no frame waits): none
    /// for a single-grid bundle, which is mapped whole.
    pub paging_stalls: u64,
    /// A pyramid's tiles read and dropped during the flight, the most
    /// resident at once and their memory, MB, and tile drapes uploaded.
    pub tiles_loaded: u64,
    pub tiles_evicted: u64,
    pub tiles_resident_max: usize,
    pub tile_cache_mb_max: f64,
    pub tile_uploads: u64,
    /// A pyramid's raycast: frames that waited for a level window to be
    /// read (the rest found theirs held or read ahead), and the windows
    /// read ahead beside the frames.
    pub raycast_window_waits: usize,
    pub raycast_windows_ahead: u64,
    /// The flight's first and last camera (`relevo render --camera`).
    pub start_camera: String,
    pub end_camera: String,
}

/// Run the benchmark and print its records.
pub fn run(a: BenchArgs) -> Result<()> {
    if a.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let raycast_bytes = frame_bytes_per_pixel(true, true);
    relevo_core::memory::check(
        &format!("a {}×{} frame", a.size[0], a.size[1]),
        u64::from(a.size[0]) * u64::from(a.size[1]),
        raycast_bytes,
        "choose a smaller --size",
    )?;
    let (bundle, name, scratch) = match (&a.bundle, a.fractal) {
        (Some(bundle), _) => (bundle.clone(), bundle.display().to_string(), None),
        (None, Some(side)) => {
            let scratch = tempfile::Builder::new()
                .prefix("relevo-view-bench-")
                .tempdir()
                .context("making a scratch folder for the fractal")?;
            let bundle = write_fractal(side, scratch.path())?;
            (bundle, format!("fractal {side}²"), Some(scratch))
        }
        (None, None) => bail!("give a bundle to fly over, or --fractal SIDE"),
    };
    let result = fly_all(&a, &bundle, &name);
    drop(scratch);
    result
}

/// relevo-core's fractal of `side`² (seed 1, 10 m cells, north-up in UTM
/// 31N's numbers as the pyramid benchmark writes it) as a pyramid of
/// [`pyramid::DEFAULT_TILE_CELLS`]-cell tiles (a quarter of the side when
/// that is less, at least 16 cells) in `dir`, each pass's progress on
/// stderr.
fn write_fractal(side: usize, dir: &Path) -> Result<PathBuf> {
    if !(side >= 17 && (side - 1).is_power_of_two()) {
        bail!("--fractal {side}: the side must be 2^n + 1, at least 17 (e.g. 4097, 16385)");
    }
    let cell = 10.0;
    // The generator's f64 working heights, the f32 heights and the mask.
    relevo_core::memory::check(
        &format!("the {side}² fractal"),
        (side * side) as u64,
        13,
        "choose a smaller --fractal side",
    )?;
    let grid = HeightGrid {
        side,
        heights: relevo_core::grid::fractal_heights(side, 1),
        mask: vec![1; side * side],
        geotransform: GeoTransform::north_up(600_000.0, 5_100_000.0, cell, cell),
    };
    let description = pyramid::PyramidDescription {
        region: format!("fractal {side}²"),
        crs: Crs {
            wkt: String::new(),
            epsg: None,
        },
        grid: GridInfo::of(&grid, cell, 1.0).context("the fractal holds no data")?,
        inputs: Vec::new(),
        parameters: Default::default(),
    };
    let options = pyramid::WriteOptions {
        tile_cells: pyramid::DEFAULT_TILE_CELLS.min((side - 1) / 4).max(16),
        build: pyramid::BuildOptions {
            metric: ErrorMetric::default(),
            cell_size_m: cell,
            drape: true,
        },
        force: false,
        resume: false,
    };
    let start = Instant::now();
    let last = std::sync::Mutex::new("");
    let bundle = pyramid::write_pyramid(
        &dir.join("fractal.relevo"),
        &grid,
        description,
        options,
        &|p| {
            // One line a pass, when it starts.
            if let Ok(mut last) = last.lock() {
                if *last != p.pass {
                    *last = p.pass;
                    eprintln!(
                        "fractal {side}²: {} ({} tiles), {:.0} s in",
                        p.pass,
                        p.total,
                        start.elapsed().as_secs_f64()
                    );
                }
            }
        },
    )?;
    eprintln!(
        "fractal {side}²: pyramid written in {:.0} s",
        start.elapsed().as_secs_f64()
    );
    Ok(bundle)
}

/// Fly every configuration over `bundle` (labelled `name`) and print the
/// records.
fn fly_all(a: &BenchArgs, bundle: &Path, name: &str) -> Result<()> {
    let mut scene = Scene::open(bundle)?;
    if let Some(path) = &a.objects {
        scene
            .load_objects(path)
            .with_context(|| path.display().to_string())?;
    }
    let (device, queue, adapter) = device()?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({"bench": "view-adapter", "adapter": adapter})
        );
    } else {
        println!("{name}: {adapter}, {}×{}", a.size[0], a.size[1]);
    }
    let mut renderer = Renderer::new(&device, &queue, &scene, a.size);
    for (k, (config, settings)) in configurations(&scene, a.objects.is_some())
        .into_iter()
        .enumerate()
    {
        if k > 0 && scene.paged.is_some() {
            // A pyramid flies each mode from an empty cache, paging as it goes.
            scene = Scene::open(bundle)?;
            if let Some(path) = &a.objects {
                scene.load_objects(path)?;
            }
            renderer = Renderer::new(&device, &queue, &scene, a.size);
        }
        let record = fly(
            &device,
            &queue,
            &mut renderer,
            &mut scene,
            &settings,
            a,
            Labels {
                bundle: name,
                adapter: &adapter,
                config: &config,
            },
        )?;
        if a.json {
            println!("{}", serde_json::to_string(&record)?);
        } else {
            println!(
                "  {config}: p50 {:.1} ms ({:.0} fps), p95 {:.1}, p99 {:.1}, max {:.1}; {} triangles, {} impostors",
                record.frame_ms_p50,
                record.fps_p50,
                record.frame_ms_p95,
                record.frame_ms_p99,
                record.frame_ms_max,
                record.triangles_p50,
                record.impostors_p50
            );
        }
    }
    Ok(())
}

/// The modes flown: the mesh at τ = 1 and 2 px and the raycast; with the
/// bundle's vegetation, both modes with relevo-core's quadtree cut and the
/// mesh with the plain list; with objects, both modes with them.
pub fn configurations(scene: &Scene, objects: bool) -> Vec<(String, Settings)> {
    let plain = |mode: TerrainMode| Settings {
        mode,
        objects: false,
        ..Default::default()
    };
    let mut configs = vec![
        (
            "mesh tau 1".to_string(),
            Settings {
                tau_px: 1.0,
                ..plain(TerrainMode::Mesh)
            },
        ),
        (
            "mesh tau 2".to_string(),
            Settings {
                tau_px: 2.0,
                ..plain(TerrainMode::Mesh)
            },
        ),
        ("raycast".to_string(), plain(TerrainMode::Raycast)),
    ];
    if scene.vegetation.is_some() {
        for (mode, selection) in [
            (TerrainMode::Mesh, VegetationSelection::Quadtree),
            (TerrainMode::Raycast, VegetationSelection::Quadtree),
            (TerrainMode::Mesh, VegetationSelection::List),
        ] {
            configs.push((
                format!("{mode} + vegetation {selection}"),
                Settings {
                    objects: true,
                    vegetation: selection,
                    ..plain(mode)
                },
            ));
        }
    }
    if objects {
        for mode in [TerrainMode::Mesh, TerrainMode::Raycast] {
            configs.push((
                format!("{mode} + objects"),
                Settings {
                    objects: true,
                    ..plain(mode)
                },
            ));
        }
    }
    configs
}

/// The four legs' controls, one a leg, and whether the leg follows the
/// ground.
const LEGS: [(Controls, bool); 4] = [
    // Takeoff: climbing while moving off.
    (
        Controls {
            forward: 0.5,
            turn: 0.0,
            climb: 1.0,
            look: 0.0,
        },
        false,
    ),
    // A low pass at full speed, following the ground.
    (
        Controls {
            forward: 1.0,
            turn: 0.0,
            climb: 0.0,
            look: 0.0,
        },
        true,
    ),
    // A turn to the right.
    (
        Controls {
            forward: 0.5,
            turn: 1.0,
            climb: 0.0,
            look: 0.0,
        },
        true,
    ),
    // A climb, looking a little down.
    (
        Controls {
            forward: 1.0,
            turn: 0.0,
            climb: 1.0,
            look: 0.3,
        },
        false,
    ),
];

/// What names a record.
struct Labels<'a> {
    bundle: &'a str,
    adapter: &'a str,
    config: &'a str,
}

/// Fly the four legs from the home view with `settings`, one warm-up frame
/// first, and measure every frame.
#[allow(clippy::too_many_arguments)]
fn fly(
    device: &Device,
    queue: &Queue,
    renderer: &mut Renderer,
    scene: &mut Scene,
    settings: &Settings,
    a: &BenchArgs,
    labels: Labels,
) -> Result<Record> {
    let mut flight = Flight::home(scene);
    let height = a.size[1];
    let start_camera = flight.pose(scene, height).to_string();
    renderer.forget_last_frame();
    renderer.render(
        device,
        queue,
        scene,
        &flight.camera(scene, a.size),
        settings,
    )?;
    wait_for_gpu(device)?;
    let mut times = Vec::new();
    let mut stats: Vec<FrameStats> = Vec::new();
    // When the last frame was finished: a frame's time runs from there.
    let mut finished = Instant::now();
    let paging_of = |scene: &Scene| scene.paged.as_ref().map(|p| p.stats()).unwrap_or_default();
    let paging_before = paging_of(scene);
    let ahead_of = |scene: &Scene| scene.level_windows.as_ref().map_or(0, |w| w.reads().ahead);
    let ahead_before = ahead_of(scene);
    for (controls, follow) in LEGS {
        if follow && !flight.follow_terrain {
            // Down to the low pass's height, then keep it.
            if let Some(ground) = scene.ground_height(flight.position.x, flight.position.y) {
                flight.position.z = ground + LOW_PASS_M;
            }
        }
        flight.follow_terrain = follow;
        for _ in 0..a.frames {
            flight.fly(scene, &controls, STEP_S);
            let camera = flight.camera(scene, a.size);
            let previous = renderer.last_submission();
            let frame = renderer.render(device, queue, scene, &camera, settings)?;
            stats.push(frame);
            if a.in_flight == 1 {
                wait_for_gpu(device)?;
            } else if let Some(previous) = previous.filter(|_| stats.len() > 1) {
                // The previous frame, drawn while this one was prepared.
                wait_for_submission(device, previous)?;
            } else {
                // The flight's first frame: none of its frames finished yet.
                continue;
            }
            times.push(finished.elapsed().as_secs_f64() * 1e3);
            finished = Instant::now();
        }
    }
    if a.in_flight == 2 {
        // The last frame, which nothing was prepared beside.
        wait_for_gpu(device)?;
        times.push(finished.elapsed().as_secs_f64() * 1e3);
    }
    let p50 = |values: Vec<f64>| percentile(values, 50.0);
    let field = |f: fn(&FrameStats) -> f64| p50(stats.iter().map(f).collect());
    let count = |f: fn(&FrameStats) -> usize| {
        let values: Vec<f64> = stats.iter().map(|s| f(s) as f64).collect();
        (
            percentile(values.clone(), 50.0) as usize,
            percentile(values, 100.0) as usize,
        )
    };
    let (triangles_p50, triangles_max) = count(|s| s.triangles);
    let (impostors_p50, impostors_max) = count(|s| s.impostors);
    let frame_ms_p50 = percentile(times.clone(), 50.0);
    let paging = paging_of(scene);
    Ok(Record {
        bench: "view-flight",
        bundle: labels.bundle.to_string(),
        adapter: labels.adapter.to_string(),
        config: labels.config.to_string(),
        size: a.size,
        frames: times.len(),
        in_flight: a.in_flight,
        frame_ms_p50,
        frame_ms_p95: percentile(times.clone(), 95.0),
        frame_ms_p99: percentile(times.clone(), 99.0),
        frame_ms_max: percentile(times, 100.0),
        fps_p50: 1e3 / frame_ms_p50,
        triangles_p50,
        triangles_max,
        impostors_p50,
        impostors_max,
        mesh_upload_ms_p50: field(|s| s.mesh_upload_ms),
        raycast_upload_ms_p50: field(|s| s.colour_upload_ms + s.depth_upload_ms),
        refine_ms_p50: field(|s| s.refine_ms),
        raycast_ms_p50: field(|s| s.raycast_ms),
        cut_ms_p50: field(|s| s.cut_ms),
        paging_stalls: paging.stalled_frames - paging_before.stalled_frames,
        tiles_loaded: paging.loaded_total - paging_before.loaded_total,
        tiles_evicted: paging.evicted_total - paging_before.evicted_total,
        tiles_resident_max: stats
            .iter()
            .filter_map(|s| s.paging.map(|p| p.resident))
            .max()
            .unwrap_or(0),
        tile_cache_mb_max: stats
            .iter()
            .filter_map(|s| s.paging.map(|p| p.resident_bytes as f64 / 1e6))
            .fold(0.0, f64::max),
        tile_uploads: stats.iter().map(|s| u64::from(s.tile_uploads)).sum(),
        raycast_window_waits: stats.iter().filter(|s| s.level_windows_waited > 0).count(),
        raycast_windows_ahead: ahead_of(scene) - ahead_before,
        start_camera,
        end_camera: flight.pose(scene, height).to_string(),
    })
}

/// The nearest-rank `p`-th percentile of `values` (0 for none).
fn percentile(mut values: Vec<f64>, p: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    let rank = ((p / 100.0) * values.len() as f64).ceil().max(1.0) as usize;
    values[rank.min(values.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::percentile;

    #[test]
    fn percentiles_take_the_nearest_rank() {
        let values: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(values.clone(), 50.0), 50.0);
        assert_eq!(percentile(values.clone(), 95.0), 95.0);
        assert_eq!(percentile(values.clone(), 99.0), 99.0);
        assert_eq!(percentile(values, 100.0), 100.0);
        assert_eq!(percentile(vec![3.0, 1.0, 2.0], 50.0), 2.0);
        assert_eq!(percentile(Vec::new(), 50.0), 0.0);
    }
}
