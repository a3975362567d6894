//! Raycast figures: milliseconds per frame for each configuration of the
//! floating-horizon renderer, level and pitched, with an image-quality
//! figure beside each time, and in the same run the classic voxel-space
//! loop as the baseline and the time to merely write a frame as the memory
//! floor.

use crate::measure::{emit, median, srtm_padded};
use anyhow::Result;
use rayon::prelude::*;
use relevo_core::bundle::Bundle;
use relevo_core::camera::Camera;
use relevo_core::grid::fractal_heights;
use relevo_core::horizon::{
    self, Arithmetic, ColorSource, DistanceBand, RaycastFrame, RaycastMode, RenderOptions, Terrain,
};
use serde_json::json;
use std::path::Path;
use std::time::Instant;

/// Headings each configuration is timed from.
const HEADINGS: usize = 8;

/// A terrain to fly over: name, side, heights, mask, cell size, and the
/// drape of a bundle (without one, a hillshaded height ramp by vertex).
struct Grid {
    name: String,
    side: usize,
    heights: Vec<f32>,
    mask: Vec<u8>,
    cell_m: f64,
    drape: Option<ColorSource>,
    /// The highest height, metres (the cameras fly 100 m above it).
    top_m: f64,
}

/// The highest of `heights`, metres.
fn highest_m(heights: &[f32]) -> f64 {
    heights.iter().copied().fold(f32::MIN, f32::max) as f64
}

/// Degrees the camera turns from one timed frame to the next: a viewer
/// turning at 30°/s and 60 frames a second. Each heading's frames are a
/// short flight, so that consecutive frames share most of what they read,
/// as a viewer's do; the first frame after the jump to a new heading is
/// timed apart (see [`Timing`]).
const TURN_PER_FRAME_DEG: f64 = 0.5;

/// The camera of heading `k`, frame `j` of its flight: from the grid's
/// centre, 100 m above its highest point, turned by `j` ×
/// [`TURN_PER_FRAME_DEG`], looking down either by the projection-plane
/// shift (incl at 70 % of the height, pitch 0) or by a real pitch (centred
/// plane).
fn camera(grid: &Grid, k: usize, j: usize, size: [u32; 2], pitch_deg: f64) -> Camera {
    let extent = (grid.side - 1) as f64 * grid.cell_m;
    let incl = if pitch_deg == 0.0 { 0.7 } else { 0.5 };
    Camera {
        position: glam::DVec3::new(extent * 0.5, extent * 0.5, grid.top_m + 100.0),
        heading_deg: k as f64 * 360.0 / HEADINGS as f64 + j as f64 * TURN_PER_FRAME_DEG,
        pitch_deg,
        incl_px: size[1] as f64 * incl,
        fov_x_deg: 60.0,
        width: size[0],
        height: size[1],
        near_m: grid.cell_m,
        far_m: 1024.0 * grid.cell_m,
    }
}

/// The classic voxel-space loop as published by S. Macke
/// (github.com/s-macke/VoxelSpace, after NovaLogic's Comanche, 1992): lines
/// parallel to the screen from front to back, the step growing by 0.005
/// cell per line, each column drawn as a vertical line up from its y-buffer
/// into a row-major RGBA image; nearest samples, no depth. Re-implemented
/// from that description for this comparison; `threads` column ranges are
/// drawn in parallel, each into its own row-major strip.
struct ClassicVoxelSpace {
    strips: Vec<Vec<u32>>,
}

impl ClassicVoxelSpace {
    fn render(&mut self, grid: &Grid, colours: &[u32], camera: &Camera, threads: usize) {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let strip_w = w.div_ceil(threads);
        self.strips.resize(threads, Vec::new());
        let heading = camera.heading_deg.to_radians();
        let (sin, cos) = heading.sin_cos();
        let d = camera.plane_distance_px();
        let horizon = h as f64 - camera.incl_px;
        let half = (camera.fov_x_deg.to_radians() / 2.0).tan();
        let (ex, ey) = (
            camera.position.x / grid.cell_m,
            camera.position.y / grid.cell_m,
        );
        let last = (grid.side - 1) as f64;
        let far = camera.far_m / grid.cell_m;
        self.strips
            .par_iter_mut()
            .enumerate()
            .for_each(|(t, strip)| {
                let first = t * strip_w;
                let width = strip_w.min(w.saturating_sub(first));
                strip.clear();
                strip.resize(width * h, 0);
                let mut y_buffer = vec![h as f64; width];
                let (mut z, mut dz) = (1.0f64, 1.0f64);
                while z < far {
                    // The slice's left end and the step between columns, in cells.
                    let (fx, fy) = (ex + sin * z, ey + cos * z);
                    let across = half * z * 2.0 / w as f64;
                    let (mut px, mut py) = (
                        fx - cos * half * z + cos * across * (first as f64 + 0.5),
                        fy + sin * half * z - sin * across * (first as f64 + 0.5),
                    );
                    let scale = d / (z * grid.cell_m);
                    for (i, top) in y_buffer.iter_mut().enumerate() {
                        let (c, r) = ((px + 0.5).floor(), (last - py + 0.5).floor());
                        px += cos * across;
                        py -= sin * across;
                        if c < 0.0 || r < 0.0 || c > last || r > last {
                            continue;
                        }
                        let v = r as usize * grid.side + c as usize;
                        let on_screen =
                            (camera.position.z - grid.heights[v] as f64) * scale + horizon;
                        if on_screen < *top {
                            let from = on_screen.max(0.0) as usize;
                            for row in from..(*top as usize).min(h) {
                                strip[row * width + i] = colours[v];
                            }
                            *top = on_screen.max(0.0);
                        }
                    }
                    z += dz;
                    dz += 0.005;
                }
            });
    }
}

/// Raycast figures: each configuration at 1920×1080 and 1280×720, far 1024
/// cells, the median over 8 headings' flights of `runs` frames (and of
/// their first frames, after the jump to the heading), with its PSNR against the
/// full-resolution level or pitched render, beside the classic loop and the
/// frame write floor.
/// `grid` keeps only the grids whose name contains it, `size` (e.g.
/// `1920x1080`) only that frame size, `mode` only the configurations whose
/// name contains it; `bundle` adds a bundle's terrain with its drape (what
/// `relevo render` and the viewer draw: colours from the drape image).
pub fn render(
    data: &Path,
    runs: usize,
    json_lines: bool,
    grid: Option<&str>,
    size: Option<&str>,
    mode: Option<&str>,
    bundle: Option<&Path>,
) -> Result<()> {
    let sizes: Vec<[u32; 2]> = [[1920u32, 1080], [1280, 720]]
        .into_iter()
        .filter(|[w, h]| size.is_none_or(|s| s == format!("{w}x{h}")))
        .collect();
    if sizes.is_empty() {
        anyhow::bail!(
            "--size {}: the sizes are 1920x1080 and 1280x720",
            size.unwrap_or("")
        );
    }
    let mut grids = bench_grids(data, grid, bundle)?;
    let configs = configurations();
    let threads = rayon::current_num_threads();
    for grid in &mut grids {
        let drape = grid.drape.take();
        let shaded = drape.is_none();
        let mut terrain = Terrain::new(grid.side, grid.cell_m, &grid.heights, &grid.mask, drape);
        if shaded {
            terrain = terrain.with_hillshade(315.0, 40.0);
        }
        let grid = &*grid;
        let shade = terrain_colours(&terrain, grid);
        for &size in &sizes {
            let mut renderer = horizon::Raycaster::default();
            // The reference frames of each heading and pitch.
            let mut references: Vec<(f64, Vec<RaycastFrame>)> = Vec::new();
            for (name, options, pitch) in &configs {
                let mut timing = Timing::default();
                let mut quality = Vec::new();
                let reference = references.iter().position(|(p, _)| p == pitch);
                let shown = mode.is_none_or(|part| {
                    // A whole name picks that one; otherwise a part of names.
                    if configs.iter().any(|c| c.0 == part) {
                        *name == part
                    } else {
                        name.contains(part)
                    }
                });
                if !shown && reference.is_some() {
                    continue;
                }
                let mut frames = Vec::new();
                for k in 0..HEADINGS {
                    let flight = |j| camera(grid, k, j, size, *pitch);
                    let mut draw = |cam: &Camera| {
                        renderer.render(&terrain, cam, options)?;
                        anyhow::Ok(())
                    };
                    if shown {
                        timing.fly(runs, flight, &mut draw)?;
                    } else {
                        // A reference left out still gives the others their
                        // PSNR (the flight's last frame), untimed.
                        draw(&flight(runs))?;
                    }
                    let frame = renderer.frame();
                    match reference {
                        Some(r) => quality.push(frame.psnr_db(&references[r].1[k])),
                        None => frames.push(frame.clone()),
                    }
                }
                if reference.is_none() {
                    references.push((*pitch, frames));
                }
                if !shown {
                    continue;
                }
                let (ms, after_jump_ms) = timing.medians();
                // The worst heading's PSNR (infinite: the same image).
                let psnr_db = quality.iter().copied().fold(f64::INFINITY, f64::min);
                // The reference itself, its PSNR in dB, or "equal".
                let psnr_json = match reference {
                    None => json!("reference"),
                    Some(_) if psnr_db.is_finite() => json!(psnr_db),
                    Some(_) => json!("equal"),
                };
                let psnr_text = psnr_json.as_f64().map_or_else(
                    || psnr_json.as_str().unwrap_or_default().to_string(),
                    |db| format!("{db:.1} dB"),
                );
                emit(
                    json_lines,
                    json!({"bench": "render", "grid": grid.name, "mode": name, "width": size[0],
                           "height": size[1], "far": 1024, "pitch_deg": pitch, "threads": threads,
                           "ms": ms, "after_jump_ms": after_jump_ms,
                           "psnr_db": psnr_json}),
                    format!(
                        "{:>15} {}×{} {name:>36}: {ms:7.2} ms/frame ({after_jump_ms:5.2} after a jump), PSNR {}",
                        grid.name,
                        size[0],
                        size[1],
                        psnr_text
                    ),
                );
            }
            if mode.is_none_or(|part| FRAME_WRITE.contains(part)) {
                frame_write_floor(grid, &renderer, size, runs, json_lines)?;
            }
            for threads in [1, 2] {
                if mode.is_some_and(|part| !"classic voxel space".contains(part)) {
                    continue;
                }
                let mut classic = ClassicVoxelSpace { strips: Vec::new() };
                let mut timing = Timing::default();
                for k in 0..HEADINGS {
                    let flight = |j| camera(grid, k, j, size, 0.0);
                    timing.fly(runs, flight, |cam| {
                        classic.render(grid, &shade, cam, threads);
                        Ok(())
                    })?;
                }
                let (ms, after_jump_ms) = timing.medians();
                emit(
                    json_lines,
                    json!({"bench": "render", "grid": grid.name, "mode": "classic voxel space",
                           "threads": threads, "width": size[0], "height": size[1], "far": 1024,
                           "ms": ms, "after_jump_ms": after_jump_ms}),
                    format!(
                        "{:>15} {}×{} {:>36}: {ms:7.2} ms/frame ({after_jump_ms:5.2} after a jump; {threads} thread{}, no depth)",
                        grid.name,
                        size[0],
                        size[1],
                        "classic voxel space (s-macke)",
                        if threads == 1 { "" } else { "s" }
                    ),
                );
            }
        }
    }
    Ok(())
}

/// RaycastFrame times of one configuration over the headings' flights.
#[derive(Default)]
struct Timing {
    /// Every flight frame after the first, milliseconds.
    flight_ms: Vec<f64>,
    /// Each heading's first frame, drawn after the jump from the last
    /// heading (45°, or from the configuration before), milliseconds.
    after_jump_ms: Vec<f64>,
}

impl Timing {
    /// Time `draw` over frames 0..=`runs` of one heading's flight, frame
    /// j seen by `flight(j)` (made before its timing starts).
    fn fly(
        &mut self,
        runs: usize,
        flight: impl Fn(usize) -> Camera,
        mut draw: impl FnMut(&Camera) -> Result<()>,
    ) -> Result<()> {
        for j in 0..=runs {
            let camera = flight(j);
            let start = Instant::now();
            draw(&camera)?;
            let ms = start.elapsed().as_secs_f64() * 1e3;
            if j == 0 {
                self.after_jump_ms.push(ms);
            } else {
                self.flight_ms.push(ms);
            }
        }
        Ok(())
    }

    /// The medians of the flight's frames and of the first frames after a
    /// jump.
    fn medians(&self) -> (f64, f64) {
        (median(&self.flight_ms), median(&self.after_jump_ms))
    }
}

/// The name of the memory floor's figure.
const FRAME_WRITE: &str = "frame write floor";

/// The memory floor under every configuration: milliseconds to write
/// `frame`'s colour and depth once (4 + 4 bytes a pixel, in its column
/// tiles, tiles in parallel on the renderer's threads), nothing computed —
/// the median over `runs` × [`HEADINGS`] writes.
fn frame_write_ms(mut frame: RaycastFrame, runs: usize) -> f64 {
    let tile = horizon::TILE_COLUMNS * frame.height;
    let mut times = Vec::new();
    for run in 0..runs * HEADINGS {
        let start = Instant::now();
        frame
            .rgba
            .par_chunks_mut(tile)
            .zip(frame.depth.par_chunks_mut(tile))
            .for_each(|(colour, depth)| {
                colour.fill(run as u32);
                depth.fill(run as f32);
            });
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    std::hint::black_box(&frame);
    median(&times)
}

/// The raycaster's own colour of every vertex (hillshaded height ramp), row
/// by row, for the classic loop to draw the same picture.
fn terrain_colours(terrain: &Terrain, grid: &Grid) -> Vec<u32> {
    let last = (grid.side - 1) as f64;
    (0..grid.side * grid.side)
        .map(|i| {
            let (c, r) = ((i % grid.side) as f64, (i / grid.side) as f64);
            terrain.color(c * grid.cell_m, (last - r) * grid.cell_m, false, 0)
        })
        .collect()
}

/// The grids to time: the fractal 4097² and srtm_ref 1025² (both shaded),
/// and a bundle's terrain with its drape when given; `grid` keeps those
/// whose name contains it.
fn bench_grids(data: &Path, grid: Option<&str>, bundle: Option<&Path>) -> Result<Vec<Grid>> {
    let wanted = |name: &str| grid.is_none_or(|part| name.contains(part));
    let mut grids = Vec::new();
    if wanted("fractal 4097²") {
        let heights = fractal_heights(4097, 1);
        grids.push(Grid {
            name: "fractal 4097²".into(),
            side: 4097,
            top_m: highest_m(&heights),
            heights,
            mask: vec![1u8; 4097 * 4097],
            cell_m: 30.0,
            drape: None,
        });
    }
    if wanted("srtm_ref 1025²") {
        let srtm = srtm_padded(data)?;
        grids.push(Grid {
            name: "srtm_ref 1025²".into(),
            side: srtm.side,
            top_m: highest_m(&srtm.heights),
            heights: srtm.heights,
            mask: srtm.mask,
            cell_m: 90.0,
            drape: None,
        });
    }
    if let Some(path) = bundle {
        let bundle = Bundle::open(path)?;
        let frame = bundle.frame();
        let name = path.file_stem().map_or_else(
            || "bundle".into(),
            |stem| stem.to_string_lossy().into_owned(),
        );
        let drape = bundle.drape()?.and_then(|d| d.color_source(&frame));
        anyhow::ensure!(
            drape.is_some(),
            "{}: the bundle has no drape",
            path.display()
        );
        let name = format!("{name} {}² (drape)", frame.side);
        if wanted(&name) {
            let heights = bundle.heights()?;
            grids.push(Grid {
                name,
                side: frame.side,
                top_m: highest_m(&heights),
                heights: heights.to_vec(),
                mask: bundle.mask()?.to_vec(),
                cell_m: frame.cell_size_m,
                drape,
            });
        }
    }
    if grids.is_empty() {
        anyhow::bail!(
            "--grid {}: the grids are fractal, srtm and a --bundle's name",
            grid.unwrap_or("")
        );
    }
    Ok(grids)
}

/// The configurations timed, as (name, options, pitch): the first of each
/// pitch is its reference.
fn configurations() -> Vec<(&'static str, RenderOptions, f64)> {
    let band = |spc: f64, subvoxel: bool| {
        vec![DistanceBand {
            until_m: f64::INFINITY,
            slices_per_cell: spc,
            subvoxel,
        }]
    };
    // (name, options, pitch): the first of each pitch is its reference.
    vec![
        ("raycast", RenderOptions::default(), 0.0),
        (
            "raycast, growing steps",
            RenderOptions {
                grow_steps: true,
                ..Default::default()
            },
            0.0,
        ),
        (
            "raycast, 16.16 fixed point",
            RenderOptions {
                arithmetic: Arithmetic::Fixed,
                ..Default::default()
            },
            0.0,
        ),
        (
            "raycast, 2 slices/cell + sub-voxel",
            RenderOptions {
                bands: band(2.0, true),
                ..Default::default()
            },
            0.0,
        ),
        (
            "distorted (voxel-space shortcuts)",
            RenderOptions {
                mode: RaycastMode::Distorted,
                ..Default::default()
            },
            0.0,
        ),
        ("raycast, pitch -30°", RenderOptions::default(), -30.0),
        (
            "raycast, pitch -30°, growing steps",
            RenderOptions {
                grow_steps: true,
                ..Default::default()
            },
            -30.0,
        ),
    ]
}

/// The frame write floor: writing a frame of the renderer's — which has
/// drawn this size's references: the raycaster's own buffers and layout —
/// with nothing drawn.
fn frame_write_floor(
    grid: &Grid,
    renderer: &horizon::Raycaster,
    size: [u32; 2],
    runs: usize,
    json_lines: bool,
) -> Result<()> {
    let threads = rayon::current_num_threads();
    let frame = renderer.frame().clone();
    anyhow::ensure!(
        [frame.width, frame.height] == [size[0] as usize, size[1] as usize],
        "the floor needs a frame of {}×{}",
        size[0],
        size[1]
    );
    let ms = frame_write_ms(frame, runs);
    emit(
        json_lines,
        json!({"bench": "render", "grid": grid.name, "mode": FRAME_WRITE,
           "threads": threads, "width": size[0], "height": size[1], "ms": ms}),
        format!(
            "{:>15} {}×{} {FRAME_WRITE:>36}: {ms:7.2} ms/frame ({threads} thread{})",
            grid.name,
            size[0],
            size[1],
            if threads == 1 { "" } else { "s" }
        ),
    );
    Ok(())
}
