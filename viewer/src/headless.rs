//! `relevo-view render`: the same renderer as the window, drawing into its
//! offscreen targets without a window, read back to PNG (and the depth
//! buffer), at any size the GPU allows.

use crate::flight::Flight;
use crate::gpu::{
    frame_bytes_per_pixel, FrameStats, Readback, Renderer, Targets, COLOUR_FORMAT, DEPTH_FORMAT,
};
use crate::hud;
use crate::scene::Scene;
use crate::settings::{Settings, TerrainMode, VegetationSelection};
use anyhow::{bail, Context, Result};
use eframe::egui;
use eframe::egui_wgpu::{self, wgpu};
use relevo_core::horizon::{Arithmetic, DistanceBand};
use relevo_core::raster::png::encode_rgba;
use relevo_core::scene::{self, CameraPose};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// The bundle to render.
    pub bundle: PathBuf,
    /// How the terrain is drawn: mesh, raycast, or a Z-buffer baseline
    /// zbuffer:a … zbuffer:g (points, top faces, front faces, segments,
    /// blocks, flat triangles, smooth triangles).
    #[arg(long, default_value = "mesh", value_parser = TerrainMode::parse)]
    pub mode: TerrainMode,
    /// Eye easting, northing (bundle CRS), height (m), heading (° clockwise
    /// from north), optionally the pitch with its unit (`-20deg` looks down)
    /// and incl (the view axis's screen row in pixels from the bottom;
    /// larger looks further down). Default: the home view.
    #[arg(
        long,
        value_name = "X,Y,Z,HEADING[,PITCHdeg][,INCL]",
        allow_hyphen_values = true
    )]
    pub camera: Option<String>,
    /// Image size, WIDTHxHEIGHT (`--tab samples` fits the drape into it).
    #[arg(long, default_value = "1280x720", value_parser = scene::parse_size)]
    pub size: [u32; 2],
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 60.0)]
    pub fov: f64,
    /// Far plane, in grid cells.
    #[arg(long, default_value_t = 1024.0)]
    pub far: f64,
    /// Mesh mode: screen-space tolerance τ, pixels (0 keeps every vertex).
    #[arg(long, default_value_t = 2.0)]
    pub tau: f64,
    /// Mesh mode: no geomorphing.
    #[arg(long)]
    pub no_morph: bool,
    /// Mesh mode: wireframe over the surface.
    #[arg(long)]
    pub wireframe: bool,
    /// Mesh mode: a shaded height ramp instead of the drape.
    #[arg(long)]
    pub no_texture: bool,
    /// Raycast mode: distance bands UNTIL_M:SLICES_PER_CELL or UNTIL_M:SLICES_PER_CELL:sub, e.g. 3000:4:sub,inf:1.
    #[arg(long, value_parser = scene::parse_bands)]
    pub bands: Option<Bands>,
    /// Raycast mode: 16.16 fixed-point inner loop.
    #[arg(long)]
    pub fixed: bool,
    /// Raycast mode: prefiltered colour levels by slice footprint.
    #[arg(long)]
    pub prefilter: bool,
    /// Raycast mode: slices spreading with distance (see `relevo render --help`).
    #[arg(long)]
    pub grow_steps: bool,
    /// Objects to composite: a GeoJSON placement file (see docs/formats.md).
    #[arg(long)]
    pub objects: Option<PathBuf>,
    /// Draw the objects and vegetation alone, without the terrain.
    #[arg(long)]
    pub no_terrain: bool,
    /// What chooses the bundle's vegetation: quadtree (relevo-core's cut),
    /// or the baselines list and blobs or blobs:SIDE_M.
    #[arg(long, default_value = "quadtree", value_parser = VegetationSelection::parse)]
    pub vegetation: VegetationSelection,
    /// No objects or vegetation.
    #[arg(long)]
    pub no_objects: bool,
    /// Vegetation as sprites (two crossed quads) instead of billboards.
    #[arg(long)]
    pub sprites: bool,
    /// Vegetation impostors as whole quads, without their alpha.
    #[arg(long)]
    pub no_alpha: bool,
    /// Vegetation textures unfiltered (nearest texel, no mip levels).
    #[arg(long)]
    pub no_blur: bool,
    /// Elevation of the line of sight above which impostors show their top
    /// view, degrees.
    #[arg(long, default_value_t = 45.0)]
    pub view_angle: f64,
    /// Each impostor's own view angle: where its top view shows more than
    /// its side.
    #[arg(long)]
    pub auto_view_angle: bool,
    /// Margin over which a cluster dithers into its children (0–1; 0: the
    /// cut switches levels).
    #[arg(long, default_value_t = 0.25)]
    pub level_fade: f64,
    /// Paint the window's HUD into the image.
    #[arg(long)]
    pub hud: bool,
    /// Which tab to render: the 3D view, or the samples tab's image —
    /// detection on the drape with `--samples` (or the bundle's own
    /// samples), its overlay and the rectangles.
    #[arg(long, default_value = "view", value_parser = ["view", "samples"])]
    pub tab: String,
    /// Samples for `--tab samples`: class;xmin;ymin;xmax;ymax in drape pixels.
    #[arg(long)]
    pub samples: Option<PathBuf>,
    /// Output PNG.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Also write the depth buffer: raw little-endian f32, row-major, top row first, [0, 1].
    #[arg(long)]
    pub depth: Option<PathBuf>,
    /// Also write the frame's figures as JSON.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

/// One `--bands` value: the whole list.
type Bands = Vec<DistanceBand>;

/// What `--stats` writes.
#[derive(Debug, Serialize)]
struct Report<'a> {
    adapter: &'a str,
    mode: TerrainMode,
    camera: String,
    frame: FrameStats,
}

/// A device without a window: the first adapter wgpu finds (a GPU, or
/// Mesa's lavapipe where there is none), with the adapter's own limits so
/// images larger than any screen can be drawn.
pub fn device() -> Result<(wgpu::Device, wgpu::Queue, String)> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        ..Default::default()
    }))
    .context("no GPU adapter (install Mesa's Vulkan drivers for a software one)")?;
    let info = adapter.get_info();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("relevo-view"),
        required_limits: adapter.limits(),
        ..Default::default()
    }))
    .context("the GPU adapter refused a device")?;
    Ok((device, queue, format!("{} ({:?})", info.name, info.backend)))
}

/// Paint the HUD's `lines` over the targets' colour with egui's own
/// renderer, as the window does.
fn paint_hud(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    targets: &Targets,
    lines: &[String],
    frame_s: f64,
) -> Result<()> {
    let [w, h] = targets.size;
    let ctx = egui::Context::default();
    let screen = egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(w as f32, h as f32));
    let input = egui::RawInput {
        screen_rect: Some(screen),
        ..Default::default()
    };
    let output = ctx.run_ui(input, |ui| {
        hud::paint(ui.painter(), screen, lines, &[frame_s], 1);
    });
    let primitives = ctx.tessellate(output.shapes, output.pixels_per_point);
    let mut renderer = egui_wgpu::Renderer::new(
        device,
        COLOUR_FORMAT,
        egui_wgpu::RendererOptions {
            depth_stencil_format: Some(DEPTH_FORMAT),
            ..Default::default()
        },
    );
    for (id, deltas) in &output.textures_delta.set {
        for delta in deltas {
            renderer.update_texture(device, queue, *id, delta);
        }
    }
    let screen = egui_wgpu::ScreenDescriptor {
        size_in_pixels: [w, h],
        pixels_per_point: output.pixels_per_point,
    };
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("hud") });
    let uploads = renderer.update_buffers(device, queue, &mut encoder, &primitives, &screen);
    {
        let mut pass = targets.begin(&mut encoder, None, "hud").forget_lifetime();
        renderer.render(&mut pass, &primitives, &screen);
    }
    queue.submit(uploads.into_iter().chain([encoder.finish()]));
    wait_for_gpu(device)
}

/// Wait until the GPU has finished everything submitted.
pub fn wait_for_gpu(device: &wgpu::Device) -> Result<()> {
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .context("waiting for the GPU")?;
    Ok(())
}

/// Wait until the GPU has finished `submission` (and what came before it),
/// leaving later submissions running.
pub fn wait_for_submission(device: &wgpu::Device, submission: wgpu::SubmissionIndex) -> Result<()> {
    device
        .poll(wgpu::PollType::Wait {
            submission_index: Some(submission),
            timeout: None,
        })
        .context("waiting for the GPU")?;
    Ok(())
}

/// What one headless frame is: its size, whether the window's HUD is
/// painted over it, and whether its depth is read back.
#[derive(Debug, Clone, Copy)]
pub struct Shot {
    pub size: [u32; 2],
    pub hud: bool,
    pub depth: bool,
}

impl Shot {
    /// A frame of `size` without the HUD, its depth read back.
    pub fn new(size: [u32; 2]) -> Shot {
        Shot {
            size,
            hud: false,
            depth: true,
        }
    }
}

/// Render `scene` once for `flight` and read the targets back as `shot`
/// asks (without its depth, [`Readback::depth`] is empty).
pub fn render_once(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    scene: &mut Scene,
    flight: &Flight,
    settings: &Settings,
    shot: &Shot,
) -> Result<(Readback, FrameStats)> {
    let size = shot.size;
    let camera = flight.camera(scene, size);
    let mut renderer = Renderer::new(device, queue, scene, size);
    renderer.settle_tiles();
    let start = Instant::now();
    let stats = renderer.render(device, queue, scene, &camera, settings)?;
    wait_for_gpu(device)?;
    if shot.hud {
        let frame_s = start.elapsed().as_secs_f64();
        let readings = hud::Readings {
            fps: 1.0 / frame_s,
            frame_ms: frame_s * 1e3,
            settings,
            stats: &stats,
            scene: Some(scene),
            flight: Some(flight),
            pointer: None,
        };
        paint_hud(
            device,
            queue,
            &renderer.targets,
            &hud::lines(&readings),
            frame_s,
        )?;
    }
    let mut readback = renderer.targets.read(device, queue, shot.depth)?;
    // A terrain-only raycast's depth is the CPU buffer itself (not uploaded).
    if shot.depth {
        if let Some(depth) = renderer.raycast_depth(scene, settings) {
            readback.depth = depth;
        }
    }
    Ok((readback, stats))
}

pub fn run(a: RenderArgs) -> Result<()> {
    let outputs: Vec<&Path> = std::iter::once(&a.out)
        .chain(&a.depth)
        .chain(&a.stats)
        .map(PathBuf::as_path)
        .collect();
    relevo_core::atomic::check_outputs(&outputs, a.force)?;
    scene::check_view_limits(a.fov, a.far)?;
    if !(a.tau >= 0.0 && a.tau.is_finite()) {
        bail!(
            "--tau must be a non-negative number of pixels, got {}",
            a.tau
        );
    }
    relevo_core::memory::check(
        &format!("a {}×{} frame", a.size[0], a.size[1]),
        u64::from(a.size[0]) * u64::from(a.size[1]),
        frame_bytes_per_pixel(a.mode == TerrainMode::Raycast, a.depth.is_some()),
        "choose a smaller --size",
    )?;
    if a.tab == "samples" {
        return render_samples_tab(&a);
    }
    let pose = a
        .camera
        .as_deref()
        .map(CameraPose::parse)
        .transpose()
        .map_err(|e| anyhow::anyhow!("--camera {e}"))?;
    let mut scene = Scene::open(&a.bundle)?;
    if let Some(path) = &a.objects {
        scene.load_objects(path)?;
    }
    let mut flight = match &pose {
        None => Flight::home(&scene),
        Some(pose) => Flight::from_pose(&scene, pose, a.size[1]).with_context(|| {
            format!(
                "{}: the bundle's geotransform cannot be inverted",
                a.bundle.display()
            )
        })?,
    };
    flight.fov_x_deg = a.fov;
    flight.far_cells = a.far;
    let mut settings = Settings {
        mode: a.mode,
        tau_px: a.tau,
        morph: !a.no_morph,
        wireframe: a.wireframe,
        texture: !a.no_texture,
        terrain: !a.no_terrain,
        objects: !a.no_objects,
        vegetation: a.vegetation,
        sprites: a.sprites,
        alpha: !a.no_alpha,
        blur: !a.no_blur,
        view_angle_deg: a.view_angle,
        automatic_view_angle: a.auto_view_angle,
        level_fade: a.level_fade,
        ..Default::default()
    };
    if !(0.0..=1.0).contains(&a.level_fade) {
        bail!("--level-fade {}: must lie in 0–1", a.level_fade);
    }
    if !(0.0..=90.0).contains(&a.view_angle) {
        bail!("--view-angle {}: must lie in 0–90°", a.view_angle);
    }
    settings.raycast.prefilter = a.prefilter;
    settings.raycast.grow_steps = a.grow_steps;
    if a.fixed {
        settings.raycast.arithmetic = Arithmetic::Fixed;
    }
    if let Some(bands) = a.bands {
        settings.raycast.bands = bands;
    }
    let (device, queue, adapter) = device()?;
    let largest = device.limits().max_texture_dimension_2d;
    if a.size.iter().any(|&side| side > largest) {
        bail!(
            "--size {}x{}: this GPU ({adapter}) draws at most {largest} pixels a side",
            a.size[0],
            a.size[1]
        );
    }
    let shot = Shot {
        size: a.size,
        hud: a.hud,
        depth: a.depth.is_some(),
    };
    let (readback, stats) = render_once(&device, &queue, &mut scene, &flight, &settings, &shot)?;
    let png = encode_rgba(&readback.rgba, a.size[0] as usize, a.size[1] as usize)?;
    let camera = flight.pose(&scene, a.size[1]).to_string();
    let report = Report {
        adapter: &adapter,
        mode: a.mode,
        camera: camera.clone(),
        frame: stats,
    };
    let report = serde_json::to_string_pretty(&report)?;
    // The image, its depth and its figures are written together or not at all.
    let mut files: Vec<(&Path, &[u8])> = vec![(&a.out, &png)];
    if let Some(path) = &a.depth {
        files.push((path, bytemuck::cast_slice(&readback.depth)));
    }
    if let Some(path) = &a.stats {
        files.push((path, report.as_bytes()));
    }
    relevo_core::atomic::write_files(&files)?;
    eprintln!(
        "{}: {}×{} {} on {adapter}, {} terrain and {} object triangles, camera {camera}",
        a.out.display(),
        a.size[0],
        a.size[1],
        a.mode,
        stats.triangles,
        stats.object_triangles
    );
    Ok(())
}

/// What the samples tab's image is framed on: egui's dark panel grey.
const TAB_BACKGROUND: [u8; 4] = [27, 27, 27, 255];

/// `relevo-view render --tab samples`: the samples tab's image written as
/// a PNG of `--size`.
fn render_samples_tab(a: &RenderArgs) -> Result<()> {
    let samples = match &a.samples {
        Some(path) => path.clone(),
        None => {
            let bundle = relevo_core::bundle::Bundle::open(&a.bundle)?;
            let name = relevo_core::bundle::names::VEGETATION_SAMPLES;
            let artifact = bundle.manifest.artifacts.get(name.key).with_context(|| {
                format!(
                    "{}: the bundle keeps no samples; pass --samples FILE.csv",
                    a.bundle.display()
                )
            })?;
            a.bundle.join(&artifact.file)
        }
    };
    let (rgba, [w, h], objects) = crate::samples::render_tab(&a.bundle, &samples)?;
    // The drape fitted into --size, as the tab shows it in the window.
    let [out_w, out_h] = a.size.map(|side| side as usize);
    let framed = relevo_core::raster::fit::fit_rgba(&rgba, w, h, out_w, out_h, TAB_BACKGROUND)?;
    let png = encode_rgba(&framed, out_w, out_h)?;
    relevo_core::atomic::write_file(&a.out, &png)?;
    println!(
        "{}: {out_w}×{out_h} samples tab of {} (its {w}×{h} drape fitted), {objects} objects detected",
        a.out.display(),
        a.bundle.display()
    );
    Ok(())
}
