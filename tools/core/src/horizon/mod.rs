//! Floating-horizon raycasting of a height grid on the CPU, with a depth
//! buffer that GPU-drawn objects can share.
//!
//! Szenberg, "Um algoritmo para visualização de terrenos com objetos"
//! (MSc thesis, PUC-Rio, 1997; seed 000, chapters 4–8) and Szenberg, Gattass
//! and Carvalho, "An algorithm for the visualization of a terrain with
//! objects" (SIBGRAPI 1997; seed 002).
//!
//! Each screen column is one ray in the ground plane; the terrain is sampled
//! in *slices parallel to the screen* at forward distances s₀ < s₁ < …, and a
//! column is painted bottom-up: a sample at height z and forward distance s
//! reaches screen row incl + d·(z − z_eye)/s (d = distance to the projection
//! plane in pixels), and every row between the current horizon and that row
//! takes its colour and the slice's depth. Because the slices are parallel to
//! the screen, that projection and the depth (f − f·n/s)/(f − n) (eq. 5.11)
//! are the same for every column and equal to what the GPU computes with
//! [`Camera::projection`] — there is no approximation in the conic
//! projection. Rays are evenly spaced on the view plane, and the step along
//! each is the slice spacing divided by cos θₖ (chapter 5).
//!
//! The `distorted` mode reproduces the game-literature shortcuts (every
//! column at the same distance, rays evenly spaced in angle, radial steps)
//! as a baseline; it does not match the GPU.

mod sample;

pub use sample::{ColorSource, Terrain};

use crate::camera::Camera;
use rayon::prelude::*;
use std::time::Instant;

/// Projection used for the rays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Distortion-free: rays even on the view plane, screen-parallel slices.
    Raycast,
    /// Voxel-space shortcuts: rays even in angle, radial slices.
    Distorted,
}

/// Arithmetic of the inner loop (seed 000, chapter 7 and tables 8.1–8.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arithmetic {
    Float,
    /// 16.16 fixed point for ground positions, heights and projection.
    Fixed,
}

/// A distance band with its own sampling (seed 000, §6.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// The band ends at this forward distance, metres.
    pub until_m: f64,
    /// Slices per grid cell (the seed's FATOR is its inverse).
    pub slices_per_cell: f64,
    /// Sub-voxel bilinear interpolation of height and colour (§6.2).
    pub subvoxel: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    pub mode: Mode,
    pub arithmetic: Arithmetic,
    /// Bands in increasing distance; the last one should reach the far plane.
    pub bands: Vec<Band>,
    /// Sample prefiltered colour levels chosen by each slice's footprint.
    pub prefilter: bool,
    /// Colour of pixels no terrain covers.
    pub sky: [u8; 4],
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            mode: Mode::Raycast,
            arithmetic: Arithmetic::Float,
            bands: vec![Band {
                until_m: f64::INFINITY,
                slices_per_cell: 1.0,
                subvoxel: false,
            }],
            prefilter: false,
            sky: [135, 170, 215, 255],
        }
    }
}

/// Wall time of each step of a render, milliseconds (in the spirit of the
/// seed's table 8.1).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Steps {
    /// Slice distances, depth vector and column rays.
    pub setup_ms: f64,
    /// Marching the columns.
    pub march_ms: f64,
    /// Column-major buffers to row-major image and depth.
    pub output_ms: f64,
}

/// A rendered image: RGBA8 and [0, 1] depth, row-major, top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub width: usize,
    pub height: usize,
    pub rgba: Vec<u8>,
    pub depth: Vec<f32>,
    pub steps: Steps,
}

/// One slice: forward distance, its depth and its band.
struct Slice {
    distance_m: f64,
    depth: f32,
    /// Screen pixels per metre of height at this distance, d/s.
    scale: f64,
    subvoxel: bool,
    /// Colour level from the footprint.
    level: usize,
}

/// Forward distances of the slices from the near to the far plane
/// (seed 000, Algorithm 2b generalised to bands).
fn slices(terrain: &Terrain, camera: &Camera, opts: &RenderOptions) -> Vec<Slice> {
    let d = camera.plane_distance_px();
    let mut out = Vec::new();
    let mut s = camera.near_m;
    let mut band = 0;
    while s <= camera.far_m {
        while band + 1 < opts.bands.len() && s > opts.bands[band].until_m {
            band += 1;
        }
        let b = opts.bands[band];
        let level = if opts.prefilter {
            terrain.color_level(s / d)
        } else {
            0
        };
        out.push(Slice {
            distance_m: s,
            depth: camera.depth_at(s) as f32,
            scale: d / s,
            subvoxel: b.subvoxel,
            level,
        });
        s += terrain.cell_m / b.slices_per_cell;
    }
    out
}

/// Render `terrain` seen from `camera` (whose pitch must be 0: tilt is the
/// projection-plane shift `incl_px`).
pub fn render(terrain: &Terrain, camera: &Camera, opts: &RenderOptions) -> Frame {
    let start = Instant::now();
    let (w, h) = (camera.width as usize, camera.height as usize);
    let slices = slices(terrain, camera, opts);
    let d = camera.plane_distance_px();
    let heading = camera.heading_deg.to_radians();
    let forward = [heading.sin(), heading.cos()];
    let right = [heading.cos(), -heading.sin()];
    let q = camera.fov_x_deg.to_radians();
    // Ground direction of column k, scaled so that moving by `dir · s`
    // advances the slice distance s (forward distance, or radial when distorted).
    let columns: Vec<[f64; 2]> = (0..w)
        .map(|k| {
            let offset = k as f64 + 0.5 - w as f64 / 2.0;
            match opts.mode {
                Mode::Raycast => [
                    forward[0] + right[0] * offset / d,
                    forward[1] + right[1] * offset / d,
                ],
                Mode::Distorted => {
                    let theta = (offset / w as f64) * q;
                    let (sin, cos) = theta.sin_cos();
                    [
                        forward[0] * cos + right[0] * sin,
                        forward[1] * cos + right[1] * sin,
                    ]
                }
            }
        })
        .collect();
    let setup_ms = start.elapsed().as_secs_f64() * 1e3;

    let start = Instant::now();
    let eye = camera.position;
    let sky = u32::from_le_bytes(opts.sky);
    let mut colour_columns = vec![sky; w * h];
    let mut depth_columns = vec![1.0f32; w * h];
    colour_columns
        .par_chunks_mut(h)
        .zip(depth_columns.par_chunks_mut(h))
        .zip(columns.par_iter())
        .for_each(|((colour, depth), dir)| match opts.arithmetic {
            Arithmetic::Float => march_float(
                terrain,
                &slices,
                [eye.x, eye.y, eye.z],
                *dir,
                camera.incl_px,
                colour,
                depth,
            ),
            Arithmetic::Fixed => march_fixed(
                terrain,
                &slices,
                [eye.x, eye.y, eye.z],
                *dir,
                camera.incl_px,
                colour,
                depth,
            ),
        });
    let march_ms = start.elapsed().as_secs_f64() * 1e3;

    let start = Instant::now();
    let mut rgba = vec![0u8; w * h * 4];
    let mut depth = vec![0.0f32; w * h];
    rgba.par_chunks_mut(w * 4)
        .zip(depth.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (row, drow))| {
            let j = h - 1 - y; // row counted from the bottom
            for k in 0..w {
                row[k * 4..k * 4 + 4].copy_from_slice(&colour_columns[k * h + j].to_le_bytes());
                drow[k] = depth_columns[k * h + j];
            }
        });
    let output_ms = start.elapsed().as_secs_f64() * 1e3;
    Frame {
        width: w,
        height: h,
        rgba,
        depth,
        steps: Steps {
            setup_ms,
            march_ms,
            output_ms,
        },
    }
}

/// One column in floating point (seed 000, Algorithm 1 with depth, line 11A).
fn march_float(
    terrain: &Terrain,
    slices: &[Slice],
    eye: [f64; 3],
    dir: [f64; 2],
    incl: f64,
    colour: &mut [u32],
    depth: &mut [f32],
) {
    let h = colour.len();
    let mut row = 0usize; // next unpainted row, from the bottom
    for s in slices {
        let x = eye[0] + dir[0] * s.distance_m;
        let y = eye[1] + dir[1] * s.distance_m;
        let Some(z) = terrain.height(x, y, s.subvoxel) else {
            continue;
        };
        let top = incl + (z - eye[2]) * s.scale;
        if (row as f64 + 0.5) >= top {
            continue;
        }
        let c = terrain.color(x, y, s.subvoxel, s.level);
        while row < h && (row as f64 + 0.5) < top {
            colour[row] = c;
            depth[row] = s.depth;
            row += 1;
        }
        if row >= h {
            break;
        }
    }
}

/// One column in 16.16 fixed point: ground position and heights in 1/65536
/// of a cell and of a metre, the per-slice scale in 1/65536 pixel per metre.
fn march_fixed(
    terrain: &Terrain,
    slices: &[Slice],
    eye: [f64; 3],
    dir: [f64; 2],
    incl: f64,
    colour: &mut [u32],
    depth: &mut [f32],
) {
    const ONE: f64 = 65536.0;
    let h = colour.len() as i64;
    let to_cell = ONE / terrain.cell_m;
    let (ex, ey) = ((eye[0] * to_cell) as i64, (eye[1] * to_cell) as i64);
    let (dx, dy) = ((dir[0] * to_cell) as i64, (dir[1] * to_cell) as i64);
    let ez = (eye[2] * ONE) as i64;
    let incl = (incl * ONE) as i64;
    let mut row = 0i64;
    for s in slices {
        let dist = (s.distance_m * ONE) as i64;
        let x = ex + ((dx * dist) >> 16);
        let y = ey + ((dy * dist) >> 16);
        let Some(z) = terrain.height_fixed(x, y, s.subvoxel) else {
            continue;
        };
        let scale = (s.scale * ONE) as i64;
        let top = incl + (((z - ez) * scale) >> 16);
        let centre = |row: i64| (row << 16) + (1 << 15);
        if centre(row) >= top {
            continue;
        }
        let c = terrain.color_fixed(x, y, s.subvoxel, s.level);
        while row < h && centre(row) < top {
            colour[row as usize] = c;
            depth[row as usize] = s.depth;
            row += 1;
        }
        if row >= h {
            break;
        }
    }
}
