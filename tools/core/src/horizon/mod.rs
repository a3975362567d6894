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
    /// Column-major buffers to the row-major image and depth.
    pub output_ms: f64,
}

/// A rendered image: RGBA8 and [0, 1] depth, row-major, top row first.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Frame {
    pub width: usize,
    pub height: usize,
    /// One pixel per element, RGBA bytes in little-endian order
    /// ([`Frame::rgba_bytes`] views them as bytes).
    pub rgba: Vec<u32>,
    pub depth: Vec<f32>,
    pub steps: Steps,
}

impl Frame {
    /// The image as RGBA8 bytes, row-major.
    pub fn rgba_bytes(&self) -> &[u8] {
        bytemuck::cast_slice(&self.rgba)
    }
}

/// One slice: forward distance, its depth and its band.
#[derive(Debug)]
struct Slice {
    distance_m: f64,
    depth: f32,
    /// Screen pixels per metre of height at this distance, d/s.
    scale: f64,
    subvoxel: bool,
    /// With prefiltering: a screen pixel's ground footprint across the ray
    /// (s/d) and the factor s²/d that, divided by the eye's height above the
    /// ground, gives its footprint along the ray; metres.
    footprint: Option<(f64, f64)>,
}

impl Slice {
    /// Colour level for a sample at height `z` seen from `eye_z`: the
    /// larger of the pixel's two ground footprints picks it.
    #[inline]
    fn level(&self, terrain: &Terrain, eye_z: f64, z: f64) -> usize {
        match self.footprint {
            None => 0,
            Some((across, along)) => terrain.color_level(across.max(along / (eye_z - z).max(1e-3))),
        }
    }
}

/// Forward distances of the slices from the near to the far plane
/// (seed 000, Algorithm 2b generalised to bands).
fn fill_slices(out: &mut Vec<Slice>, terrain: &Terrain, camera: &Camera, opts: &RenderOptions) {
    let d = camera.plane_distance_px();
    out.clear();
    // Slices off the terrain's square sample nothing: skip (in whole steps)
    // those nearer than the square and stop past its farthest corner, so the
    // slice count is bounded by the square's size whatever `far` is.
    let extent = (terrain.side - 1) as f64 * terrain.cell_m;
    let gap = |e: f64| (-e).max(e - extent).max(0.0);
    let reach = |e: f64| e.abs().max((e - extent).abs());
    let (x, y) = (camera.position.x, camera.position.y);
    let nearest = gap(x).hypot(gap(y));
    let end = camera.far_m.min(reach(x).hypot(reach(y)));
    let mut s = camera.near_m;
    let mut band = 0;
    while s <= end {
        while band + 1 < opts.bands.len() && s > opts.bands[band].until_m {
            band += 1;
        }
        let b = opts.bands[band];
        let step = terrain.cell_m / b.slices_per_cell;
        if s + step < nearest {
            // Whole steps up to the square or the band's end.
            let to = nearest.min(b.until_m);
            s += ((to - s) / step).floor().max(1.0) * step;
            continue;
        }
        let footprint = opts.prefilter.then_some((s / d, s * s / d));
        out.push(Slice {
            distance_m: s,
            depth: camera.depth_at(s) as f32,
            scale: d / s,
            subvoxel: b.subvoxel,
            footprint,
        });
        s += step;
    }
}

/// Render `terrain` seen from `camera` into a new frame (see [`Renderer`]
/// to reuse buffers from frame to frame).
pub fn render(terrain: &Terrain, camera: &Camera, opts: &RenderOptions) -> Frame {
    let mut renderer = Renderer::default();
    renderer.render(terrain, camera, opts);
    renderer.frame
}

/// Buffers reused from frame to frame: after the first frame of a size,
/// rendering allocates nothing.
#[derive(Debug, Default)]
pub struct Renderer {
    slices: Vec<Slice>,
    columns: Vec<[f64; 2]>,
    /// Colour and depth column by column, bottom row first.
    colour_columns: Vec<u32>,
    depth_columns: Vec<f32>,
    frame: Frame,
}

/// One column being painted, bottom row first.
struct ColumnOut<'a> {
    colour: &'a mut [u32],
    depth: &'a mut [f32],
}

impl ColumnOut<'_> {
    fn height(&self) -> usize {
        self.colour.len()
    }

    /// Set pixel `row` (counted from the bottom).
    #[inline]
    fn paint(&mut self, row: usize, colour: u32, depth: f32) {
        self.colour[row] = colour;
        self.depth[row] = depth;
    }

    /// Paint rows from `*row` up while `below(row)` (the row's centre lies
    /// under the sample), advancing `*row`; true once the column is full.
    #[inline]
    fn paint_while(
        &mut self,
        row: &mut usize,
        below: impl Fn(usize) -> bool,
        colour: u32,
        depth: f32,
    ) -> bool {
        while *row < self.height() && below(*row) {
            self.paint(*row, colour, depth);
            *row += 1;
        }
        *row >= self.height()
    }

    /// Sky (depth 1) from `row` to the top.
    fn finish(&mut self, row: usize, sky: u32) {
        self.colour[row..].fill(sky);
        self.depth[row..].fill(1.0);
    }
}

impl Renderer {
    /// The last frame rendered (empty before the first).
    pub fn frame(&self) -> &Frame {
        &self.frame
    }

    /// Render `terrain` seen from `camera` (whose pitch must be 0: tilt is
    /// the projection-plane shift `incl_px`).
    pub fn render(&mut self, terrain: &Terrain, camera: &Camera, opts: &RenderOptions) -> &Frame {
        let start = Instant::now();
        let (w, h) = (camera.width as usize, camera.height as usize);
        fill_slices(&mut self.slices, terrain, camera, opts);
        let d = camera.plane_distance_px();
        let heading = camera.heading_deg.to_radians();
        let forward = [heading.sin(), heading.cos()];
        let right = [heading.cos(), -heading.sin()];
        let q = camera.fov_x_deg.to_radians();
        // Ground direction of column k, scaled so that moving by `dir · s`
        // advances the slice distance s (forward distance, or radial when distorted).
        self.columns.clear();
        self.columns.extend((0..w).map(|k| {
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
        }));
        let setup_ms = start.elapsed().as_secs_f64() * 1e3;

        let start = Instant::now();
        let eye = [camera.position.x, camera.position.y, camera.position.z];
        let sky = u32::from_le_bytes(opts.sky);
        self.colour_columns.resize(w * h, 0);
        self.depth_columns.resize(w * h, 0.0);
        let slices = &self.slices;
        self.colour_columns
            .par_chunks_mut(h)
            .zip(self.depth_columns.par_chunks_mut(h))
            .zip(self.columns.par_iter())
            .for_each(|((colour, depth), dir)| {
                let mut out = ColumnOut { colour, depth };
                match opts.arithmetic {
                    Arithmetic::Float => {
                        march_float(terrain, slices, eye, *dir, camera.incl_px, sky, &mut out);
                    }
                    Arithmetic::Fixed => {
                        march_fixed(terrain, slices, eye, *dir, camera.incl_px, sky, &mut out);
                    }
                }
            });
        let march_ms = start.elapsed().as_secs_f64() * 1e3;

        // Transpose in bands of rows so that reads of each column stay in cache.
        let start = Instant::now();
        const BAND: usize = 16;
        let f = &mut self.frame;
        f.width = w;
        f.height = h;
        f.rgba.resize(w * h, 0);
        f.depth.resize(w * h, 0.0);
        let (colour_columns, depth_columns) = (&self.colour_columns, &self.depth_columns);
        f.rgba
            .par_chunks_mut(w * BAND)
            .zip(f.depth.par_chunks_mut(w * BAND))
            .enumerate()
            .for_each(|(band, (rows, drows))| {
                let count = drows.len() / w;
                // Column k's rows of this band, bottom-counted from `low`, reversed.
                let low = h - band * BAND - count;
                for k in 0..w {
                    let column = &colour_columns[k * h + low..k * h + low + count];
                    let dcolumn = &depth_columns[k * h + low..k * h + low + count];
                    for y in 0..count {
                        rows[y * w + k] = column[count - 1 - y];
                        drows[y * w + k] = dcolumn[count - 1 - y];
                    }
                }
            });
        let output_ms = start.elapsed().as_secs_f64() * 1e3;
        f.steps = Steps {
            setup_ms,
            march_ms,
            output_ms,
        };
        &self.frame
    }
}

/// The ray through the centre of pixel (`px`, `py`) (from the top-left),
/// as a terrain-frame direction scaled so that moving by `dir · s` advances
/// the forward distance by s. Pitch must be 0.
pub fn pixel_ray(camera: &Camera, px: f64, py: f64) -> [f64; 3] {
    let d = camera.plane_distance_px();
    let heading = camera.heading_deg.to_radians();
    let (forward, right) = (
        [heading.sin(), heading.cos()],
        [heading.cos(), -heading.sin()],
    );
    let across = px + 0.5 - camera.width as f64 / 2.0;
    let up = (camera.height as f64 - 1.0 - py) + 0.5 - camera.incl_px;
    [
        forward[0] + right[0] * across / d,
        forward[1] + right[1] * across / d,
        up / d,
    ]
}

/// Where the ray through pixel (`px`, `py`) first meets the exact bilinear
/// terrain surface, as a forward distance in metres: an independent
/// reference for the raycaster's depth, and a way to pick terrain points.
/// Marches in steps of 1/32 cell, then bisects.
pub fn pick(terrain: &Terrain, camera: &Camera, px: f64, py: f64) -> Option<f64> {
    let dir = pixel_ray(camera, px, py);
    let eye = camera.position;
    let below = |s: f64| {
        let (x, y, z) = (eye.x + dir[0] * s, eye.y + dir[1] * s, eye.z + dir[2] * s);
        terrain.surface(x, y).map(|ground| z <= ground)
    };
    let step = terrain.cell_m / 32.0;
    let mut s = camera.near_m;
    while s <= camera.far_m {
        if below(s) == Some(true) {
            let (mut lo, mut hi) = (s - step, s);
            for _ in 0..40 {
                let mid = (lo + hi) / 2.0;
                if below(mid) == Some(true) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            return Some(hi.max(camera.near_m));
        }
        s += step;
    }
    None
}

/// Forward distance of a [0, 1] depth, inverting eq. 5.11.
pub fn distance_of_depth(camera: &Camera, depth: f64) -> f64 {
    let (n, f) = (camera.near_m, camera.far_m);
    f * n / (f - depth * (f - n))
}

/// One column in floating point (seed 000, Algorithm 1 with depth, line 11A).
fn march_float(
    terrain: &Terrain,
    slices: &[Slice],
    eye: [f64; 3],
    dir: [f64; 2],
    incl: f64,
    sky: u32,
    out: &mut ColumnOut,
) {
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
        let c = terrain.color(x, y, s.subvoxel, s.level(terrain, eye[2], z));
        if out.paint_while(&mut row, |r| (r as f64 + 0.5) < top, c, s.depth) {
            break;
        }
    }
    out.finish(row, sky);
}

/// One column in 16.16 fixed point: ground position and heights in 1/65536
/// of a cell and of a metre, the per-slice scale in 1/65536 pixel per metre.
fn march_fixed(
    terrain: &Terrain,
    slices: &[Slice],
    eye: [f64; 3],
    dir: [f64; 2],
    incl: f64,
    sky: u32,
    out: &mut ColumnOut,
) {
    const ONE: f64 = 65536.0;
    let to_cell = ONE / terrain.cell_m;
    let (ex, ey) = ((eye[0] * to_cell) as i64, (eye[1] * to_cell) as i64);
    let (dx, dy) = ((dir[0] * to_cell) as i64, (dir[1] * to_cell) as i64);
    let ez = (eye[2] * ONE) as i64;
    let incl = (incl * ONE) as i64;
    let mut row = 0usize; // next unpainted row, from the bottom
    for s in slices {
        let dist = (s.distance_m * ONE) as i64;
        let x = ex + ((dx * dist) >> 16);
        let y = ey + ((dy * dist) >> 16);
        let Some(z) = terrain.height_fixed(x, y, s.subvoxel) else {
            continue;
        };
        let scale = (s.scale * ONE) as i64;
        let top = incl + (((z - ez) * scale) >> 16);
        let centre = |row: usize| ((row as i64) << 16) + (1 << 15);
        if centre(row) >= top {
            continue;
        }
        let c = terrain.color_fixed(x, y, s.subvoxel, s.level(terrain, eye[2], z as f64 / ONE));
        if out.paint_while(&mut row, |r| centre(r) < top, c, s.depth) {
            break;
        }
    }
    out.finish(row, sky);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::{GeoTransform, TerrainFrame};
    use glam::DVec3;

    fn camera(w: u32, h: u32, eye: [f64; 3], heading: f64, incl: f64, far_m: f64) -> Camera {
        Camera {
            position: DVec3::from_array(eye),
            heading_deg: heading,
            pitch_deg: 0.0,
            incl_px: incl,
            fov_x_deg: 60.0,
            width: w,
            height: h,
            near_m: 1.0,
            far_m,
        }
    }

    /// A drape of one texel per cell over a `side`² grid of 1 m cells.
    fn texel_per_cell(rgba: &[u8], side: usize) -> ColorSource {
        let geotransform = GeoTransform::north_up(0.0, side as f64, 1.0, 1.0);
        let frame = TerrainFrame {
            side,
            cell_size_m: 1.0,
            geotransform,
        };
        ColorSource::new(rgba, side, side, &geotransform, &frame).unwrap()
    }

    /// A flat 257² grid, 1 m cells, with one-cell poles of height 40 m, and
    /// an image (one texel per cell) that is red on the poles, green elsewhere.
    /// Heights, mask, RGBA image and pole cells of the pole scene.
    type Scene = (Vec<f32>, Vec<u8>, Vec<u8>, Vec<(usize, usize)>);

    fn poles() -> Scene {
        let side = 257;
        let spots = vec![(128, 60), (70, 40), (190, 45), (100, 90), (160, 100)];
        let mut heights = vec![0.0f32; side * side];
        let mut rgba = vec![0u8; side * side * 4];
        for i in 0..side * side {
            rgba[i * 4..i * 4 + 4].copy_from_slice(&[40, 160, 40, 255]);
        }
        for &(c, r) in &spots {
            heights[r * side + c] = 40.0;
            rgba[(r * side + c) * 4..(r * side + c) * 4 + 4].copy_from_slice(&[255, 0, 0, 255]);
        }
        (heights, vec![1u8; side * side], rgba, spots)
    }

    /// Top pixel (column, row) of each pole in the image, by its red colour,
    /// against where the camera's projection matrix sends the pole's top.
    fn pole_misses(mode: Mode) -> Vec<f64> {
        let side = 257;
        let (heights, mask, rgba, spots) = poles();
        let color = texel_per_cell(&rgba, side);
        let terrain = Terrain::new(side, 1.0, &heights, &mask, Some(color));
        // Eye south of the poles, looking north, level.
        let cam = camera(960, 540, [128.0, 0.0, 30.0], 0.0, 270.0, 400.0);
        let opts = RenderOptions {
            mode,
            bands: vec![Band {
                until_m: f64::INFINITY,
                slices_per_cell: 8.0,
                subvoxel: false,
            }],
            ..Default::default()
        };
        let frame = render(&terrain, &cam, &opts);
        let vp = cam.view_projection();
        spots
            .iter()
            .map(|&(c, r)| {
                // Pole top centre in the terrain frame.
                let p = DVec3::new(c as f64, (side - 1 - r) as f64, 40.0);
                let clip = vp * p.extend(1.0);
                let x = (clip.x / clip.w + 1.0) / 2.0 * 960.0;
                let y = (1.0 - clip.y / clip.w) / 2.0 * 540.0;
                // Red pixels: their topmost row and the mean column on it.
                let red: Vec<(usize, usize)> = (0..540 * 960)
                    .filter(|&i| {
                        frame.rgba_bytes()[i * 4] == 255 && frame.rgba_bytes()[i * 4 + 1] == 0
                    })
                    .map(|i| (i % 960, i / 960))
                    .filter(|&(px, _)| (px as f64 - x).abs() < 40.0)
                    .collect();
                if red.is_empty() {
                    return f64::INFINITY;
                }
                let top = red.iter().map(|p| p.1).min().unwrap();
                let cols: Vec<f64> = red
                    .iter()
                    .filter(|p| p.1 == top)
                    .map(|p| p.0 as f64 + 0.5)
                    .collect();
                let col = cols.iter().sum::<f64>() / cols.len() as f64;
                (col - x).abs().max((top as f64 - y).abs())
            })
            .collect()
    }

    #[test]
    fn poles_land_where_the_projection_matrix_puts_them() {
        let raycast = pole_misses(Mode::Raycast);
        assert!(
            raycast.iter().all(|&m| m <= 1.0),
            "raycast misses {raycast:?} px"
        );
        let distorted = pole_misses(Mode::Distorted);
        let worst = distorted.iter().cloned().fold(0.0, f64::max);
        eprintln!("pole misses, raycast {raycast:.2?} px, distorted {distorted:.2?} px");
        assert!(
            worst > 3.0,
            "distorted mode should miss the off-centre poles, worst {worst}"
        );
    }

    /// Render `terrain` for `cam` at 8 slices per cell with sub-voxels, and
    /// measure its depth against the exact surface: per terrain pixel, the
    /// distance error in slice spacings (sorted), and how many pixels the
    /// two disagree on being terrain or sky.
    fn depth_against_exact_surface(terrain: &Terrain, cam: &Camera) -> (Frame, Vec<f64>, usize) {
        let opts = RenderOptions {
            bands: vec![Band {
                until_m: f64::INFINITY,
                slices_per_cell: 8.0,
                subvoxel: true,
            }],
            ..Default::default()
        };
        let frame = render(terrain, cam, &opts);
        let spacing = terrain.cell_m / 8.0;
        let (mut errors, mut disagree) = (Vec::new(), 0);
        for py in 0..cam.height as usize {
            for px in 0..cam.width as usize {
                let d = frame.depth[py * cam.width as usize + px];
                match (d < 1.0, pick(terrain, cam, px as f64, py as f64)) {
                    (true, Some(exact)) => {
                        errors.push((distance_of_depth(cam, d as f64) - exact).abs() / spacing);
                    }
                    (false, None) => {}
                    _ => disagree += 1,
                }
            }
        }
        errors.sort_by(f64::total_cmp);
        (frame, errors, disagree)
    }

    #[test]
    fn depth_is_monotonic_up_each_column_and_matches_the_exact_surface() {
        // A smooth real-looking surface: sums of sines, 129², 10 m cells.
        let side = 129;
        let heights: Vec<f32> = (0..side * side)
            .map(|i| {
                let (c, r) = ((i % side) as f64, (i / side) as f64);
                (40.0 * (c / 9.0).sin() * (r / 13.0).cos() + 25.0 * ((c + r) / 21.0).sin()) as f32
            })
            .collect();
        let mask = vec![1u8; side * side];
        let terrain = Terrain::new(side, 10.0, &heights, &mask, None);
        let cam = camera(160, 90, [300.0, 100.0, 120.0], 20.0, 70.0, 1200.0);
        let (frame, errors, _) = depth_against_exact_surface(&terrain, &cam);
        for k in 0..160 {
            let mut last = 0.0f32;
            for row in (0..90).rev() {
                let d = frame.depth[row * 160 + k];
                assert!((0.0..=1.0).contains(&d));
                assert!(d >= last, "depth decreases up column {k}");
                last = d;
            }
        }
        let (median, p95) = (errors[errors.len() / 2], errors[errors.len() * 95 / 100]);
        eprintln!("depth vs exact surface: median {median:.3}, 95th percentile {p95:.3} slice spacings over {} pixels", errors.len());
        assert!(errors.len() > 5000);
        assert!(
            median <= 1.0 && p95 <= 2.0,
            "median {median}, 95th percentile {p95} slice spacings"
        );
    }

    #[test]
    fn depth_of_real_dems_matches_the_exact_surface() {
        // From the south-west quarter of each crop looking north-east, 150 m
        // above its highest point, the horizon three quarters up the screen.
        for dem in [
            crate::testdata::dem("srtm_ref_257.f32"),
            crate::testdata::dem("copernicus_grenoble_257.f32"),
        ] {
            let (side, cell) = (dem.side, dem.cell_size_m);
            let extent = (side - 1) as f64 * cell;
            let top = dem.heights.iter().copied().fold(f32::MIN, f32::max) as f64;
            let mask = vec![1u8; side * side];
            let terrain = Terrain::new(side, cell, &dem.heights, &mask, None);
            let eye = [0.15 * extent, 0.1 * extent, top + 150.0];
            let mut cam = camera(240, 135, eye, 35.0, 0.75 * 135.0, 1024.0 * cell);
            cam.near_m = cell;
            let (_, errors, disagree) = depth_against_exact_surface(&terrain, &cam);
            let (median, p95) = (errors[errors.len() / 2], errors[errors.len() * 95 / 100]);
            let pixels = 240 * 135;
            eprintln!(
                "{}: depth vs exact surface median {median:.3}, p95 {p95:.3} slice spacings; \
                 {disagree} of {pixels} pixels disagree on terrain/sky",
                dem.name
            );
            assert!(
                errors.len() > pixels / 2,
                "{}: {} terrain pixels",
                dem.name,
                errors.len()
            );
            assert!(
                median <= 1.0 && p95 <= 2.0,
                "{}: median {median}, p95 {p95}",
                dem.name
            );
            assert!(
                disagree * 100 < pixels,
                "{}: {disagree} pixels disagree",
                dem.name
            );
        }
    }

    /// A far plane far beyond the terrain, and an eye far outside it, cost
    /// no more slices than the terrain's square holds, and draw what a far
    /// plane at the square's farthest corner draws.
    #[test]
    fn slices_stay_within_the_terrain_whatever_the_far_plane() {
        let dem = crate::testdata::dem("srtm_ref_257.f32");
        let (side, cell) = (dem.side, dem.cell_size_m);
        let extent = (side - 1) as f64 * cell;
        let mask = vec![1u8; side * side];
        let terrain = Terrain::new(side, cell, &dem.heights, &mask, None);
        let top = dem.heights.iter().copied().fold(f32::MIN, f32::max) as f64;
        let opts = RenderOptions::default();
        let most = (2.0 * extent * std::f64::consts::SQRT_2 / cell + 2.0) as usize;
        for eye in [
            [0.5 * extent, -0.2 * extent, top + 300.0],
            [0.5 * extent, -5e8, top + 300.0],
        ] {
            let mut renderer = Renderer::default();
            let mut far = camera(240, 135, eye, 0.0, 100.0, 1e12);
            far.near_m = cell;
            renderer.render(&terrain, &far, &opts);
            assert!(
                renderer.slices.len() <= most,
                "{} slices",
                renderer.slices.len()
            );
            let reach = (eye[0].abs().max((eye[0] - extent).abs()))
                .hypot(eye[1].abs().max((eye[1] - extent).abs()));
            let mut bounded = camera(240, 135, eye, 0.0, 100.0, reach + cell);
            bounded.near_m = cell;
            let mut reference = Renderer::default();
            reference.render(&terrain, &bounded, &opts);
            if eye[1] > -1e6 {
                assert!(renderer.slices.len() > 100);
                assert_eq!(renderer.frame.rgba, reference.frame.rgba);
            }
        }
    }

    /// Whatever the padding holds never shows: Gironde's sea (below 0 m)
    /// masked out as padding, holding either the sea floor or a 600 m wall,
    /// renders the same image and depth, from four cameras over the coast,
    /// in both arithmetics, with and without sub-voxel sampling, in both
    /// modes. (Bilinear samples beside the coast used to blend the padding
    /// in: a curtain along the data's edge.)
    #[test]
    fn padding_heights_never_show() {
        let dem = crate::testdata::dem("gironde_257.f32");
        let (side, cell) = (dem.side, dem.cell_size_m);
        let mask: Vec<u8> = dem.heights.iter().map(|&z| u8::from(z >= 0.0)).collect();
        assert!(mask.iter().filter(|&&m| m == 0).count() > side * side / 10);
        let wall: Vec<f32> = dem
            .heights
            .iter()
            .zip(&mask)
            .map(|(&z, &m)| if m == 1 { z } else { 600.0 })
            .collect();
        let floor = Terrain::new(side, cell, &dem.heights, &mask, None);
        let walled = Terrain::new(side, cell, &wall, &mask, None);
        let extent = (side - 1) as f64 * cell;
        let mut compared = 0;
        for (eye, heading) in [
            ([0.5 * extent, -0.1 * extent, 400.0], 0.0),
            ([-0.1 * extent, 0.5 * extent, 250.0], 90.0),
            ([1.1 * extent, 1.1 * extent, 800.0], 225.0),
            ([-0.1 * extent, -0.1 * extent, 300.0], 45.0),
        ] {
            let cam = camera(240, 135, eye, heading, 90.0, 2.0 * extent);
            for arithmetic in [Arithmetic::Float, Arithmetic::Fixed] {
                for subvoxel in [true, false] {
                    for mode in [Mode::Raycast, Mode::Distorted] {
                        let options = RenderOptions {
                            mode,
                            arithmetic,
                            bands: vec![Band {
                                until_m: f64::INFINITY,
                                slices_per_cell: 2.0,
                                subvoxel,
                            }],
                            ..Default::default()
                        };
                        let (a, b) = (
                            render(&floor, &cam, &options),
                            render(&walled, &cam, &options),
                        );
                        let terrain = a.depth.iter().filter(|&&d| d < 1.0).count();
                        assert!(
                            terrain > 240 * 135 / 10,
                            "{eye:?}: {terrain} terrain pixels"
                        );
                        let what = format!("{eye:?} {arithmetic:?} subvoxel {subvoxel} {mode:?}");
                        assert!(a.depth == b.depth, "{what}: depth differs");
                        assert!(a.rgba == b.rgba, "{what}: colour differs");
                        compared += 1;
                    }
                }
            }
        }
        assert_eq!(compared, 32);
    }

    #[test]
    fn fixed_point_matches_floating_point() {
        let (heights, mask, rgba, _) = poles();
        let side = 257;
        let color = texel_per_cell(&rgba, side);
        let terrain = Terrain::new(side, 1.0, &heights, &mask, Some(color));
        let cam = camera(320, 180, [128.0, 0.0, 30.0], 10.0, 120.0, 400.0);
        let float = render(&terrain, &cam, &RenderOptions::default());
        let fixed = render(
            &terrain,
            &cam,
            &RenderOptions {
                arithmetic: Arithmetic::Fixed,
                ..Default::default()
            },
        );
        let differ = float
            .depth
            .iter()
            .zip(&fixed.depth)
            .filter(|(a, b)| a != b)
            .count();
        assert!(differ * 100 < float.depth.len(), "{differ} pixels differ");
    }

    #[test]
    fn prefiltering_reduces_far_chessboard_aliasing() {
        // Planar terrain with a chessboard of 1-cell squares (seed 000, §8.2).
        let side = 513;
        let heights = vec![0.0f32; side * side];
        let mask = vec![1u8; side * side];
        let rgba: Vec<u8> = (0..side * side)
            .flat_map(|i| {
                let v = if (i % side + i / side) % 2 == 0 {
                    255
                } else {
                    0
                };
                [v, v, v, 255]
            })
            .collect();
        let energy = |prefilter: bool| {
            let color = texel_per_cell(&rgba, side);
            let terrain = Terrain::new(side, 1.0, &heights, &mask, Some(color));
            let cam = camera(320, 180, [256.0, 0.0, 12.0], 0.0, 150.0, 500.0);
            let opts = RenderOptions {
                prefilter,
                ..Default::default()
            };
            let f = render(&terrain, &cam, &opts);
            // High-frequency energy of the far half of the terrain rows: mean
            // absolute difference of horizontal neighbours.
            let terrain_rows: Vec<usize> =
                (0..180).filter(|&y| f.depth[y * 320 + 160] < 1.0).collect();
            let far = &terrain_rows[..terrain_rows.len() / 2];
            let mut sum = 0.0;
            let mut n = 0;
            for &y in far {
                for x in 0..319 {
                    sum += (f.rgba_bytes()[(y * 320 + x) * 4] as f64
                        - f.rgba_bytes()[(y * 320 + x + 1) * 4] as f64)
                        .abs();
                    n += 1;
                }
            }
            sum / n as f64
        };
        let (plain, filtered) = (energy(false), energy(true));
        eprintln!("far-half chessboard energy: plain {plain:.1}, prefiltered {filtered:.1}");
        assert!(
            filtered < plain * 0.5,
            "prefiltered {filtered} vs plain {plain}"
        );
    }
}
