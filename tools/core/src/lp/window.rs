//! The hierarchy's errors and radii computed over a rectangle of the grid
//! (a tile and its halo, or the whole grid), in two passes:
//!
//! 1. [`own_errors`]: each vertex's own error from the heights of its
//!    diamond (or, for a diamond larger than the rectangle, [`own_partial`]
//!    over the part a rectangle holds — the parts' largest is the whole's);
//! 2. [`saturate`]: bottom-up, each vertex's error maxed with its
//!    children's and its radius enclosing theirs (LP seed §3.3).
//!
//! Every value is computed from global columns and rows with the same
//! arithmetic wherever the rectangle lies, so a vertex whose diamond and
//! descendants lie inside the rectangle gets exactly the value the whole
//! grid gives it: tiles computed this way agree bit for bit with the
//! single grid.

use super::diamond::{child_offsets, hypotenuse, level_rows, parents, step, vertex_kind, Vertex};
use super::metric::{midpoint_error, round_up, triangle_deviation, ErrorMetric};
use super::vertices::terrain_position;
use rayon::prelude::*;

/// A rectangle of grid vertices: columns `c0..c0 + width`, rows
/// `r0..r0 + height`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Rect {
    pub c0: usize,
    pub r0: usize,
    pub width: usize,
    pub height: usize,
}

impl Rect {
    /// The whole `side`² grid.
    pub fn whole(side: usize) -> Rect {
        Rect {
            c0: 0,
            r0: 0,
            width: side,
            height: side,
        }
    }

    /// Columns `c0..=c1`, rows `r0..=r1` of a `side`² grid, grown by
    /// `margin` on every side and clipped to the grid.
    pub fn around([c0, r0, c1, r1]: [usize; 4], margin: usize, side: usize) -> Rect {
        let (a, b) = (c0.saturating_sub(margin), r0.saturating_sub(margin));
        let (c, d) = ((c1 + margin).min(side - 1), (r1 + margin).min(side - 1));
        Rect {
            c0: a,
            r0: b,
            width: c - a + 1,
            height: d - b + 1,
        }
    }

    pub fn contains(&self, (c, r): Vertex) -> bool {
        c >= self.c0 && r >= self.r0 && c < self.c0 + self.width && r < self.r0 + self.height
    }

    /// Row-major position of (c, r) in an array over this rectangle.
    #[inline]
    pub fn index(&self, (c, r): Vertex) -> usize {
        (r - self.r0) * self.width + (c - self.c0)
    }

    pub fn len(&self) -> usize {
        self.width * self.height
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The first value ≥ `lo` that is ≡ `start` (mod `step`).
    fn first_from(lo: usize, start: usize, step: usize) -> usize {
        if lo <= start {
            start
        } else {
            start + (lo - start).div_ceil(step) * step
        }
    }
}

/// Heights over a rectangle of a `side`² grid with `cell_size_m` spacing.
#[derive(Debug, Clone, Copy)]
pub struct HeightWindow<'h> {
    /// Row-major over `rect`.
    pub heights: &'h [f32],
    pub rect: Rect,
    pub side: usize,
    pub cell_size_m: f64,
}

impl HeightWindow<'_> {
    #[inline]
    fn z(&self, v: Vertex) -> f32 {
        self.heights[self.rect.index(v)]
    }

    /// (c, r) relative to the window's corner.
    #[inline]
    fn local(&self, (c, r): Vertex) -> (i64, i64) {
        (
            c as i64 - self.rect.c0 as i64,
            r as i64 - self.rect.r0 as i64,
        )
    }
}

/// Own error of vertex `v` of scale `h` (an edge vertex when `edge`) by
/// `metric`, from heights `z_of` gives for the vertex and its triangles'
/// corners; with `clip` (Bound metric, h ≥ 2 only), over the grid points
/// of `window` inside `clip` alone.
fn own_error(
    window: &HeightWindow,
    z_of: &dyn Fn(Vertex) -> f32,
    (v, h, edge): (Vertex, usize, bool),
    metric: ErrorMetric,
    clip: Option<Rect>,
) -> f32 {
    let (a, b) = hypotenuse(v, h, edge);
    match metric {
        ErrorMetric::Midpoint => midpoint_error(z_of(a), z_of(b), z_of(v)) as f32,
        // At scale 1 a triangle's grid points are its corners, the vertex
        // and its legs' midpoints (the children), each off the plane by its
        // midpoint error: nesting adds the children's, so the vertex's own
        // is its midpoint error.
        ErrorMetric::Bound if h == 1 => round_up(midpoint_error(z_of(a), z_of(b), z_of(v))),
        ErrorMetric::Bound => {
            let clip = clip.map(|c| {
                let (c0, r0) = window.local((c.c0, c.r0));
                [c0, r0, c0 + c.width as i64, r0 + c.height as i64]
            });
            let deviation = parents(window.side, v, a)
                .into_iter()
                .flatten()
                .map(|p| {
                    triangle_deviation(
                        window.heights,
                        window.rect.width,
                        [window.local(a), window.local(b), window.local(p)],
                        [z_of(a), z_of(b), z_of(p)],
                        clip,
                    )
                })
                .fold(0.0, f64::max);
            round_up(deviation)
        }
    }
}

/// Midpoint own error (the [`ErrorMetric::Midpoint`] metric) of vertex `v`
/// of the `side`² grid, from the heights `z_of` gives; 0 for a corner.
pub fn midpoint_own(side: usize, z_of: &dyn Fn(Vertex) -> f32, v: Vertex) -> f32 {
    match vertex_kind(side, v.0, v.1) {
        Some((h, edge)) => {
            let (a, b) = hypotenuse(v, h, edge);
            midpoint_error(z_of(a), z_of(b), z_of(v)) as f32
        }
        None => 0.0,
    }
}

/// Own errors of the vertices of `region` (row-major over it) whose scale
/// is at most `max_scale`; 0 for the corners and coarser vertices. The
/// diamonds of those vertices must lie inside `window`.
pub fn own_errors(
    window: &HeightWindow,
    region: Rect,
    metric: ErrorMetric,
    max_scale: usize,
) -> Vec<f32> {
    let z_of = |v: Vertex| window.z(v);
    let mut out = vec![0.0f32; region.len()];
    out.par_chunks_mut(region.width.max(1))
        .enumerate()
        .for_each(|(dr, row)| {
            let r = region.r0 + dr;
            for (dc, value) in row.iter_mut().enumerate() {
                let c = region.c0 + dc;
                if let Some((h, edge)) = vertex_kind(window.side, c, r) {
                    if h <= max_scale {
                        *value = own_error(window, &z_of, ((c, r), h, edge), metric, None);
                    }
                }
            }
        });
    out
}

/// The part of vertex `v`'s own error (Bound metric, scale ≥ 2) that the
/// grid points of `window` inside `clip` give, its corners' heights from
/// `z_of`: the largest of such parts over rectangles covering the diamond
/// is the vertex's own error, bit for bit.
pub fn own_partial(
    window: &HeightWindow,
    z_of: &dyn Fn(Vertex) -> f32,
    v: Vertex,
    clip: Rect,
) -> f32 {
    match vertex_kind(window.side, v.0, v.1) {
        Some((h, edge)) if h >= 2 => {
            own_error(window, z_of, (v, h, edge), ErrorMetric::Bound, Some(clip))
        }
        _ => 0.0,
    }
}

/// Error and radius of vertex `v` (height `z`) from its own error and its
/// children's `[error, radius]` and heights, as `child` gives them (`None`
/// for a child it does not hold).
#[inline]
pub fn combine(
    side: usize,
    cell_size_m: f64,
    (v, z): (Vertex, f32),
    own: f32,
    (h, edge): (usize, bool),
    child: impl Fn(Vertex) -> Option<([f32; 2], f32)>,
) -> [f32; 2] {
    let p = terrain_position(v.0, v.1, side, cell_size_m, z as f64);
    let mut error = own;
    let mut radius = 0.0f64;
    for offset in child_offsets(h, edge) {
        if offset == (0, 0) {
            continue;
        }
        let Some(k) = step(side, v, offset) else {
            continue;
        };
        let Some(([child_error, child_radius], child_z)) = child(k) else {
            continue;
        };
        let q = terrain_position(k.0, k.1, side, cell_size_m, child_z as f64);
        let distance =
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
        error = error.max(child_error);
        radius = radius.max(distance + child_radius as f64);
    }
    [error, round_up(radius)]
}

/// Errors and radii of the vertices of `window` up to scale `max_scale`
/// (row-major over the window; `[0, 0]` for the corners and coarser
/// vertices), from their own errors `own` (over the window), finest level
/// first. A vertex whose descendants lie inside the window gets its exact
/// value; one nearer the window's edge misses the children outside it.
pub fn saturate(window: &HeightWindow, own: &[f32], max_scale: usize) -> Vec<[f32; 2]> {
    let rect = window.rect;
    let mut out = vec![[0.0f32; 2]; rect.len()];
    let shared = SharedOut::new(&mut out);
    let mut h = 1;
    while h < window.side - 1 && h <= max_scale {
        for edge in [true, false] {
            let (first_row, row_step, columns) = level_rows(h, edge);
            let first = Rect::first_from(rect.r0, first_row, row_step);
            let rows: Vec<usize> = (first..rect.r0 + rect.height).step_by(row_step).collect();
            rows.into_par_iter().for_each(|r| {
                let (start, step) = columns(r, h);
                let c_first = Rect::first_from(rect.c0, start, step);
                for c in (c_first..(rect.c0 + rect.width).min(window.side)).step_by(step) {
                    let v = (c, r);
                    let i = rect.index(v);
                    let value = combine(
                        window.side,
                        window.cell_size_m,
                        (v, window.z(v)),
                        own[i],
                        (h, edge),
                        |k| {
                            // SAFETY: children belong to finer levels,
                            // finished before this one.
                            rect.contains(k)
                                .then(|| (unsafe { shared.get(rect.index(k)) }, window.z(k)))
                        },
                    );
                    // SAFETY: (c, r) belongs to this level and this row only.
                    unsafe { shared.set(i, value) };
                }
            });
        }
        h *= 2;
    }
    out
}

/// The output array shared by the threads of one level: each level writes
/// only its own vertices and reads only finer levels' vertices, which no
/// thread writes during that level, so accesses never overlap.
#[derive(Clone, Copy)]
struct SharedOut {
    ptr: *mut [f32; 2],
    len: usize,
}

// SAFETY: see the type's documentation; every access is to a distinct
// element or to one no thread writes at that time.
unsafe impl Send for SharedOut {}
// SAFETY: as for `Send`: threads never touch the same element concurrently.
unsafe impl Sync for SharedOut {}

impl SharedOut {
    fn new(out: &mut [[f32; 2]]) -> Self {
        SharedOut {
            ptr: out.as_mut_ptr(),
            len: out.len(),
        }
    }
    /// # Safety
    /// No thread may be writing element `i`.
    unsafe fn get(&self, i: usize) -> [f32; 2] {
        assert!(i < self.len);
        // SAFETY: `i` is in bounds and, by the caller's promise, not written now.
        unsafe { *self.ptr.add(i) }
    }
    /// # Safety
    /// No other thread may be reading or writing element `i`.
    unsafe fn set(&self, i: usize, value: [f32; 2]) {
        assert!(i < self.len);
        // SAFETY: `i` is in bounds and, by the caller's promise, no other
        // thread touches it now.
        unsafe { *self.ptr.add(i) = value };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lp::{ErrorMetric, Hierarchy};
    use crate::testdata;

    /// The heights of `rect` copied out of a `side`² grid.
    fn cut(heights: &[f32], side: usize, rect: Rect) -> Vec<f32> {
        (rect.r0..rect.r0 + rect.height)
            .flat_map(|r| {
                heights[r * side + rect.c0..r * side + rect.c0 + rect.width]
                    .iter()
                    .copied()
            })
            .collect()
    }

    /// Tiles of 32 cells on the real crops, each pass over the tile and
    /// its halo as a tiled build runs it: own errors from the tile ± 16,
    /// saturation over the tile ± 32 from them, and the lattice's own
    /// errors as the largest of every tile's part — all equal the single
    /// grid's, bit for bit, on both metrics.
    #[test]
    fn tiles_with_halos_give_the_single_grids_values_bit_for_bit() {
        const T: usize = 32;
        for dem in testdata::dems() {
            let side = dem.side;
            for metric in [ErrorMetric::Bound, ErrorMetric::Midpoint] {
                let single = Hierarchy::compute(&dem.heights, side, dem.cell_size_m, metric);
                let whole = HeightWindow {
                    heights: &dem.heights,
                    rect: Rect::whole(side),
                    side,
                    cell_size_m: dem.cell_size_m,
                };
                let whole_own = own_errors(&whole, whole.rect, metric, usize::MAX);
                let mut lattice_own = vec![0.0f32; side * side];
                for ty in 0..(side - 1) / T {
                    for tx in 0..(side - 1) / T {
                        let tile = [tx * T, ty * T, (tx + 1) * T, (ty + 1) * T];
                        let tile_rect = Rect::around(tile, 0, side);
                        // Pass 1: own errors from the tile ± T/2.
                        let halo = Rect::around(tile, T / 2, side);
                        let heights = cut(&dem.heights, side, halo);
                        let window = HeightWindow {
                            heights: &heights,
                            rect: halo,
                            side,
                            cell_size_m: dem.cell_size_m,
                        };
                        let own = own_errors(&window, tile_rect, metric, T / 2);
                        for r in tile[1]..=tile[3] {
                            for c in tile[0]..=tile[2] {
                                let fine = vertex_kind(side, c, r).is_some_and(|(h, _)| h <= T / 2);
                                let want = if fine { whole_own[r * side + c] } else { 0.0 };
                                assert_eq!(
                                    own[tile_rect.index((c, r))].to_bits(),
                                    want.to_bits(),
                                    "{} own ({c}, {r})",
                                    dem.name
                                );
                            }
                        }
                        // The lattice's own errors, part by part.
                        if metric == ErrorMetric::Bound {
                            let z_of = |v: Vertex| dem.heights[v.1 * side + v.0];
                            for r in (0..side).step_by(T) {
                                for c in (0..side).step_by(T) {
                                    let part = own_partial(&window, &z_of, (c, r), tile_rect);
                                    let i = r * side + c;
                                    lattice_own[i] = lattice_own[i].max(part);
                                }
                            }
                        }
                        // Pass 2: saturation over the tile ± T.
                        let wide = Rect::around(tile, T, side);
                        let heights = cut(&dem.heights, side, wide);
                        let window = HeightWindow {
                            heights: &heights,
                            rect: wide,
                            side,
                            cell_size_m: dem.cell_size_m,
                        };
                        let own = cut(&whole_own, side, wide);
                        let out = saturate(&window, &own, T / 2);
                        for r in tile[1]..=tile[3] {
                            for c in tile[0]..=tile[2] {
                                if vertex_kind(side, c, r).is_some_and(|(h, _)| h <= T / 2) {
                                    let got = out[wide.index((c, r))];
                                    let want = single.error_radius[r * side + c];
                                    assert_eq!(
                                        got.map(f32::to_bits),
                                        want.map(f32::to_bits),
                                        "{} ({c}, {r})",
                                        dem.name
                                    );
                                }
                            }
                        }
                    }
                }
                if metric == ErrorMetric::Bound {
                    for r in (0..side).step_by(T) {
                        for c in (0..side).step_by(T) {
                            let i = r * side + c;
                            assert_eq!(
                                lattice_own[i].to_bits(),
                                whole_own[i].to_bits(),
                                "{} lattice ({c}, {r})",
                                dem.name
                            );
                        }
                    }
                }
            }
        }
    }
}
