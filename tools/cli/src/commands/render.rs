//! `relevo render`: the floating-horizon raycast of a bundle to PNG (and its
//! depth buffer), without a GPU.

use crate::output;
use anyhow::{bail, Result};
use clap::Args;
use relevo_core::bundle::Bundle;
use relevo_core::horizon::{Arithmetic, DistanceBand, RaycastFrame, RaycastMode, RenderOptions};
use relevo_core::pyramid::render::LevelOptions;
use relevo_core::pyramid::Pyramid;
use relevo_core::raster::png::encode_rgba;
use relevo_core::scene::{self, CameraPose, View};
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The bundle to render.
    pub bundle: PathBuf,
    /// Eye easting, northing (bundle CRS), height (m), heading (° clockwise
    /// from north), then optionally the pitch in degrees with its unit
    /// (`-20deg` looks 20° down; see `relevo render --help` for its range)
    /// and incl (projection-plane shift: the screen row, in pixels from the
    /// bottom, the view axis passes through; larger looks further down).
    #[arg(
        long,
        allow_hyphen_values = true,
        value_name = "X,Y,Z,HEADING[,PITCHdeg][,INCL]",
        value_parser = CameraPose::parse,
        required = true
    )]
    pub camera: CameraPose,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 60.0)]
    pub fov: f64,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "960x540", value_parser = scene::parse_size)]
    pub size: [u32; 2],
    /// Far plane, in grid cells.
    #[arg(long, default_value_t = 1024.0)]
    pub far: f64,
    /// Distortion-free raycast, or the voxel-space shortcuts as a baseline.
    #[arg(long, value_enum, default_value_t = RenderMode::Raycast)]
    pub mode: RenderMode,
    /// 16.16 fixed-point inner loop instead of floating point.
    #[arg(long)]
    pub fixed: bool,
    /// Distance bands UNTIL_M:SLICES_PER_CELL[:sub], e.g. 3000:4:sub,inf:1 (sub = sub-voxel bilinear).
    #[arg(long, value_parser = scene::parse_bands)]
    pub bands: Option<Bands>,
    /// Sample prefiltered colour levels by slice footprint (anti-aliasing).
    #[arg(long)]
    pub prefilter: bool,
    /// Let slices spread with distance while a step moves the terrain by at
    /// most a pixel: faster far away, a little less detail (see
    /// docs/benchmarks.md for the cost in PSNR).
    #[arg(long)]
    pub grow_steps: bool,
    /// Bake a hillshade: sun AZIMUTH,ELEVATION in degrees.
    #[arg(long, value_delimiter = ',', value_name = "AZIMUTH,ELEVATION")]
    pub hillshade: Option<Vec<f64>>,
    /// A pyramid: the largest a level's cell may look on screen, pixels,
    /// before farther slices read the next coarser level (the bands are
    /// the levels; --bands is for single grids).
    #[arg(long, default_value_t = 1.0)]
    pub max_cell_px: f64,
    /// Also write the depth buffer: raw little-endian f32, row-major, top row first, [0, 1].
    #[arg(long)]
    pub depth: Option<PathBuf>,
    /// Output PNG.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

/// One `--bands` value: the whole list (a plain `Vec` would make clap
/// expect the flag once per band).
type Bands = Vec<DistanceBand>;

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum RenderMode {
    Raycast,
    Distorted,
}

pub fn run(a: RenderArgs) -> Result<()> {
    let outputs: Vec<&Path> = std::iter::once(&a.out)
        .chain(&a.depth)
        .map(PathBuf::as_path)
        .collect();
    output::check(&outputs, a.force)?;
    scene::check_view_limits(a.fov, a.far)?;
    let pose = a.camera;
    if a.hillshade.as_ref().is_some_and(|h| h.len() != 2) {
        bail!("--hillshade takes AZIMUTH,ELEVATION");
    }
    // Colour and depth, by column and as the image, and the PNG.
    relevo_core::memory::check(
        &format!("a {}×{} frame", a.size[0], a.size[1]),
        a.size[0] as u64 * a.size[1] as u64,
        RaycastFrame::BYTES_PER_PIXEL,
        "choose a smaller --size",
    )?;
    let view = View {
        eye: pose.eye,
        heading_deg: pose.heading_deg,
        pitch_deg: pose.pitch_deg,
        incl_px: pose.incl_px,
        fov_x_deg: a.fov,
        size: a.size,
        far_cells: a.far,
    };
    let mode = match a.mode {
        RenderMode::Raycast => RaycastMode::Raycast,
        RenderMode::Distorted => RaycastMode::Distorted,
    };
    let arithmetic = if a.fixed {
        Arithmetic::Fixed
    } else {
        Arithmetic::Float
    };
    let options = RenderOptions {
        mode,
        arithmetic,
        prefilter: a.prefilter,
        grow_steps: a.grow_steps,
        ..RenderOptions::default()
    };
    let hillshade = a.hillshade.map(|v| [v[0], v[1]]);
    let pyramid = relevo_core::bundle::format_of(&a.bundle).as_deref()
        == Some(relevo_core::bundle::PYRAMID_FORMAT);
    let frame = if pyramid {
        if a.bands.is_some() {
            bail!(
                "{}: a pyramid's distance bands are its levels; set where they switch with \
                 --max-cell-px instead of --bands",
                a.bundle.display()
            );
        }
        let p = std::sync::Arc::new(Pyramid::open(&a.bundle)?);
        let camera = scene::camera(&p.frame(), &view)?;
        let levels = LevelOptions {
            max_cell_px: a.max_cell_px,
            hillshade,
        };
        let (frame, read) = relevo_core::pyramid::render::render(&p, &camera, &options, levels)?;
        let windows: Vec<String> = read
            .iter()
            .map(|l| format!("level {} {}×{}", l.level, l.width, l.height))
            .collect();
        eprintln!(
            "{}: the bands read {}",
            a.bundle.display(),
            if windows.is_empty() {
                "no level (nothing in view)".to_string()
            } else {
                windows.join(", ")
            }
        );
        frame
    } else {
        let bundle = Bundle::open(&a.bundle)?;
        let options = scene::with_bands(options, a.bands)?;
        scene::render_bundle(&bundle, &view, &options, hillshade)?
    };
    let rows = frame.to_rows();
    let png = encode_rgba(rows.rgba_bytes(), rows.width, rows.height)?;
    // The image and its depth are written together or not at all.
    let mut files: Vec<(&Path, &[u8])> = vec![(&a.out, &png)];
    if let Some(d) = &a.depth {
        files.push((d, bytemuck::cast_slice(&rows.depth)));
    }
    relevo_core::atomic::write_files(&files)?;
    let s = frame.steps;
    eprintln!(
        "{}: {}×{} in {:.1} ms (setup {:.1}, march {:.1}, output {:.1})",
        a.out.display(),
        frame.width,
        frame.height,
        s.setup_ms + s.march_ms + s.output_ms,
        s.setup_ms,
        s.march_ms,
        s.output_ms
    );
    Ok(())
}
