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

mod frame;
mod march;
mod sample;
mod screen;

use frame::tiled_len;
pub use frame::{tiled_index, RaycastFrame, Rows, Steps, TILE_COLUMNS};
use march::Slice;
pub use sample::{grid_position, hillshade, ColorSource, Terrain};
pub use screen::{pitch_range, MAX_LINE_DENSITY};

use crate::camera::Camera;
use crate::{Error, Result};
use rayon::prelude::*;
use screen::Screen;
use std::sync::Arc;
use std::time::Instant;

/// Projection used for the rays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RaycastMode {
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
pub struct DistanceBand {
    /// The band ends at this forward distance, metres.
    pub until_m: f64,
    /// Slices per grid cell (the seed's FATOR is its inverse).
    pub slices_per_cell: f64,
    /// Sub-voxel bilinear interpolation of height and colour (§6.2).
    pub subvoxel: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    pub mode: RaycastMode,
    pub arithmetic: Arithmetic,
    /// Bands in increasing distance; the last one should reach the far plane.
    pub bands: Vec<DistanceBand>,
    /// Sample prefiltered colour levels chosen by each slice's footprint.
    pub prefilter: bool,
    /// Let the slice spacing grow with distance while one step moves any
    /// terrain point by at most a pixel on screen (see `fill_slices`):
    /// fewer slices far away, at a measured cost in image detail.
    pub grow_steps: bool,
    /// Colour of pixels no terrain covers.
    pub sky: [u8; 4],
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            mode: RaycastMode::Raycast,
            arithmetic: Arithmetic::Float,
            bands: vec![DistanceBand {
                until_m: f64::INFINITY,
                slices_per_cell: 1.0,
                subvoxel: false,
            }],
            prefilter: false,
            grow_steps: false,
            sky: [135, 170, 215, 255],
        }
    }
}

/// What the slices are laid out over: the whole level-0 grid, whether one
/// terrain holds it or a pyramid's levels do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridExtent {
    /// Vertices a side.
    pub side: usize,
    /// Vertex spacing, metres.
    pub cell_m: f64,
    /// The lowest and highest heights with data, metres.
    pub lowest_m: f64,
    pub highest_m: f64,
}

impl Terrain<'_> {
    /// The grid this terrain holds, as the slices see it.
    pub fn extent(&self) -> GridExtent {
        GridExtent {
            side: self.side,
            cell_m: self.cell_m,
            lowest_m: self.lowest_m,
            highest_m: self.highest_m,
        }
    }
}

/// Horizontal forward distances of the slices (seed 000, Algorithm 2b
/// generalised to bands), from the nearest that can show anything to the
/// farthest.
fn fill_slices(
    out: &mut Vec<Slice>,
    grid: &GridExtent,
    camera: &Camera,
    screen: &Screen,
    opts: &RenderOptions,
) {
    let d = camera.plane_distance_px();
    out.clear();
    // A row's rays reach the near and far planes at s = near·α/d and
    // far·α/d; the slices span the widest of those.
    let deepest = screen.forward_per_depth.iter().copied().fold(0.0, f64::max);
    // Slices off the terrain's square sample nothing: skip (in whole steps)
    // those nearer than the square and stop past its farthest corner, so the
    // slice count is bounded by the square's size whatever `far` is.
    let extent = (grid.side - 1) as f64 * grid.cell_m;
    let gap = |e: f64| (-e).max(e - extent).max(0.0);
    let reach = |e: f64| e.abs().max((e - extent).abs());
    let (x, y, z) = (camera.position.x, camera.position.y, camera.position.z);
    let mut nearest = gap(x).hypot(gap(y));
    // Nothing nearer than where the highest terrain would reach the bottom
    // row's rays can show (when they point down and the eye is above it).
    let lowest_slope = screen.slope.first().copied().unwrap_or(0.0);
    if lowest_slope < 0.0 && z > grid.highest_m {
        nearest = nearest.max((z - grid.highest_m) / -lowest_slope);
    }
    let end = (camera.far_m * deepest).min(reach(x).hypot(reach(y)));
    // Growing steps: a point Δz below (or above) the eye at distance s sits
    // d·Δz/s pixels from the horizon; one step Δs moves it by d·Δz·Δs/s²,
    // at most a pixel while Δs ≤ s²/(d·Δz) — bounded over the terrain by its
    // largest |Δz|. (The vertical counterpart of the prefilter's footprint;
    // seed 000 §9.1 names multiresolution as the next step.) A level camera
    // is assumed for the bound; pitched, rows differ by at most α's spread.
    let largest_rise = (z - grid.lowest_m).abs().max((grid.highest_m - z).abs());
    let growth =
        (opts.grow_steps && largest_rise.is_finite()).then(|| d * largest_rise.max(grid.cell_m));
    let mut s = camera.near_m * deepest;
    let mut band = 0;
    while s <= end {
        while band + 1 < opts.bands.len() && s > opts.bands[band].until_m {
            band += 1;
        }
        let b = opts.bands[band];
        let base = grid.cell_m / b.slices_per_cell;
        let step = growth.map_or(base, |g| base.max(s * s / g));
        if s + step < nearest {
            // Whole steps up to the square or the band's end.
            let to = nearest.min(b.until_m);
            s += ((to - s) / step).floor().max(1.0) * step;
            continue;
        }
        let footprint = opts.prefilter.then_some((s / d, s * s / d));
        out.push(Slice {
            distance_m: s,
            subvoxel: b.subvoxel,
            footprint,
        });
        s += step;
    }
}

/// Render `terrain` seen from `camera` into a new frame (see [`Raycaster`]
/// to reuse buffers from frame to frame).
///
/// ```
/// use relevo_core::camera::Camera;
/// use relevo_core::horizon::{render, RenderOptions, Terrain};
/// // A 129² ridge of 30 m cells, every vertex data, no drape.
/// let side = 129;
/// let heights: Vec<f32> = (0..side * side)
///     .map(|i| 200.0 - ((i % side) as f32 - 64.0).abs() * 3.0)
///     .collect();
/// let terrain = Terrain::new(side, 30.0, heights, vec![1u8; side * side], None);
/// let camera = Camera {
///     position: glam::DVec3::new(1920.0, -500.0, 150.0),
///     heading_deg: 0.0,
///     pitch_deg: 0.0,
///     incl_px: 60.0,
///     fov_x_deg: 60.0,
///     width: 320,
///     height: 180,
///     near_m: 30.0,
///     far_m: 30_000.0,
/// };
/// let frame = render(&terrain, &camera, &RenderOptions::default()).unwrap();
/// let rows = frame.to_rows();
/// // The ridge fills the bottom row; the top row is sky (depth 1).
/// assert!(rows.depth[(rows.height - 1) * rows.width + rows.width / 2] < 1.0);
/// assert_eq!(rows.depth[rows.width / 2], 1.0);
/// ```
pub fn render(terrain: &Terrain, camera: &Camera, opts: &RenderOptions) -> Result<RaycastFrame> {
    let mut renderer = Raycaster::default();
    renderer.render(terrain, camera, opts)?;
    Ok(renderer.frame)
}

/// A pyramid as the raycaster reads it: the whole grid's extent, and each
/// level's terrain over a stretch of ground on request.
pub struct Levels<'a> {
    pub extent: GridExtent,
    /// The terrain of `level` over the ground box `[x0, y0, x1, y1]`
    /// (level-0 terrain frame, metres), or what keeps it from being read.
    #[allow(clippy::type_complexity)]
    pub load: &'a (dyn Fn(u32, [f64; 4]) -> Result<Arc<LevelTerrain>> + Sync),
}

/// One level of a pyramid over a stretch of ground.
pub struct LevelTerrain {
    pub terrain: Terrain<'static>,
    /// Where this terrain's frame origin lies in the level-0 terrain frame,
    /// metres: a level-0 point (x, y) is (x, y) − `offset_m` in it.
    pub offset_m: [f64; 2],
}

/// What a frame is rendered from.
enum Terrains<'a> {
    One(&'a Terrain<'a>),
    Levels(&'a Levels<'a>),
}

/// Buffers reused from frame to frame: after the first frame of a size and
/// pitch, rendering allocates nothing.
#[derive(Debug, Default)]
pub struct Raycaster {
    slices: Vec<Slice>,
    screen: Screen,
    /// Ground direction of each line.
    directions: Vec<[f64; 2]>,
    /// A pitched camera's lines, row by row (top row first), before each
    /// pixel takes its nearest line.
    line_colour: Vec<u32>,
    line_depth: Vec<f32>,
    frame: RaycastFrame,
}

impl Raycaster {
    /// The last frame rendered (empty before the first).
    pub fn frame(&self) -> &RaycastFrame {
        &self.frame
    }

    /// The last frame rendered, kept.
    pub fn into_frame(self) -> RaycastFrame {
        self.frame
    }

    /// Render `terrain` seen from `camera`, pitched within
    /// [`pitch_range`] (the distorted mode only level).
    pub fn render(
        &mut self,
        terrain: &Terrain,
        camera: &Camera,
        opts: &RenderOptions,
    ) -> Result<&RaycastFrame> {
        self.render_with(&terrain.extent(), &Terrains::One(terrain), camera, opts)
    }

    /// Render a pyramid seen from `camera`: band i of `opts.bands` reads
    /// level i (the last band reads on as far as it goes), each level over
    /// the ground its band's slices reach, as [`Levels::load`] gives it.
    pub fn render_levels(
        &mut self,
        levels: &Levels,
        camera: &Camera,
        opts: &RenderOptions,
    ) -> Result<&RaycastFrame> {
        self.render_with(&levels.extent, &Terrains::Levels(levels), camera, opts)
    }

    fn render_with(
        &mut self,
        extent: &GridExtent,
        terrains: &Terrains,
        camera: &Camera,
        opts: &RenderOptions,
    ) -> Result<&RaycastFrame> {
        let start = Instant::now();
        if opts.mode == RaycastMode::Distorted && camera.pitch_deg != 0.0 {
            return Err(Error::Input(
                "the distorted (voxel-space) mode draws only level cameras (pitch 0)".into(),
            ));
        }
        let (w, h) = (camera.width as usize, camera.height as usize);
        if w == 0 || h == 0 {
            // A window minimised to nothing: an empty frame.
            self.frame.resize(w, h);
            return Ok(&self.frame);
        }
        self.screen.fill(camera)?;
        fill_slices(&mut self.slices, extent, camera, &self.screen, opts);
        let heading = camera.heading_deg.to_radians();
        let forward = [heading.sin(), heading.cos()];
        let right = [heading.cos(), -heading.sin()];
        let q = camera.fov_x_deg.to_radians();
        // Ground direction of line j, scaled so that moving by `dir · s`
        // advances the slice distance s (forward distance, or radial when
        // distorted).
        let screen = &self.screen;
        self.directions.clear();
        self.directions
            .extend((0..screen.lines).map(|j| match opts.mode {
                RaycastMode::Raycast => {
                    let a = screen.first_offset + j as f64 * screen.offset_step;
                    [forward[0] + right[0] * a, forward[1] + right[1] * a]
                }
                RaycastMode::Distorted => {
                    let theta = ((j as f64 + 0.5) / w as f64 - 0.5) * q;
                    let (sin, cos) = theta.sin_cos();
                    [
                        forward[0] * cos + right[0] * sin,
                        forward[1] * cos + right[1] * sin,
                    ]
                }
            }));
        let eye = [camera.position.x, camera.position.y];
        let bands = match terrains {
            Terrains::One(_) => Vec::new(),
            Terrains::Levels(levels) => self.load_levels(levels, extent, eye, opts)?,
        };
        let setup_ms = start.elapsed().as_secs_f64() * 1e3;

        let start = Instant::now();
        let f = &mut self.frame;
        f.resize(w, h);
        let target = if screen.pitched {
            let size = tiled_len(screen.lines, h);
            self.line_colour.resize(size, 0);
            self.line_depth.resize(size, 0.0);
            march::Target::new(&mut self.line_colour, &mut self.line_depth, screen.lines, h)
        } else {
            march::Target::new(&mut f.rgba, &mut f.depth, w, h)
        };
        let pass = march::Pass {
            slices: &self.slices,
            screen,
            directions: &self.directions,
            eye_z: camera.position.z,
            depth_terms: camera.depth_terms(),
            far_m: camera.far_m,
            sky: u32::from_le_bytes(opts.sky),
        };
        // Each segment's terrain, the eye in its frame, and its slices.
        let parts: Vec<(&Terrain, [f64; 2], std::ops::Range<usize>)> = match terrains {
            Terrains::One(terrain) => vec![(*terrain, eye, 0..self.slices.len())],
            Terrains::Levels(_) => bands
                .iter()
                .map(|(l, range)| {
                    let eye = [eye[0] - l.offset_m[0], eye[1] - l.offset_m[1]];
                    (&l.terrain, eye, range.clone())
                })
                .collect(),
        };
        let segments = Segments::new(&parts, opts.arithmetic);
        let packets = screen.lines.div_ceil(march::PACKET);
        let march_packet = |p: usize| {
            let first = p * march::PACKET;
            let count = march::PACKET.min(screen.lines - first);
            // SAFETY: each packet index comes once from the range, so each
            // line is marched by one task only.
            unsafe {
                match &segments {
                    Segments::Float(s) => pass.march(s, first, count, &target),
                    Segments::Fixed(s) => pass.march(s, first, count, &target),
                }
            }
        };
        (0..packets).into_par_iter().for_each(march_packet);
        let march_ms = start.elapsed().as_secs_f64() * 1e3;

        // A pitched screen: every pixel takes its nearest line (both in
        // column tiles).
        let start = Instant::now();
        if screen.pitched {
            let (line_colour, line_depth) = (&self.line_colour[..], &self.line_depth[..]);
            let tile = TILE_COLUMNS * h;
            f.rgba
                .par_chunks_mut(tile)
                .zip(f.depth.par_chunks_mut(tile))
                .enumerate()
                .for_each(|(t, (rgba, depth))| {
                    let tile = GatherTile {
                        first: t * TILE_COLUMNS,
                        rgba,
                        depth,
                    };
                    tile.gather(screen, line_colour, line_depth);
                });
        }
        let output_ms = start.elapsed().as_secs_f64() * 1e3;
        f.steps = Steps {
            setup_ms,
            march_ms,
            output_ms,
        };
        Ok(&self.frame)
    }
}

/// The segments of a frame in the arithmetic it is marched in.
enum Segments<'a> {
    Float(Vec<march::Segment<'a, march::FloatSampling<'a>>>),
    Fixed(Vec<march::Segment<'a, march::FixedSampling<'a>>>),
}

impl<'a> Segments<'a> {
    /// A segment for each (terrain, eye in its frame, slices).
    fn new(
        parts: &[(&'a Terrain<'a>, [f64; 2], std::ops::Range<usize>)],
        arithmetic: Arithmetic,
    ) -> Self {
        match arithmetic {
            Arithmetic::Float => Segments::Float(segments(parts, |terrain, eye| {
                march::FloatSampling { terrain, eye }
            })),
            Arithmetic::Fixed => Segments::Fixed(segments(parts, march::FixedSampling::new)),
        }
    }
}

/// The segments of `parts` sampled as `sampling` makes them.
fn segments<'a, S>(
    parts: &[(&'a Terrain<'a>, [f64; 2], std::ops::Range<usize>)],
    sampling: impl Fn(&'a Terrain<'a>, [f64; 2]) -> S,
) -> Vec<march::Segment<'a, S>> {
    parts
        .iter()
        .map(|&(terrain, eye, ref slices)| march::Segment {
            sampling: sampling(terrain, eye),
            terrain,
            eye,
            slices: slices.clone(),
        })
        .collect()
}

impl Raycaster {
    /// Each band's level over the ground its slices reach — every line's
    /// ground from the band's nearest to its farthest slice, two of the
    /// level's cells around for sub-voxel samples — with the slices it
    /// serves. Band i reads level i; the last band takes the slices past
    /// the others.
    fn load_levels(
        &self,
        levels: &Levels,
        extent: &GridExtent,
        eye: [f64; 2],
        opts: &RenderOptions,
    ) -> Result<Vec<(Arc<LevelTerrain>, std::ops::Range<usize>)>> {
        // Each band's level, slices and ground; then the levels read side
        // by side (a camera that moved far may need several new windows).
        let mut wanted = Vec::new();
        let mut from = 0;
        for (level, band) in opts.bands.iter().enumerate() {
            let to = if level + 1 == opts.bands.len() {
                self.slices.len()
            } else {
                from + self.slices[from..].partition_point(|s| s.distance_m <= band.until_m)
            };
            if to > from {
                let (near, far) = (self.slices[from].distance_m, self.slices[to - 1].distance_m);
                let margin = 2.0 * extent.cell_m * 2f64.powi(level as i32);
                let [mut x0, mut y0, mut x1, mut y1] = [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ];
                for dir in &self.directions {
                    for s in [near, far] {
                        let (x, y) = (eye[0] + dir[0] * s, eye[1] + dir[1] * s);
                        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
                    }
                }
                let ground = [x0 - margin, y0 - margin, x1 + margin, y1 + margin];
                wanted.push((level as u32, ground, from..to));
            }
            from = to;
        }
        wanted
            .into_par_iter()
            .map(|(level, ground, slices)| Ok(((levels.load)(level, ground)?, slices)))
            .collect()
    }
}

/// One column tile of a pitched frame, to take its pixels from the lines.
struct GatherTile<'a> {
    /// The tile's first pixel column.
    first: usize,
    rgba: &'a mut [u32],
    depth: &'a mut [f32],
}

impl GatherTile<'_> {
    /// Each pixel takes its nearest line's colour and depth (the lines'
    /// buffers are in column tiles too).
    fn gather(self, screen: &Screen, line_colour: &[u32], line_depth: &[f32]) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the machine has AVX2 (checked just above).
            unsafe { self.gather_avx2(screen, line_colour, line_depth) };
            return;
        }
        self.gather_rows(screen, line_colour, line_depth);
    }

    /// [`GatherTile::gather_rows`] compiled for AVX2, where a row's lines
    /// and their places in the buffers go several at a time.
    ///
    /// # Safety
    /// The machine must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn gather_avx2(self, screen: &Screen, line_colour: &[u32], line_depth: &[f32]) {
        self.gather_rows(screen, line_colour, line_depth);
    }

    /// The lines of one row of the tile, then their pixels, row by row.
    #[inline(always)]
    fn gather_rows(self, screen: &Screen, line_colour: &[u32], line_depth: &[f32]) {
        let (w, h) = (screen.width, screen.height);
        let columns = TILE_COLUMNS.min(w - self.first);
        let mut lines = [0u32; TILE_COLUMNS];
        let lines = &mut lines[..columns];
        // Every element the gather reads lies below this.
        let len = line_colour.len().min(line_depth.len());
        for y in 0..h {
            // The row's lines, then where they lie in the lines' buffers
            // (fewer than 2³² elements, `Screen::fill`), side by side.
            screen.lines_on_row(h - 1 - y, self.first, lines);
            let mut last = 0;
            for j in lines.iter_mut() {
                *j = tiled_index(*j as usize, y, h) as u32;
                last = last.max(*j);
            }
            assert!((last as usize) < len, "a line outside its buffers");
            let row = y * TILE_COLUMNS;
            let pixels = self.rgba[row..row + columns]
                .iter_mut()
                .zip(&mut self.depth[row..row + columns]);
            for ((colour, depth), &from) in pixels.zip(&*lines) {
                // SAFETY: from ≤ last < len, both buffers' length (checked
                // above).
                unsafe {
                    *colour = *line_colour.get_unchecked(from as usize);
                    *depth = *line_depth.get_unchecked(from as usize);
                }
            }
        }
    }
}

/// The ray through the centre of pixel (`px`, `py`) (from the top-left),
/// as a terrain-frame direction scaled so that moving by `dir · t` advances
/// the view depth (distance along the view axis) by t.
pub fn pixel_ray(camera: &Camera, px: f64, py: f64) -> [f64; 3] {
    let d = camera.plane_distance_px();
    let heading = camera.heading_deg.to_radians();
    let level_forward = [heading.sin(), heading.cos()];
    let right = [heading.cos(), -heading.sin()];
    let across = px + 0.5 - camera.width as f64 / 2.0;
    let up = (camera.height as f64 - 1.0 - py) + 0.5 - camera.incl_px;
    let (ahead, rise) = screen::ray_at(camera, up);
    [
        level_forward[0] * ahead / d + right[0] * across / d,
        level_forward[1] * ahead / d + right[1] * across / d,
        rise / d,
    ]
}

/// Where the ray through pixel (`px`, `py`) first meets the exact bilinear
/// terrain surface, as a view depth in metres: an independent reference
/// for the raycaster's depth, and a way to pick terrain points. Marches in
/// steps of 1/32 cell over the ground, then bisects.
pub fn pick(terrain: &Terrain, camera: &Camera, px: f64, py: f64) -> Option<f64> {
    let dir = pixel_ray(camera, px, py);
    let eye = camera.position;
    let below = |t: f64| {
        let (x, y, z) = (eye.x + dir[0] * t, eye.y + dir[1] * t, eye.z + dir[2] * t);
        terrain.surface(x, y).map(|ground| z <= ground)
    };
    let step = terrain.cell_m / 32.0 / dir[0].hypot(dir[1]).max(1e-6);
    let mut t = camera.near_m;
    while t <= camera.far_m {
        if below(t) == Some(true) {
            let (mut lo, mut hi) = (t - step, t);
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
        t += step;
    }
    None
}

/// View depth of a [0, 1] depth, inverting eq. 5.11.
pub fn distance_of_depth(camera: &Camera, depth: f64) -> f64 {
    let [a, b] = camera.depth_terms();
    b / (a - depth)
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
    fn pole_misses(mode: RaycastMode, pitch_deg: f64) -> Vec<f64> {
        let side = 257;
        let (heights, mask, rgba, spots) = poles();
        let color = texel_per_cell(&rgba, side);
        let terrain = Terrain::new(side, 1.0, &heights, &mask, Some(color));
        // Eye south of the poles, looking north; for steep pitches the
        // projection plane is also shifted so their tops (above the eye)
        // stay on screen.
        let incl = if pitch_deg < -15.0 { 60.0 } else { 270.0 };
        let mut cam = camera(960, 540, [128.0, 0.0, 30.0], 0.0, incl, 400.0);
        cam.pitch_deg = pitch_deg;
        let opts = RenderOptions {
            mode,
            bands: vec![DistanceBand {
                until_m: f64::INFINITY,
                slices_per_cell: 8.0,
                subvoxel: false,
            }],
            ..Default::default()
        };
        let frame = render(&terrain, &cam, &opts).unwrap().to_rows();
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
        for pitch in [0.0, -10.0, -25.0, 12.0] {
            let raycast = pole_misses(RaycastMode::Raycast, pitch);
            eprintln!("pitch {pitch}°: pole misses {raycast:.2?} px");
            assert!(
                raycast.iter().all(|&m| m <= 1.0),
                "pitch {pitch}°: raycast misses {raycast:?} px"
            );
        }
        let distorted = pole_misses(RaycastMode::Distorted, 0.0);
        let worst = distorted.iter().cloned().fold(0.0, f64::max);
        eprintln!("pole misses, distorted {distorted:.2?} px");
        assert!(
            worst > 3.0,
            "distorted mode should miss the off-centre poles, worst {worst}"
        );
    }

    /// Render `terrain` for `cam` at 8 slices per cell with sub-voxels, and
    /// measure its depth against the exact surface: per terrain pixel, the
    /// distance error in slice spacings (sorted), and how many pixels the
    /// two disagree on being terrain or sky.
    fn depth_against_exact_surface(terrain: &Terrain, cam: &Camera) -> (Rows, Vec<f64>, usize) {
        let opts = RenderOptions {
            bands: vec![DistanceBand {
                until_m: f64::INFINITY,
                slices_per_cell: 8.0,
                subvoxel: true,
            }],
            ..Default::default()
        };
        let frame = render(terrain, cam, &opts).unwrap().to_rows();
        let (mut errors, mut disagree) = (Vec::new(), 0);
        let d = cam.plane_distance_px();
        let (sin, cos) = cam.pitch_deg.to_radians().sin_cos();
        for py in 0..cam.height as usize {
            // The slices' spacing along this row's rays, as view depth:
            // horizontal spacing · d / α (see `screen`).
            let rho = (cam.height as usize - 1 - py) as f64 + 0.5 - cam.incl_px;
            let spacing = terrain.cell_m / 8.0 * d / (d * cos - rho * sin);
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
        // From the south-west quarter of each crop looking north-east.
        // 150 m above the highest point, level with the plane shifted, then
        // pitched for real (centred plane) down and up.
        let dems = [
            crate::testdata::dem("srtm_ref_257.f32"),
            crate::testdata::dem("copernicus_grenoble_257.f32"),
        ];
        for (dem, (pitch, incl)) in dems
            .iter()
            .flat_map(|dem| [(0.0, 0.75), (-15.0, 0.5), (-40.0, 0.5), (5.0, 0.5)].map(|p| (dem, p)))
        {
            let (side, cell) = (dem.side, dem.cell_size_m);
            let extent = (side - 1) as f64 * cell;
            let top = dem.heights.iter().copied().fold(f32::MIN, f32::max) as f64;
            let mask = vec![1u8; side * side];
            let terrain = Terrain::new(side, cell, &dem.heights, &mask, None);
            let eye = [0.15 * extent, 0.1 * extent, top + 150.0];
            let mut cam = camera(240, 135, eye, 35.0, incl * 135.0, 1024.0 * cell);
            cam.pitch_deg = pitch;
            cam.near_m = cell;
            let (_, errors, disagree) = depth_against_exact_surface(&terrain, &cam);
            let (median, p95) = (errors[errors.len() / 2], errors[errors.len() * 95 / 100]);
            let pixels = 240 * 135;
            // A pitched pixel takes the line nearest it, up to half a pixel
            // aside: at far silhouettes that half pixel can cross a ridge.
            let p95_bound = if pitch == 0.0 { 2.0 } else { 2.5 };
            eprintln!(
                "{} pitch {pitch}°: depth vs exact surface median {median:.3}, p95 {p95:.3} slice spacings \
                 over {} terrain pixels; {disagree} of {pixels} pixels disagree on terrain/sky",
                dem.name,
                errors.len()
            );
            assert!(
                errors.len() > pixels / 4,
                "{}: {} terrain pixels",
                dem.name,
                errors.len()
            );
            assert!(
                median <= 1.0 && p95 <= p95_bound,
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
            let mut renderer = Raycaster::default();
            let mut far = camera(240, 135, eye, 0.0, 100.0, 1e12);
            far.near_m = cell;
            renderer.render(&terrain, &far, &opts).unwrap();
            assert!(
                renderer.slices.len() <= most,
                "{} slices",
                renderer.slices.len()
            );
            let reach = (eye[0].abs().max((eye[0] - extent).abs()))
                .hypot(eye[1].abs().max((eye[1] - extent).abs()));
            let mut bounded = camera(240, 135, eye, 0.0, 100.0, reach + cell);
            bounded.near_m = cell;
            let mut reference = Raycaster::default();
            reference.render(&terrain, &bounded, &opts).unwrap();
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
    /// Real DEMs, one with a mask (Gironde's sea) so that masked vertices
    /// beside data take their neighbours' heights.
    fn masked_and_whole_dems() -> Vec<(crate::testdata::Dem, Vec<u8>)> {
        ["gironde_257.f32", "srtm_ref_257.f32"]
            .map(|name| {
                let dem = crate::testdata::dem(name);
                let mask = dem.heights.iter().map(|&z| u8::from(z >= 0.0)).collect();
                (dem, mask)
            })
            .into()
    }

    #[test]
    fn the_tiles_highest_heights_bound_every_sample() {
        let mut random = crate::testdata::Lcg(7);
        for (dem, mask) in masked_and_whole_dems() {
            let terrain = Terrain::new(dem.side, dem.cell_size_m, &dem.heights, &mask, None);
            let extent = (dem.side - 1) as f64 * dem.cell_size_m;
            let mut checked = 0;
            for _ in 0..2000 {
                // A box of up to 40 cells anywhere on or beside the grid.
                let corner = [0, 1].map(|_| (random.next() * 1.4 - 0.2) * extent);
                let size = [0, 1].map(|_| random.next() * 40.0 * dem.cell_size_m);
                let points = [
                    corner,
                    [corner[0] + size[0], corner[1]],
                    [corner[0], corner[1] + size[1]],
                    [corner[0] + size[0], corner[1] + size[1]],
                ];
                let highest = terrain.highest_near(&points);
                for _ in 0..20 {
                    let (x, y) = (
                        corner[0] + random.next() * size[0],
                        corner[1] + random.next() * size[1],
                    );
                    let to_fixed = 65536.0 / dem.cell_size_m;
                    let (fx, fy) = ((x * to_fixed) as i64, (y * to_fixed) as i64);
                    for subvoxel in [false, true] {
                        let fixed = terrain
                            .height_fixed(fx, fy, subvoxel)
                            .map(|z| z as f64 / 65536.0);
                        for z in [terrain.height(x, y, subvoxel), fixed]
                            .into_iter()
                            .flatten()
                        {
                            assert!(z <= highest, "{}: {z} above {highest}", dem.name);
                            checked += 1;
                        }
                    }
                }
            }
            assert!(checked > 20_000, "{}: {checked} samples", dem.name);
        }
    }

    #[test]
    fn skipping_empty_space_changes_no_pixel() {
        for (dem, mask) in masked_and_whole_dems() {
            let (side, cell) = (dem.side, dem.cell_size_m);
            let terrain = Terrain::new(side, cell, &dem.heights, &mask, None);
            let every_slice =
                Terrain::new(side, cell, &dem.heights, &mask, None).without_skipping();
            let extent = (side - 1) as f64 * cell;
            let top = dem.heights.iter().copied().fold(f32::MIN, f32::max) as f64;
            for (eye, heading, pitch) in [
                ([0.5 * extent, 0.5 * extent, top + 100.0], 30.0, 0.0),
                ([0.15 * extent, 0.1 * extent, top + 150.0], 35.0, -30.0),
                ([-0.1 * extent, 0.5 * extent, top * 0.5], 90.0, 10.0),
                ([1.1 * extent, 1.1 * extent, top + 300.0], 225.0, 0.0),
            ] {
                let mut cam = camera(240, 135, eye, heading, 90.0, 2.0 * extent);
                cam.pitch_deg = pitch;
                if pitch != 0.0 {
                    cam.incl_px = 67.5;
                }
                for (mode, arithmetic, subvoxel, grow_steps) in [
                    (RaycastMode::Raycast, Arithmetic::Float, false, false),
                    (RaycastMode::Raycast, Arithmetic::Float, true, true),
                    (RaycastMode::Raycast, Arithmetic::Fixed, true, false),
                    (RaycastMode::Distorted, Arithmetic::Float, false, false),
                ] {
                    if mode == RaycastMode::Distorted && pitch != 0.0 {
                        continue;
                    }
                    let options = RenderOptions {
                        mode,
                        arithmetic,
                        bands: vec![DistanceBand {
                            until_m: f64::INFINITY,
                            slices_per_cell: 1.0,
                            subvoxel,
                        }],
                        grow_steps,
                        ..Default::default()
                    };
                    let skipped = render(&terrain, &cam, &options).unwrap().to_rows();
                    let all = render(&every_slice, &cam, &options).unwrap().to_rows();
                    assert!(
                        skipped.rgba == all.rgba && skipped.depth == all.depth,
                        "{} from {eye:?} pitch {pitch}: {options:?}",
                        dem.name
                    );
                    assert!(skipped.depth.iter().any(|&d| d < 1.0));
                }
            }
        }
    }

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
                    for mode in [RaycastMode::Raycast, RaycastMode::Distorted] {
                        let options = RenderOptions {
                            mode,
                            arithmetic,
                            bands: vec![DistanceBand {
                                until_m: f64::INFINITY,
                                slices_per_cell: 2.0,
                                subvoxel,
                            }],
                            ..Default::default()
                        };
                        let (a, b) = (
                            render(&floor, &cam, &options).unwrap().to_rows(),
                            render(&walled, &cam, &options).unwrap().to_rows(),
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
    fn an_empty_viewport_renders_an_empty_frame() {
        let (heights, mask, _, _) = poles();
        let terrain = Terrain::new(257, 1.0, &heights, &mask, None);
        for (w, h, pitch) in [(0, 90, 0.0), (160, 0, -20.0), (0, 0, 10.0)] {
            let mut cam = camera(w, h, [128.0, 0.0, 30.0], 0.0, 0.0, 400.0);
            cam.pitch_deg = pitch;
            let frame = render(&terrain, &cam, &RenderOptions::default()).unwrap();
            assert!(frame.rgba.is_empty() && frame.depth.is_empty());
        }
    }

    /// Slices that spread with distance draw fewer slices on a real DEM seen
    /// across its whole width, and stay within the stated bound of the
    /// full-resolution image: PSNR ≥ 30 dB, terrain and sky agreeing on 99 %
    /// of the pixels.
    #[test]
    fn growing_steps_stay_within_the_stated_image_bound() {
        let dem = crate::testdata::dem("srtm_ref_257.f32");
        let (side, cell) = (dem.side, dem.cell_size_m);
        let extent = (side - 1) as f64 * cell;
        let mask = vec![1u8; side * side];
        let terrain =
            Terrain::new(side, cell, &dem.heights, &mask, None).with_hillshade(315.0, 40.0);
        let top = dem.heights.iter().copied().fold(f32::MIN, f32::max) as f64;
        for heading in [20.0, 65.0] {
            let mut cam = camera(
                480,
                270,
                [0.05 * extent, 0.05 * extent, top + 100.0],
                heading,
                190.0,
                2.0 * extent,
            );
            cam.near_m = cell;
            let mut full = Raycaster::default();
            full.render(&terrain, &cam, &RenderOptions::default())
                .unwrap();
            let mut grown = Raycaster::default();
            let options = RenderOptions {
                grow_steps: true,
                ..Default::default()
            };
            grown.render(&terrain, &cam, &options).unwrap();
            let psnr = grown.frame.psnr_db(&full.frame);
            let disagree = full
                .frame
                .to_rows()
                .depth
                .iter()
                .zip(&grown.frame.to_rows().depth)
                .filter(|(a, b)| (**a < 1.0) != (**b < 1.0))
                .count();
            eprintln!(
                "heading {heading}: {} of {} slices, PSNR {psnr:.1} dB, {disagree} pixels disagree on terrain/sky",
                grown.slices.len(),
                full.slices.len()
            );
            assert!(grown.slices.len() * 10 < full.slices.len() * 9);
            assert!(psnr >= 30.0, "PSNR {psnr} dB");
            assert!(disagree * 100 < 480 * 270, "{disagree} pixels");
        }
    }

    #[test]
    fn fixed_point_matches_floating_point() {
        let (heights, mask, rgba, _) = poles();
        let side = 257;
        let color = texel_per_cell(&rgba, side);
        let terrain = Terrain::new(side, 1.0, &heights, &mask, Some(color));
        let cam = camera(320, 180, [128.0, 0.0, 30.0], 10.0, 120.0, 400.0);
        let float = render(&terrain, &cam, &RenderOptions::default())
            .unwrap()
            .to_rows();
        let fixed = render(
            &terrain,
            &cam,
            &RenderOptions {
                arithmetic: Arithmetic::Fixed,
                ..Default::default()
            },
        )
        .unwrap()
        .to_rows();
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
            let f = render(&terrain, &cam, &opts).unwrap().to_rows();
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
