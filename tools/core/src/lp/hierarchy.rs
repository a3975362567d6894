//! Object-space errors and bounding-sphere radii (LP seed §3.3, the
//! `IniciaErros` / `PropagaErrosRaios` pre-processing).
//!
//! The seed walks even and odd blocks recursively; here the same hierarchy
//! is visited level by level, finest first, so every vertex of a level can be
//! computed in parallel from the finished level below:
//!
//! - an *edge* vertex of scale h lies mid-way along an axis-aligned block edge
//!   of length 2h; its triangles' hypotenuse is that edge, and its children
//!   are the four diagonal neighbours at (±h/2, ±h/2) (none when h = 1);
//! - a *centre* vertex of a 2h-block lies mid-way along the block's diagonal,
//!   which runs top-left to bottom-right when the block's index (bx + by) is
//!   even and top-right to bottom-left when odd; its children are the four
//!   edge midpoints at distance h.
//!
//! The object-space error of a vertex is its own error maxed with its
//! children's errors. Its own error is measured by one of two
//! [`ErrorMetric`]s: by default the largest vertical distance between the
//! grid points its diamond covers and the two triangles drawn while it is
//! left out, so that a mesh cut at a tolerance is within that tolerance of
//! every grid point; or, as martini and the seed (`CalculaErroObj`), how
//! far its height is from the average of its hypotenuse's end points, which
//! looks at the vertex alone. Either way the radius is the smallest sphere about the
//! vertex containing every child's sphere (seed's `PropagaRaiosBloco`). So
//! δ(parent) ≥ δ(child) and r(parent) ≥ |p(parent) − p(child)| + r(child).
//!
//! Why the bound holds: a mesh extracted at tolerance τ is made of leaf
//! triangles whose hypotenuse midpoint m is left out (δ(m) ≤ τ); each leaf
//! is one half of m's diamond, so every grid point inside it is within
//! own(m) ≤ δ(m) ≤ τ of it. Lindstrom and Pascucci (2002, §4) define the
//! error the same way, over the points a vertex's removal affects.

use super::vertices::terrain_position;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// How a vertex's own object-space error is measured.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ErrorMetric {
    /// The largest vertical distance between the grid points of the
    /// vertex's diamond and the two triangles drawn without the vertex: a
    /// true bound on the distance from a mesh extracted at a tolerance to
    /// every grid point it covers.
    #[default]
    Bound,
    /// The vertex's height against the midpoint of its hypotenuse, as
    /// @mapbox/martini and the LP seed (`CalculaErroObj`) measure it; kept
    /// for conformance with martini's meshes.
    Midpoint,
}

impl ErrorMetric {
    /// The metric of bundles written before the manifest recorded one.
    pub fn unrecorded() -> ErrorMetric {
        ErrorMetric::Midpoint
    }
}

/// Per-vertex error and radius, row-major, interleaved as `[δ, r]`: owned
/// when computed, borrowed when read from a bundle's mapped `lp` array (no
/// copy, whatever the grid size).
#[derive(Debug, Clone, PartialEq)]
pub struct Hierarchy<'a> {
    pub side: usize,
    /// Horizontal vertex spacing, metres.
    pub cell_size_m: f64,
    /// `[object-space error δ (m), bounding-sphere radius r (m)]` per vertex.
    pub error_radius: Cow<'a, [[f32; 2]]>,
}

impl<'a> Hierarchy<'a> {
    /// A hierarchy over stored `[δ, r]` pairs, e.g. a bundle's `lp` array.
    pub fn borrowed(side: usize, cell_size_m: f64, error_radius: &'a [[f32; 2]]) -> Self {
        Hierarchy {
            side,
            cell_size_m,
            error_radius: Cow::Borrowed(error_radius),
        }
    }

    /// The same hierarchy owning its pairs (a copy when borrowed).
    pub fn into_owned(self) -> Hierarchy<'static> {
        Hierarchy {
            side: self.side,
            cell_size_m: self.cell_size_m,
            error_radius: Cow::Owned(self.error_radius.into_owned()),
        }
    }

    pub fn error(&self, i: usize) -> f32 {
        self.error_radius[i][0]
    }
    pub fn radius(&self, i: usize) -> f32 {
        self.error_radius[i][1]
    }

    /// Compute errors (by `metric`) and radii of a `side`×`side` grid of
    /// heights (metres). Arithmetic is f64; results are stored as f32, radii
    /// and bounds rounded up so that nesting and the bound survive the
    /// rounding (midpoint errors are rounded to nearest, as martini does).
    ///
    /// ```
    /// use relevo_core::lp::{ErrorMetric, Hierarchy};
    /// // A 17² grid, 10 m cells: a plane (no error) with one 8 m bump.
    /// let side = 17;
    /// let mut heights: Vec<f32> = (0..side * side).map(|i| (i % side) as f32).collect();
    /// heights[8 * side + 8] += 8.0;
    /// let h = Hierarchy::compute(&heights, side, 10.0, ErrorMetric::Bound);
    /// // The bump's vertex is only skipped by triangles that miss it by 8 m,
    /// // and a parent's error bounds its children's (nesting).
    /// assert!(h.error(8 * side + 8) >= 8.0);
    /// assert!(h.error(0) == 0.0 && h.error(side * side - 1) == 0.0);
    /// ```
    pub fn compute(
        heights: &[f32],
        side: usize,
        cell_size_m: f64,
        metric: ErrorMetric,
    ) -> Hierarchy<'static> {
        assert!(
            side >= 3 && (side - 1).is_power_of_two(),
            "side must be 2^k+1"
        );
        assert_eq!(heights.len(), side * side);
        let mut out = vec![[0.0f32; 2]; side * side];
        let grid = Grid {
            heights,
            side,
            cell: cell_size_m,
            metric,
        };
        finest_levels(&grid, &mut out);
        let shared = SharedOut::new(&mut out);
        let mut h = 2;
        while h < side - 1 {
            coarse_level(&grid, h, true, shared);
            coarse_level(&grid, h, false, shared);
            h *= 2;
        }
        Hierarchy {
            side,
            cell_size_m,
            error_radius: Cow::Owned(out),
        }
    }

    /// Vertices breaking the nesting invariants, as messages (at most
    /// `limit`): δ(parent) ≥ δ(child) and r(parent) ≥ |p − p_child| + r(child),
    /// checked for every parent–child pair with the stored f32 values.
    pub fn nesting_violations(&self, heights: &[f32], limit: usize) -> Vec<String> {
        let (side, cell) = (self.side, self.cell_size_m);
        let mut problems = Vec::new();
        visit_bottom_up(side, |d| {
            if problems.len() >= limit {
                return;
            }
            let (c, r) = (d.vertex % side, d.vertex / side);
            let p = terrain_position(c, r, side, cell, heights[d.vertex] as f64);
            for &k in d.children.iter().flatten() {
                let q = terrain_position(k % side, k / side, side, cell, heights[k] as f64);
                let dist =
                    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                let [e, rad] = self.error_radius[d.vertex];
                let [ek, rk] = self.error_radius[k];
                if e < ek {
                    problems.push(format!("vertex ({c}, {r}): error {e} < child's {ek}"));
                }
                if (rad as f64) < dist + rk as f64 {
                    problems.push(format!(
                        "vertex ({c}, {r}): radius {rad} < {dist} + child's {rk}"
                    ));
                }
            }
        });
        problems
    }

    /// The children of vertex (c, r), if any (up to four).
    pub fn children(&self, c: usize, r: usize) -> impl Iterator<Item = (usize, usize)> {
        children(self.side, c, r)
    }
}

/// Scale of vertex (c, r): the h for which it is an edge (`Some(true)`) or a
/// centre (`Some(false)`) vertex; `None` for the four corners.
pub fn vertex_kind(side: usize, c: usize, r: usize) -> Option<(usize, bool)> {
    let low = |v: usize| {
        if v == 0 {
            usize::MAX
        } else {
            1 << v.trailing_zeros()
        }
    };
    let (lc, lr) = (low(c), low(r));
    if lc == usize::MAX && lr == usize::MAX || (lc.min(lr) >= side - 1) {
        return None;
    }
    let h = lc.min(lr);
    Some((h, lc != lr))
}

/// Offsets of the children of an edge (`edge`) or centre vertex of scale
/// `h`: the diagonal neighbours at h/2, or the edge midpoints at h. An edge
/// vertex of scale 1 has none (all offsets zero).
fn child_offsets(h: usize, edge: bool) -> [(i64, i64); 4] {
    let (q, hi) = ((h / 2) as i64, h as i64);
    if edge {
        [(-q, -q), (q, -q), (-q, q), (q, q)]
    } else {
        [(-hi, 0), (hi, 0), (0, -hi), (0, hi)]
    }
}

/// The children of vertex (c, r) on a `side` grid (see the module docs).
pub fn children(side: usize, c: usize, r: usize) -> impl Iterator<Item = (usize, usize)> {
    let offsets = match vertex_kind(side, c, r) {
        Some((h, edge)) => child_offsets(h, edge),
        None => [(0, 0); 4],
    };
    let n = side as i64;
    offsets.into_iter().filter_map(move |(dc, dr)| {
        let (nc, nr) = (c as i64 + dc, r as i64 + dr);
        ((dc, dr) != (0, 0) && nc >= 0 && nr >= 0 && nc < n && nr < n)
            .then_some((nc as usize, nr as usize))
    })
}

/// The heights and how errors are measured on them.
struct Grid<'h> {
    heights: &'h [f32],
    side: usize,
    /// Vertex spacing, metres.
    cell: f64,
    metric: ErrorMetric,
}

impl Grid<'_> {
    /// Own error of vertex (c, r) of scale `h` by the grid's metric, f32
    /// as stored.
    fn own_error(&self, (c, r): (usize, usize), h: usize, edge: bool) -> f32 {
        let side = self.side;
        let (a, b) = hypotenuse(side, c, r, h, edge);
        let m = r * side + c;
        match self.metric {
            ErrorMetric::Midpoint => midpoint_error(self.heights, a, b, m) as f32,
            // At scale 1 a triangle's grid points are its corners, the vertex
            // and its legs' midpoints (the children), each off the plane by
            // its midpoint error: nesting adds the children's, so the vertex's
            // own is its midpoint error.
            ErrorMetric::Bound if h == 1 => round_up(midpoint_error(self.heights, a, b, m)),
            ErrorMetric::Bound => {
                let at = |i: usize| ((i % side) as i64, (i / side) as i64);
                let deviation = parents(side, (c, r), a)
                    .into_iter()
                    .flatten()
                    .map(|p| triangle_deviation(self.heights, side, [at(a), at(b), at(p)]))
                    .fold(0.0, f64::max);
                round_up(deviation)
            }
        }
    }
}

/// Largest vertical distance between the grid points inside triangle
/// `corners` (grid columns and rows) of a `side`-wide height grid and the
/// triangle's plane, metres. The legs must be axis-aligned or diagonal, as
/// every triangle of the hierarchy's (so rows cross edges at whole columns).
pub fn triangle_deviation(heights: &[f32], side: usize, corners: [(i64, i64); 3]) -> f64 {
    let side = side as i64;
    let z = |(c, r): (i64, i64)| heights[(r * side + c) as usize] as f64;
    let [p0, p1, p2] = corners;
    // The plane z = z0 + dz_dc·(c − c0) + dz_dr·(r − r0).
    let (e1, e2) = ((p1.0 - p0.0, p1.1 - p0.1), (p2.0 - p0.0, p2.1 - p0.1));
    let (dz1, dz2) = (z(p1) - z(p0), z(p2) - z(p0));
    let det = (e1.0 * e2.1 - e1.1 * e2.0) as f64;
    let dz_dc = (dz1 * e2.1 as f64 - dz2 * e1.1 as f64) / det;
    let dz_dr = (dz2 * e1.0 as f64 - dz1 * e2.0 as f64) / det;
    let (top, bottom) = (p0.1.min(p1.1).min(p2.1), p0.1.max(p1.1).max(p2.1));
    let edges = [(p0, p1), (p1, p2), (p2, p0)];
    let mut largest = 0.0f64;
    for r in top..=bottom {
        // The row's span: where it crosses the non-horizontal edges.
        let (mut first, mut last) = (i64::MAX, i64::MIN);
        for &(u, v) in &edges {
            if u.1 != v.1 && (u.1.min(v.1)..=u.1.max(v.1)).contains(&r) {
                let c = u.0 + (r - u.1) * (v.0 - u.0) / (v.1 - u.1);
                first = first.min(c);
                last = last.max(c);
            }
        }
        let span = &heights[(r * side + first) as usize..=(r * side + last) as usize];
        let start = z(p0) + dz_dr * (r - p0.1) as f64 + dz_dc * (first - p0.0) as f64;
        largest = largest.max(span_deviation(span, start, dz_dc));
    }
    largest
}

/// Largest |z − (start + slope·i)| over the heights `span[i]`, in four
/// independent lanes so that the loop vectorises (heights are finite).
#[inline]
fn span_deviation(span: &[f32], start: f64, slope: f64) -> f64 {
    let mut lanes = [0.0f64; 4];
    let chunks = span.chunks_exact(4);
    let rest = chunks.remainder();
    let mut x = 0.0f64;
    for chunk in chunks {
        for (j, lane) in lanes.iter_mut().enumerate() {
            let d = (chunk[j] as f64 - (start + slope * (x + j as f64))).abs();
            *lane = if d > *lane { d } else { *lane };
        }
        x += 4.0;
    }
    for (j, &z) in rest.iter().enumerate() {
        let d = (z as f64 - (start + slope * (x + j as f64))).abs();
        lanes[j] = if d > lanes[j] { d } else { lanes[j] };
    }
    lanes[0].max(lanes[1]).max(lanes[2].max(lanes[3]))
}

/// Height error of vertex `m` against the midpoint of `a`–`b`, as martini
/// and the seed compute it: the average in f64, the difference in f64.
#[inline]
fn midpoint_error(heights: &[f32], a: usize, b: usize, m: usize) -> f64 {
    let average = (heights[a] as f64 + heights[b] as f64) / 2.0;
    (average - heights[m] as f64).abs()
}

/// The right-angle vertices of the (one or two) triangles whose hypotenuse
/// vertex (c, r) bisects, `a` being one end of that hypotenuse: across the
/// hypotenuse, as far from the vertex as its end points are, so (a − m)
/// rotated by ±90°. `None` where one would fall outside the grid.
fn parents(side: usize, (c, r): (usize, usize), a: usize) -> [Option<usize>; 2] {
    let (ac, ar) = ((a % side) as i64 - c as i64, (a / side) as i64 - r as i64);
    let at = |dc: i64, dr: i64| {
        let (pc, pr) = (c as i64 + dc, r as i64 + dr);
        (pc >= 0 && pr >= 0 && pc < side as i64 && pr < side as i64)
            .then(|| pr as usize * side + pc as usize)
    };
    [at(-ar, ac), at(ar, -ac)]
}

/// Distance between two terrain-frame points, metres.
#[inline]
fn distance(p: [f64; 3], q: [f64; 3]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

/// Error and radius of vertex (c, r) from its own error and its finished
/// children in `out`.
#[inline]
fn combine(
    grid: &Grid,
    out: SharedOut,
    (c, r): (usize, usize),
    own: f32,
    children: &[(i64, i64)],
) -> [f32; 2] {
    let (heights, side, cell) = (grid.heights, grid.side, grid.cell);
    let p = terrain_position(c, r, side, cell, heights[r * side + c] as f64);
    let mut error = own;
    let mut radius = 0.0f64;
    for &(dc, dr) in children {
        let (nc, nr) = (c as i64 + dc, r as i64 + dr);
        if nc < 0 || nr < 0 || nc >= side as i64 || nr >= side as i64 {
            continue;
        }
        let (nc, nr) = (nc as usize, nr as usize);
        let k = nr * side + nc;
        let q = terrain_position(nc, nr, side, cell, heights[k] as f64);
        // SAFETY: children belong to finer levels, finished before this one.
        let [child_error, child_radius] = unsafe { out.get(k) };
        error = error.max(child_error);
        radius = radius.max(distance(p, q) + child_radius as f64);
    }
    [error, round_up(radius)]
}

/// Smallest f32 not below `v` (v ≥ 0).
#[inline]
fn round_up(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) < v {
        f.next_up()
    } else {
        f
    }
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

/// Both levels of scale 1 in one pass over the rows. Edge vertices of scale
/// 1 have no children; a centre vertex of a 2-block has the four edge
/// vertices around it as children, whose errors are recomputed here from
/// the heights (the same arithmetic as when they are stored), so each row
/// depends on the heights alone.
fn finest_levels(grid: &Grid, out: &mut [[f32; 2]]) {
    let (heights, side, cell) = (grid.heights, grid.side, grid.cell);
    out.par_chunks_mut(side).enumerate().for_each(|(r, row)| {
        let at = |c: usize, r: usize| r * side + c;
        let edge_error = |c: usize, r: usize| grid.own_error((c, r), 1, true);
        if r % 2 == 0 {
            for c in (1..side).step_by(2) {
                row[c] = [edge_error(c, r), 0.0];
            }
            return;
        }
        for c in (0..side).step_by(2) {
            row[c] = [edge_error(c, r), 0.0];
        }
        for c in (1..side).step_by(2) {
            let mut error = grid.own_error((c, r), 1, false);
            let p = terrain_position(c, r, side, cell, heights[at(c, r)] as f64);
            // The children have radius 0: the largest squared distance gives
            // the radius with one square root (sqrt is monotonic and exact).
            let mut farthest = 0.0f64;
            // The vertical edges beside it on this row are already stored.
            error = error.max(row[c - 1][0]).max(row[c + 1][0]);
            for (k, (nc, nr)) in [(c - 1, r), (c + 1, r), (c, r - 1), (c, r + 1)]
                .into_iter()
                .enumerate()
            {
                if k >= 2 {
                    error = error.max(edge_error(nc, nr));
                }
                let q = terrain_position(nc, nr, side, cell, heights[at(nc, nr)] as f64);
                farthest = farthest
                    .max((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2));
            }
            row[c] = [error, round_up(farthest.sqrt())];
        }
    });
}

/// The edge (`edge`) or centre vertices of scale `h` ≥ 2, rows in parallel.
fn coarse_level(grid: &Grid, h: usize, edge: bool, out: SharedOut) {
    let side = grid.side;
    let children = child_offsets(h, edge);
    let (first_row, row_step) = if edge { (0, h) } else { (h, 2 * h) };
    let rows: Vec<usize> = (first_row..side).step_by(row_step).collect();
    rows.into_par_iter().for_each(|r| {
        let (start, step) = if edge {
            edge_columns(r, h)
        } else {
            centre_columns(r, h)
        };
        for c in (start..side).step_by(step) {
            let m = r * side + c;
            let own = grid.own_error((c, r), h, edge);
            let value = combine(grid, out, (c, r), own, &children);
            // SAFETY: (c, r) belongs to this level and to this row only.
            unsafe { out.set(m, value) };
        }
    });
}

/// A vertex as [`visit_bottom_up`] presents it; all fields are row-major
/// indices, `None` where a parent or child would fall outside the grid.
pub struct Diamond {
    pub vertex: usize,
    /// End points of the hypotenuse the vertex bisects.
    pub hypotenuse: [usize; 2],
    /// Right-angle vertices of its (one or two) triangles.
    pub parents: [Option<usize>; 2],
    pub children: [Option<usize>; 4],
}

/// Visit every non-corner vertex finest level first, sequentially.
pub fn visit_bottom_up(side: usize, mut f: impl FnMut(&Diamond)) {
    let mut h = 1;
    while h < side - 1 {
        for (first_row, row_step, columns, edge) in [
            (
                0,
                h,
                edge_columns as fn(usize, usize) -> (usize, usize),
                true,
            ),
            (h, 2 * h, centre_columns, false),
        ] {
            for r in (first_row..side).step_by(row_step) {
                let (start, step) = columns(r, h);
                for c in (start..side).step_by(step) {
                    let (a, b) = hypotenuse(side, c, r, h, edge);
                    let mut kids = [None; 4];
                    for (k, (nc, nr)) in kids.iter_mut().zip(children(side, c, r)) {
                        *k = Some(nr * side + nc);
                    }
                    f(&Diamond {
                        vertex: r * side + c,
                        hypotenuse: [a, b],
                        parents: parents(side, (c, r), a),
                        children: kids,
                    });
                }
            }
        }
        h *= 2;
    }
}

/// End points of the hypotenuse that vertex (c, r) of scale h bisects.
fn hypotenuse(side: usize, c: usize, r: usize, h: usize, edge: bool) -> (usize, usize) {
    let m = r * side + c;
    if edge {
        if (r / h).is_multiple_of(2) {
            (m - h, m + h)
        } else {
            (m - h * side, m + h * side)
        }
    } else if (c / (2 * h) + r / (2 * h)).is_multiple_of(2) {
        (m - h * side - h, m + h * side + h)
    } else {
        (m - h * side + h, m + h * side - h)
    }
}

/// Columns of edge vertices on row r: c ≡ h (mod 2h) on rows r ≡ 0, else c ≡ 0.
fn edge_columns(r: usize, h: usize) -> (usize, usize) {
    if (r / h).is_multiple_of(2) {
        (h, 2 * h)
    } else {
        (0, 2 * h)
    }
}

/// Columns of centre vertices: c ≡ h (mod 2h).
fn centre_columns(_r: usize, h: usize) -> (usize, usize) {
    (h, 2 * h)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rough deterministic surface (integer hash noise plus a slope).
    fn surface(side: usize) -> Vec<f32> {
        (0..side * side)
            .map(|i| {
                let x = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40;
                (x % 1000) as f32 * 0.01 + (i % side) as f32 * 0.5
            })
            .collect()
    }

    #[test]
    fn nested_on_a_rough_surface() {
        let side = 65;
        let heights = surface(side);
        let h = Hierarchy::compute(&heights, side, 30.0, ErrorMetric::default());
        assert_eq!(h.nesting_violations(&heights, 10), Vec::<String>::new());
        // Corners never split: zero. The centre carries the largest error.
        assert_eq!(h.error(0), 0.0);
        let max = h.error_radius.iter().map(|e| e[0]).fold(0.0, f32::max);
        assert_eq!(h.error(32 * side + 32), max);
    }

    #[test]
    fn nested_on_real_dems() {
        for dem in crate::testdata::dems() {
            let h = Hierarchy::compute(
                &dem.heights,
                dem.side,
                dem.cell_size_m,
                ErrorMetric::default(),
            );
            assert_eq!(
                h.nesting_violations(&dem.heights, 10),
                Vec::<String>::new(),
                "{}",
                dem.name
            );
            assert!(h.error_radius.iter().any(|e| e[0] > 1.0), "{}", dem.name);
        }
    }

    #[test]
    fn planes_have_no_error() {
        let side = 17;
        let heights: Vec<f32> = (0..side * side)
            .map(|i| (i % side) as f32 * 2.0 - (i / side) as f32)
            .collect();
        let h = Hierarchy::compute(&heights, side, 1.0, ErrorMetric::default());
        assert!(h.error_radius.iter().all(|e| e[0] == 0.0));
        // Radii still bound every descendant: the centre's sphere reaches the corners' children.
        assert!(h.radius(8 * side + 8) > 0.0);
    }

    #[test]
    fn finest_radius_is_one_diagonal_step() {
        // A flat 3×3 grid: the centre's children are the edge midpoints at one cell.
        let h = Hierarchy::compute(&[0.0; 9], 3, 10.0, ErrorMetric::default());
        assert_eq!(h.radius(4), 10.0);
        assert_eq!(h.radius(1), 0.0);
        let kids: Vec<_> = h.children(1, 1).collect();
        assert_eq!(kids, vec![(0, 1), (2, 1), (1, 0), (1, 2)]);
    }

    #[test]
    fn detects_broken_nesting() {
        let side = 9;
        let heights = surface(side);
        let mut h = Hierarchy::compute(&heights, side, 1.0, ErrorMetric::default());
        h.error_radius.to_mut()[4 * side + 4][0] = 0.0;
        assert!(!h.nesting_violations(&heights, 10).is_empty());
    }
}
