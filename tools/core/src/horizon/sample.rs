//! What the raycaster samples: heights (nearest voxel or sub-voxel
//! bilinear), the mask, and colour from the drape image (optionally from a
//! prefiltered level and with baked hillshade).

use crate::geo::{GeoTransform, TerrainFrame};
use crate::grid::{vertex_normal, EIGHT_NEIGHBOURS};
use rayon::prelude::*;
use std::borrow::Cow;

/// Sub-voxel divisions per cell side (seed 000, §6.2 uses 8).
const DIVISIONS: usize = 8;

/// Side of the square tiles the march's heights are stored in, vertices: a
/// tile is 1 KiB, four to a page.
const TILE: usize = 16;

/// Where vertex (`c`, `r`) lies in tiles of [`TILE`]² stored row by row
/// (32 bits, so that the march computes many at once in SIMD lanes).
#[inline(always)]
fn tile_index(tiles_across: u32, c: u32, r: u32) -> u32 {
    let tile = TILE as u32;
    ((r / tile) * tiles_across + c / tile) * tile * tile + (r % tile) * tile + c % tile
}

/// `x.round()` (halfway cases away from zero) without a call to the maths
/// library: the baseline x86-64 has no rounding instruction, and the drape's
/// colour lookup, compiled for it (out of the march's AVX2 code), rounds five
/// times a sample. Bit for bit `f64::round` (tested).
#[inline(always)]
fn round_half_away(x: f64) -> f64 {
    // From 2⁵² on every f64 is an integer; ±∞ and NaN stay as they are.
    if x.is_nan() || x.abs() >= 4_503_599_627_370_496.0 {
        return x;
    }
    // Toward zero, and the fraction left: both exact below 2⁵².
    let whole = x as i64 as f64;
    let fraction = x - whole;
    let rounded = if fraction >= 0.5 {
        whole + 1.0
    } else if fraction <= -0.5 {
        whole - 1.0
    } else {
        whole
    };
    // A zero keeps the sign of x, as `f64::round` gives it.
    rounded.copysign(x)
}

/// `x` rounded half away from zero and clamped to a byte:
/// `round_half_away(x).clamp(0.0, 255.0) as u8` (NaN gives 0), with the
/// clamp first so that the rounding only meets 0 ≤ x ≤ 255 (or NaN, which
/// truncates to 0 and compares false).
#[inline(always)]
fn byte_of(x: f64) -> u8 {
    let x = x.clamp(0.0, 255.0);
    let whole = x as u32;
    (whole + u32::from(x - whole as f64 >= 0.5)) as u8
}

/// Bilinear weights of the four voxels around each of the DIVISIONS² sub-voxels,
/// `[top-left, top-right, bottom-left, bottom-right]` in grid order — the
/// contribution matrix of seed 000, Algorithm 3, taken at sub-voxel centres.
fn contribution_matrix() -> [[[f64; 4]; DIVISIONS]; DIVISIONS] {
    let mut m = [[[0.0; 4]; DIVISIONS]; DIVISIONS];
    for (p, row) in m.iter_mut().enumerate() {
        for (q, w) in row.iter_mut().enumerate() {
            let (u, v) = (
                (q as f64 + 0.5) / DIVISIONS as f64,
                (p as f64 + 0.5) / DIVISIONS as f64,
            );
            *w = [(1.0 - u) * (1.0 - v), u * (1.0 - v), (1.0 - u) * v, u * v];
        }
    }
    m
}

/// One level of the colour pyramid.
struct Level {
    width: usize,
    height: usize,
    texels: Vec<[u8; 4]>,
    /// Its texels per level-0 pixel, 2^−level.
    per_pixel: f64,
    /// The last column and row, which the lookups clamp to: kept as f64
    /// so that no lookup converts them from integers again.
    last: [f64; 2],
}

impl Level {
    /// Level `index` of the pyramid: `texels`, `width`×`height`, row-major.
    fn new(index: usize, width: usize, height: usize, texels: Vec<[u8; 4]>) -> Level {
        Level {
            width,
            height,
            texels,
            per_pixel: 0.5f64.powi(index as i32),
            last: [
                width.saturating_sub(1) as f64,
                height.saturating_sub(1) as f64,
            ],
        }
    }
}

/// The drape image, as levels halving in size (level 0 is the image).
pub struct ColorSource {
    levels: Vec<Level>,
    /// Terrain frame (x, y) → level-0 pixel (u, v): u = a₀ + a₁x + a₂y, v = a₃ + a₄x + a₅y.
    to_pixel: [f64; 6],
    /// Ground size of a level-0 pixel, metres.
    texel_m: f64,
}

impl ColorSource {
    /// `rgba` (row-major, `width`×`height`) georeferenced by `color_geo`,
    /// draped over the grid of `frame`.
    pub fn new(
        rgba: &[u8],
        width: usize,
        height: usize,
        color_geo: &GeoTransform,
        frame: &TerrainFrame,
    ) -> Option<Self> {
        // Terrain frame → world → colour pixel, all affine.
        let to_pixel = frame.terrain_to_pixel(color_geo)?;
        let texel_m = color_geo.cell_size().0.max(color_geo.cell_size().1);
        let mut levels = vec![Level::new(
            0,
            width,
            height,
            rgba.chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]])
                .collect(),
        )];
        while let Some(prev) = levels.last().filter(|l| l.width > 1 || l.height > 1) {
            let (w, h) = (prev.width.div_ceil(2), prev.height.div_ceil(2));
            let mut texels = Vec::with_capacity(w * h);
            for r in 0..h {
                for c in 0..w {
                    // Average of the (up to four) texels below, weighting by alpha.
                    let mut sum = [0u32; 4];
                    for (dc, dr) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let t = prev.texels[(2 * r + dr).min(prev.height - 1) * prev.width
                            + (2 * c + dc).min(prev.width - 1)];
                        for k in 0..4 {
                            sum[k] += t[k] as u32;
                        }
                    }
                    texels.push(sum.map(|s| ((s + 2) / 4) as u8));
                }
            }
            levels.push(Level::new(levels.len(), w, h, texels));
        }
        Some(ColorSource {
            levels,
            to_pixel,
            texel_m,
        })
    }
}

/// The grid position (column, row, fractional) of terrain-frame point
/// (`x`, `y`) metres, on a grid whose cells are `1 / inv_cell` metres and
/// whose last vertex is `last` (side − 1): columns grow east, rows south.
#[inline(always)]
pub fn grid_position(x: f64, y: f64, inv_cell: f64, last: f64) -> (f64, f64) {
    (x * inv_cell, last - y * inv_cell)
}

/// `heights` with every masked vertex that has data among its eight
/// neighbours set to the mean of those neighbours' heights; `None` when
/// there is no such vertex.
fn heights_beside_data(heights: &[f32], mask: &[u8], side: usize) -> Option<Vec<f32>> {
    let beside = |i: usize| -> Option<f32> {
        let (c, r) = ((i % side) as i64, (i / side) as i64);
        let (mut sum, mut count) = (0.0f64, 0u32);
        for (dc, dr) in EIGHT_NEIGHBOURS {
            let (nc, nr) = (c + dc, r + dr);
            if nc >= 0 && nr >= 0 && (nc as usize) < side && (nr as usize) < side {
                let k = nr as usize * side + nc as usize;
                if mask[k] == 1 {
                    sum += heights[k] as f64;
                    count += 1;
                }
            }
        }
        (count > 0).then(|| (sum / count as f64) as f32)
    };
    let changed: Vec<(usize, f32)> = (0..side * side)
        .into_par_iter()
        .filter(|&i| mask[i] != 1)
        .filter_map(|i| beside(i).map(|z| (i, z)))
        .filter(|&(i, z)| z != heights[i])
        .collect();
    if changed.is_empty() {
        return None;
    }
    let mut out = heights.to_vec();
    for (i, z) in changed {
        out[i] = z;
    }
    Some(out)
}

/// Where the vertex nearest a terrain-frame point is kept in the march's
/// tiles; off the grid, the element past them (NaN height). Branch-free
/// 32-bit arithmetic on constants copied out of the terrain, so that the
/// march computes many lanes at once in SIMD registers (mask not checked:
/// masked heights are NaN). Grid positions are f32 — eight lanes to an AVX2
/// register — whose error (an f32 ulp, 2⁻¹² cell at column 4096) moves the
/// nearest vertex only for points that close to halfway between two.
#[derive(Clone, Copy)]
struct VertexIndex {
    inv_cell: f64,
    /// side − 1.
    last: f64,
    tiles_across: u32,
    off_grid: u32,
}

impl VertexIndex {
    #[inline(always)]
    fn of(terrain: &Terrain) -> Self {
        VertexIndex {
            inv_cell: terrain.inv_cell,
            last: terrain.last,
            tiles_across: terrain.tiles_across as u32,
            off_grid: (terrain.tiled.len() - 1) as u32,
        }
    }

    /// The vertex nearest terrain-frame point (x, y), metres.
    #[inline(always)]
    fn nearest(self, x: f64, y: f64) -> u32 {
        let [column, row] = self.to_grid([x, y]);
        self.at(column as f32, row as f32)
    }

    /// Grid position (column, row) of terrain-frame point `p`, each plus ½
    /// so that truncating gives the nearest vertex.
    #[inline(always)]
    fn to_grid(self, p: [f64; 2]) -> [f64; 2] {
        [
            p[0] * self.inv_cell + 0.5,
            self.last - p[1] * self.inv_cell + 0.5,
        ]
    }

    /// The vertex at grid position (`c`, `r`) plus ½ each (see
    /// [`VertexIndex::to_grid`]).
    #[inline(always)]
    fn at(self, c: f32, r: f32) -> u32 {
        let last = self.last as f32;
        let side = last + 1.0;
        let on_grid = (c >= 0.0) & (r >= 0.0) & (c < side) & (r < side);
        // SAFETY: clamped onto the grid (NaN to 0), so finite and in
        // [0, side − 1], which fits an i32.
        let (column, row) = unsafe {
            (
                c.max(0.0).min(last).to_int_unchecked::<i32>() as u32,
                r.max(0.0).min(last).to_int_unchecked::<i32>() as u32,
            )
        };
        let index = tile_index(self.tiles_across, column, row);
        if on_grid {
            index
        } else {
            self.off_grid
        }
    }
}

/// A packet's lanes in grid units, for [`Terrain::nearest_heights`]: the
/// eye's grid position (plus ½, see [`VertexIndex::to_grid`]) and each
/// lane's direction in cells per metre, so that a slice's positions are one
/// multiply-add a lane in f32.
pub(super) struct LaneCells<const N: usize> {
    eye: [f32; 2],
    dirs: [[f32; N]; 2],
}

/// The terrain the raycaster reads.
pub struct Terrain<'a> {
    pub side: usize,
    /// Vertex spacing, metres.
    pub cell_m: f64,
    heights: Cow<'a, [f32]>,
    /// What the bilinear surface reads where it differs from `heights`:
    /// masked vertices beside data hold the mean of their data neighbours,
    /// so a sample near the data's edge never blends in whatever the
    /// padding holds (it would rise or fall as a curtain along the edge).
    /// `None` when no masked vertex touches data.
    edge_heights: Option<Vec<f32>>,
    /// The heights the march reads (NaN where the mask is 0), in tiles of
    /// [`TILE`]² vertices so that neighbouring rays and slices share cache
    /// lines and pages.
    tiled: Vec<f32>,
    /// Tiles per row of tiles.
    tiles_across: usize,
    /// Per vertex, the colour used without imagery (a grey ramp by height,
    /// shaded), in the same tiles as `tiled`.
    vertex_colours: Vec<u32>,
    /// The highest and lowest heights with data, metres (∓∞ without data).
    pub(super) highest_m: f64,
    pub(super) lowest_m: f64,
    /// Per tile of `tiled`, the highest height with data in it, metres
    /// (−∞ for a tile without data): the coarse level of a max-height
    /// pyramid, which lets the march skip slices that cannot rise above
    /// the horizon.
    tile_highest: Vec<f32>,
    /// Heights in 16.16 fixed point, built on the first fixed-point render.
    heights_fixed: std::sync::OnceLock<Vec<i32>>,
    mask: Cow<'a, [u8]>,
    color: Option<ColorSource>,
    /// Per-vertex light factor, when hillshade is baked in.
    shade: Option<Vec<f32>>,
    weights: [[[f64; 4]; DIVISIONS]; DIVISIONS],
    inv_cell: f64,
    last: f64,
}

impl Terrain<'_> {
    /// Bytes a terrain holds per grid vertex at most: the heights and the
    /// surface's edge copy, the tiled march copy, vertex colours, the
    /// hillshade and fixed-point heights (4 bytes each) and the mask.
    const BYTES_PER_VERTEX: u64 = 25;
    /// Bytes the drape's colour levels hold per drape pixel (the image and
    /// its halving levels, 4/3 × 4 bytes, rounded up).
    const BYTES_PER_DRAPE_PIXEL: u64 = 6;

    /// Refuse, before anything is allocated, a terrain of `side`² vertices
    /// with a drape of `drape_pixels` that the memory budget cannot hold or
    /// the march's 32-bit indices cannot address. Every caller building a
    /// [`Terrain`] from a bundle checks here first.
    pub fn check_size(side: usize, drape_pixels: u64) -> crate::Result<()> {
        let tiles_across = side.div_ceil(TILE) as u64;
        if tiles_across * tiles_across * (TILE * TILE) as u64 >= u64::from(u32::MAX) {
            return Err(crate::Error::Input(format!(
                "the raycaster addresses at most {}² vertices; this grid has {side}²",
                (u32::MAX as f64).sqrt() as u64 / TILE as u64 * TILE as u64
            )));
        }
        let vertices = (side as u64).saturating_mul(side as u64);
        crate::memory::check(
            &format!("the raycaster's copy of the {side}×{side} grid and its drape"),
            1,
            vertices
                .saturating_mul(Self::BYTES_PER_VERTEX)
                .saturating_add(drape_pixels.saturating_mul(Self::BYTES_PER_DRAPE_PIXEL)),
            "open a smaller region",
        )
    }
}

impl<'a> Terrain<'a> {
    /// A terrain over `heights` (metres) and `mask`, borrowed (e.g. from a
    /// mapped bundle) or owned (a viewer keeping one for its session).
    /// Grids from user data are checked with [`Terrain::check_size`] first;
    /// this panics on a grid the march cannot address.
    pub fn new(
        side: usize,
        cell_m: f64,
        heights: impl Into<Cow<'a, [f32]>>,
        mask: impl Into<Cow<'a, [u8]>>,
        color: Option<ColorSource>,
    ) -> Self {
        let (heights, mask) = (heights.into(), mask.into());
        assert_eq!(heights.len(), side * side);
        assert_eq!(mask.len(), side * side);
        let tiles_across = side.div_ceil(TILE);
        // The march indexes the tiles (and one more) with 32 bits.
        assert!(tiles_across * tiles_across * TILE * TILE < u32::MAX as usize);
        // One NaN past the tiles: where samples off the grid read (see
        // `nearest_index`).
        let mut tiled = vec![f32::NAN; tiles_across * tiles_across * TILE * TILE + 1];
        let (mut highest_m, mut lowest_m) = (f64::NEG_INFINITY, f64::INFINITY);
        for r in 0..side {
            for c in 0..side {
                let i = r * side + c;
                if mask[i] == 1 {
                    tiled[tile_index(tiles_across as u32, c as u32, r as u32) as usize] =
                        heights[i];
                    highest_m = highest_m.max(heights[i] as f64);
                    lowest_m = lowest_m.min(heights[i] as f64);
                }
            }
        }
        let tile_highest = tiled
            .chunks_exact(TILE * TILE)
            .map(|tile| {
                tile.iter()
                    .copied()
                    .filter(|z| !z.is_nan())
                    .fold(f32::NEG_INFINITY, f32::max)
            })
            .collect();
        let edge_heights = heights_beside_data(&heights, &mask, side);
        let mut terrain = Terrain {
            side,
            cell_m,
            heights,
            edge_heights,
            tiled,
            tiles_across,
            vertex_colours: vec![0; tiles_across * tiles_across * TILE * TILE + 1],
            highest_m,
            lowest_m,
            tile_highest,
            heights_fixed: std::sync::OnceLock::new(),
            mask,
            color,
            shade: None,
            weights: contribution_matrix(),
            inv_cell: 1.0 / cell_m,
            last: (side - 1) as f64,
        };
        terrain.update_vertex_colors();
        terrain
    }

    /// Heights in metres, row-major, `side`×`side`.
    pub fn heights(&self) -> &[f32] {
        &self.heights
    }

    /// The heights the bilinear surface reads (see `edge_heights`).
    fn surface_heights(&self) -> &[f32] {
        self.edge_heights.as_deref().unwrap_or(&self.heights)
    }

    /// The data mask (1 data, 0 padding or void), row-major.
    pub fn mask(&self) -> &[u8] {
        &self.mask
    }

    /// Recompute the per-vertex colours used when there is no imagery.
    fn update_vertex_colors(&mut self) {
        if self.color.is_some() {
            return;
        }
        for i in 0..self.side * self.side {
            let g = (80.0 + (self.heights[i] as f64 * 0.05).rem_euclid(150.0)).min(255.0);
            let light = self.shade.as_ref().map_or(1.0, |s| s[i] as f64);
            let v = (g * light).round().clamp(0.0, 255.0) as u8;
            let (c, r) = ((i % self.side) as u32, (i / self.side) as u32);
            let at = tile_index(self.tiles_across as u32, c, r) as usize;
            self.vertex_colours[at] = u32::from_le_bytes([v, v, v, 255]);
        }
    }

    /// Bake a hillshade into the colour: Lambert shading of the grid's
    /// normals for a sun at `azimuth_deg` (clockwise from north) and
    /// `elevation_deg`, with 35 % ambient light.
    pub fn with_hillshade(self, azimuth_deg: f64, elevation_deg: f64) -> Self {
        let (side, cell) = (self.side, self.cell_m);
        let shade = (0..side * side)
            .map(|i| {
                let n = vertex_normal(self.surface_heights(), side, cell, i % side, i / side);
                hillshade(n, azimuth_deg, elevation_deg)
            })
            .collect();
        self.with_shade(shade)
    }

    /// Bake `shade`, a light factor per vertex (row-major, as
    /// [`hillshade`] gives it), into the colour — for a caller whose normals
    /// see past this grid's edges (a window of a larger grid).
    pub fn with_shade(mut self, shade: Vec<f32>) -> Self {
        assert_eq!(shade.len(), self.side * self.side);
        self.shade = Some(shade);
        self.update_vertex_colors();
        self
    }

    /// Colour level whose texels match a screen pixel of `metres_per_pixel`.
    pub(super) fn color_level(&self, metres_per_pixel: f64) -> usize {
        match &self.color {
            None => 0,
            Some(c) => {
                let ratio = metres_per_pixel / c.texel_m;
                if ratio <= 1.0 {
                    0
                } else {
                    (ratio.log2().floor() as usize).min(c.levels.len() - 1)
                }
            }
        }
    }

    /// The highest height a sample can read — nearest vertex or bilinear
    /// surface — anywhere in the box around `points` (terrain-frame metres),
    /// from the tiles the box touches; −∞ where it holds no data.
    pub(super) fn highest_near(&self, points: &[[f64; 2]]) -> f64 {
        let (mut low, mut high) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for &[x, y] in points {
            let (c, r) = self.grid(x, y);
            low = [low[0].min(c), low[1].min(r)];
            high = [high[0].max(c), high[1].max(r)];
        }
        // Two vertices of margin: the nearest vertex is half a cell away,
        // the bilinear surface reads the next one, and the heights it
        // gives masked vertices beside data come from their neighbours.
        const MARGIN: f64 = 2.0;
        if high[0] + MARGIN < 0.0
            || high[1] + MARGIN < 0.0
            || low[0] - MARGIN > self.last
            || low[1] - MARGIN > self.last
        {
            return f64::NEG_INFINITY;
        }
        let tile = |v: f64| v.clamp(0.0, self.last) as usize / TILE;
        let mut highest = f32::NEG_INFINITY;
        for tile_row in tile(low[1] - MARGIN)..=tile(high[1] + MARGIN) {
            let across = tile_row * self.tiles_across;
            for tile_column in tile(low[0] - MARGIN)..=tile(high[0] + MARGIN) {
                highest = highest.max(self.tile_highest[across + tile_column]);
            }
        }
        highest as f64
    }

    /// The same terrain with no slice ever skipped (every tile as high as
    /// can be), to check that skipping changes nothing.
    #[cfg(test)]
    pub(super) fn without_skipping(mut self) -> Self {
        self.tile_highest.fill(f32::INFINITY);
        self
    }

    /// Grid position (column, row), fractional, of terrain-frame (x, y).
    #[inline]
    fn grid(&self, x: f64, y: f64) -> (f64, f64) {
        grid_position(x, y, self.inv_cell, self.last)
    }

    /// Where the vertex nearest (x, y) is kept in `tiled` and
    /// `vertex_colours` (see [`VertexIndex`]).
    #[inline(always)]
    fn nearest_index(&self, x: f64, y: f64) -> u32 {
        VertexIndex::of(self).nearest(x, y)
    }

    /// Nearest vertex with data, if (c, r) is on the grid.
    #[inline]
    fn vertex(&self, c: f64, r: f64) -> Option<usize> {
        let (c, r) = (round_half_away(c), round_half_away(r));
        if c < 0.0 || r < 0.0 || c > (self.side - 1) as f64 || r > (self.side - 1) as f64 {
            return None;
        }
        let i = r as usize * self.side + c as usize;
        (self.mask[i] == 1).then_some(i)
    }

    /// The four vertices around (c, r) and the weights of its sub-voxel.
    #[inline]
    fn bilinear(&self, c: f64, r: f64) -> ([usize; 4], [f64; 4]) {
        let last = (self.side - 2) as f64;
        let (c0, r0) = (c.floor().clamp(0.0, last), r.floor().clamp(0.0, last));
        let q = (((c - c0) * DIVISIONS as f64) as usize).min(DIVISIONS - 1);
        let p = (((r - r0) * DIVISIONS as f64) as usize).min(DIVISIONS - 1);
        let i = r0 as usize * self.side + c0 as usize;
        (
            [i, i + 1, i + self.side, i + self.side + 1],
            self.weights[p][q],
        )
    }

    /// Height of the vertex nearest (x, y), metres; NaN off the grid or
    /// where the mask is 0. The march's one memory access per sample.
    #[inline]
    pub(super) fn nearest_height(&self, x: f64, y: f64) -> f32 {
        self.tiled[self.nearest_index(x, y) as usize]
    }

    /// `eye` and the lanes' ground directions `dirs` (one array per axis,
    /// metres per metre of s) in grid units, for [`Terrain::nearest_heights`].
    pub(super) fn lane_cells<const N: usize>(
        &self,
        eye: [f64; 2],
        dirs: &[[f64; N]; 2],
    ) -> LaneCells<N> {
        let grid_eye = VertexIndex::of(self).to_grid(eye);
        LaneCells {
            eye: grid_eye.map(|v| v as f32),
            dirs: [
                dirs[0].map(|d| (d * self.inv_cell) as f32),
                dirs[1].map(|d| (-d * self.inv_cell) as f32),
            ],
        }
    }

    /// The nearest vertex's height `s` metres along every lane of `lanes`,
    /// and where each lane's vertex is kept (for [`Terrain::vertex_colour`]):
    /// the indices of all lanes first, side by side, then the loads, all in
    /// flight together.
    #[inline(always)]
    pub(super) fn nearest_heights<const N: usize>(
        &self,
        lanes: &LaneCells<N>,
        s: f64,
        out: &mut [f64; N],
        index: &mut [u32; N],
    ) {
        let vertex_index = VertexIndex::of(self);
        let s = s as f32;
        for (k, vertex) in index.iter_mut().enumerate() {
            *vertex = vertex_index.at(
                lanes.eye[0] + lanes.dirs[0][k] * s,
                lanes.eye[1] + lanes.dirs[1][k] * s,
            );
        }
        // Every index lies in `tiled` (`VertexIndex::at`); checked once for
        // the lanes rather than at every load.
        let last = index.iter().fold(0, |last, &i| last.max(i));
        assert!(
            (last as usize) < self.tiled.len(),
            "a vertex outside the tiles"
        );
        for k in 0..N {
            // SAFETY: index[k] ≤ last < tiled.len() (checked above).
            out[k] = unsafe { *self.tiled.get_unchecked(index[k] as usize) } as f64;
        }
    }

    /// Terrain height at (x, y), metres; `None` off the grid or over masked cells.
    #[inline]
    pub fn height(&self, x: f64, y: f64, subvoxel: bool) -> Option<f64> {
        let z = self.nearest_height(x, y);
        if z.is_nan() {
            return None;
        }
        if !subvoxel {
            return Some(z as f64);
        }
        let (c, r) = self.grid(x, y);
        let (v, w) = self.bilinear(c, r);
        let heights = self.surface_heights();
        Some((0..4).map(|k| w[k] * heights[v[k]] as f64).sum())
    }

    /// The exact bilinear surface through the vertices at (x, y), metres;
    /// `None` off the grid or over masked cells.
    pub fn surface(&self, x: f64, y: f64) -> Option<f64> {
        let (c, r) = self.grid(x, y);
        self.surface_at(c, r)
    }

    /// The exact bilinear surface at grid position (`c`, `r`) (columns and
    /// rows from the first vertex, fractional), metres; `None` off the grid
    /// or when the nearest vertex has no data. A window of a larger grid
    /// holding the cell and one vertex around it gives the larger grid's
    /// value bit for bit at the shifted position.
    pub fn surface_at(&self, c: f64, r: f64) -> Option<f64> {
        self.vertex(c, r)?;
        let last = (self.side - 2) as f64;
        let (c0, r0) = (c.floor().clamp(0.0, last), r.floor().clamp(0.0, last));
        let (u, v) = (c - c0, r - r0);
        let i = r0 as usize * self.side + c0 as usize;
        let heights = self.surface_heights();
        let z = |k: usize| heights[k] as f64;
        let top = z(i) * (1.0 - u) + z(i + 1) * u;
        let bottom = z(i + self.side) * (1.0 - u) + z(i + self.side + 1) * u;
        Some(top * (1.0 - v) + bottom * v)
    }

    /// The heights in 16.16 fixed point (|h| < 32768 m fits an i32).
    fn fixed_heights(&self) -> &[i32] {
        self.heights_fixed.get_or_init(|| {
            self.surface_heights()
                .iter()
                .map(|&h| (h as f64 * 65536.0) as i32)
                .collect()
        })
    }

    /// Height at a 16.16 fixed-point grid position (`x`, `y` in cells of the
    /// terrain frame), in 16.16 metres.
    #[inline]
    pub(super) fn height_fixed(&self, x: i64, y: i64, subvoxel: bool) -> Option<i64> {
        let last = ((self.side - 1) as i64) << 16;
        let (c, r) = (x, last - y);
        if c < -(1 << 15) || r < -(1 << 15) || c >= last + (1 << 15) || r >= last + (1 << 15) {
            return None;
        }
        let (nc, nr) = (
            ((c + (1 << 15)) >> 16) as usize,
            ((r + (1 << 15)) >> 16) as usize,
        );
        let nearest = nr * self.side + nc;
        if self.mask[nearest] != 1 {
            return None;
        }
        let fixed = self.fixed_heights();
        if !subvoxel {
            return Some(fixed[nearest] as i64);
        }
        let max = ((self.side - 2) as i64) << 16;
        let (c, r) = (c.clamp(0, max + 0xffff), r.clamp(0, max + 0xffff));
        let (c0, r0) = (
            (c >> 16).min(self.side as i64 - 2) as usize,
            (r >> 16).min(self.side as i64 - 2) as usize,
        );
        let q = (((c - ((c0 as i64) << 16)) * DIVISIONS as i64) >> 16)
            .clamp(0, DIVISIONS as i64 - 1) as usize;
        let p = (((r - ((r0 as i64) << 16)) * DIVISIONS as i64) >> 16)
            .clamp(0, DIVISIONS as i64 - 1) as usize;
        let w = self.weights[p][q];
        let i = r0 * self.side + c0;
        let v = [i, i + 1, i + self.side, i + self.side + 1];
        Some((0..4).map(|k| (w[k] * fixed[v[k]] as f64) as i64).sum())
    }

    /// Colour at (x, y) from colour level `level`, RGBA packed little-endian.
    #[inline]
    pub fn color(&self, x: f64, y: f64, subvoxel: bool, level: usize) -> u32 {
        match &self.color {
            None => self.vertex_colours[self.nearest_index(x, y) as usize],
            Some(src) => self.image_color(src, x, y, subvoxel, level),
        }
    }

    /// The colour of the vertex kept at `index` (as
    /// [`Terrain::nearest_heights`] gives it) where the terrain is coloured
    /// by vertex; `None` where it is draped with an image.
    #[inline(always)]
    pub(super) fn vertex_colour(&self, index: u32) -> Option<u32> {
        self.color
            .is_none()
            .then(|| self.vertex_colours[index as usize])
    }

    /// [`Terrain::color`] from the drape image (kept out of line: the march
    /// inlines only the vertex colours' lookup).
    #[inline(never)]
    fn image_color(&self, src: &ColorSource, x: f64, y: f64, subvoxel: bool, level: usize) -> u32 {
        let (c, r) = self.grid(x, y);
        let light = match &self.shade {
            None => 1.0,
            Some(shade) => match self.vertex(c, r) {
                Some(i) => shade[i],
                None => 1.0,
            },
        };
        let rgb: [f64; 3] = {
            {
                let t = &src.to_pixel;
                let lv = &src.levels[level];
                // Scaling by a power of two is exact.
                let u = (t[0] + t[1] * x + t[2] * y) * lv.per_pixel;
                let v = (t[3] + t[4] * x + t[5] * y) * lv.per_pixel;
                // Clamped (NaN to 0), then truncated (images are far
                // narrower than 2³² texels).
                let texel = |cu: f64, cv: f64| {
                    let cu = cu.max(0.0).min(lv.last[0]) as u32 as usize;
                    let cv = cv.max(0.0).min(lv.last[1]) as u32 as usize;
                    lv.texels[cv * lv.width + cu]
                };
                if subvoxel {
                    let (u0, v0) = ((u - 0.5).floor(), (v - 0.5).floor());
                    let (fu, fv) = (u - 0.5 - u0, v - 0.5 - v0);
                    let ws = [
                        (1.0 - fu) * (1.0 - fv),
                        fu * (1.0 - fv),
                        (1.0 - fu) * fv,
                        fu * fv,
                    ];
                    let ts = [
                        texel(u0, v0),
                        texel(u0 + 1.0, v0),
                        texel(u0, v0 + 1.0),
                        texel(u0 + 1.0, v0 + 1.0),
                    ];
                    let mut rgb = [0.0; 3];
                    for (w, t) in ws.iter().zip(ts) {
                        for k in 0..3 {
                            rgb[k] += w * t[k] as f64;
                        }
                    }
                    rgb
                } else {
                    // `texel` truncates after clamping at 0, which for
                    // these is the floor.
                    let t = texel(u, v);
                    [t[0] as f64, t[1] as f64, t[2] as f64]
                }
            }
        };
        let [r8, g8, b8] = rgb.map(|v| byte_of(v * light as f64));
        u32::from_le_bytes([r8, g8, b8, 255])
    }

    /// [`Terrain::color`] at a 16.16 fixed-point grid position.
    #[inline]
    pub(super) fn color_fixed(&self, x: i64, y: i64, subvoxel: bool, level: usize) -> u32 {
        let to_m = self.cell_m / 65536.0;
        self.color(x as f64 * to_m, y as f64 * to_m, subvoxel, level)
    }
}

/// The light factor of a surface of unit normal `normal` (terrain frame,
/// z up) under a sun at `azimuth_deg` (clockwise from north) and
/// `elevation_deg`: Lambert shading with 35 % ambient light.
pub fn hillshade(normal: [f64; 3], azimuth_deg: f64, elevation_deg: f64) -> f32 {
    let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let sun = [az.sin() * el.cos(), az.cos() * el.cos(), el.sin()];
    let lambert = (normal[0] * sun[0] + normal[1] * sun[1] + normal[2] * sun[2]).max(0.0);
    (0.35 + 0.65 * lambert) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_without_the_library_is_f64_round() {
        let two_52 = 4_503_599_627_370_496.0_f64;
        let mut values = vec![
            0.0,
            0.5,
            1.5,
            2.5,
            0.499_999_999_999_999_94,
            1.0 - f64::EPSILON / 2.0,
            255.499_999_999_999_97,
            254.5,
            two_52 - 0.5,
            two_52 - 1.5,
            two_52,
            two_52 + 1.0,
            2.0 * two_52 + 2.0,
            f64::MAX,
            f64::MIN_POSITIVE,
            5e-324,
            f64::INFINITY,
            1e300,
        ];
        // Every quarter from −1000 to 1000, and their neighbours.
        for q in -4000..=4000 {
            let x = q as f64 / 4.0;
            values.extend([x, x.next_up(), x.next_down()]);
        }
        let negated: Vec<f64> = values.iter().map(|x| -x).collect();
        values.extend(negated);
        for x in values {
            assert_eq!(round_half_away(x).to_bits(), x.round().to_bits(), "{x:e}");
        }
        assert!(round_half_away(f64::NAN).is_nan());
    }

    #[test]
    fn bytes_are_the_rounded_values_clamped() {
        let mut values = vec![
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -0.0,
            0.499_999_999_999_999_94,
            254.5,
            254.499_999_999_999_97,
            255.499_999_999_999_97,
            255.5,
            1e300,
            -1e300,
        ];
        // Every 1/64 from −300 to 300, and their neighbours.
        for q in -19200..=19200 {
            let x = q as f64 / 64.0;
            values.extend([x, x.next_up(), x.next_down()]);
        }
        for x in values {
            assert_eq!(
                byte_of(x),
                round_half_away(x).clamp(0.0, 255.0) as u8,
                "{x:e}"
            );
        }
    }
}
