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
//! The object-space error of a vertex is how far its height is from the
//! average of its hypotenuse's end points (seed's `CalculaErroObj`), maxed
//! with its children's errors; the radius is the smallest sphere about the
//! vertex containing every child's sphere (seed's `PropagaRaiosBloco`). So
//! δ(parent) ≥ δ(child) and r(parent) ≥ |p(parent) − p(child)| + r(child).

use super::terrain_position;
use rayon::prelude::*;

/// Per-vertex error and radius, row-major, interleaved as `[δ, r]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Hierarchy {
    pub side: usize,
    /// Horizontal vertex spacing, metres.
    pub cell_size_m: f64,
    /// `[object-space error δ (m), bounding-sphere radius r (m)]` per vertex.
    pub error_radius: Vec<[f32; 2]>,
}

impl Hierarchy {
    pub fn error(&self, i: usize) -> f32 {
        self.error_radius[i][0]
    }
    pub fn radius(&self, i: usize) -> f32 {
        self.error_radius[i][1]
    }

    /// Compute errors and radii of a `side`×`side` grid of heights (metres).
    /// Arithmetic is f64; results are stored as f32, radii rounded up so
    /// that nesting survives the rounding.
    pub fn compute(heights: &[f32], side: usize, cell_size_m: f64) -> Hierarchy {
        assert!(
            side >= 3 && (side - 1).is_power_of_two(),
            "side must be 2^k+1"
        );
        assert_eq!(heights.len(), side * side);
        let mut out = vec![[0.0f32; 2]; side * side];
        let mut scratch = Vec::new();
        let mut h = 1;
        while h < side - 1 {
            edge_level(heights, side, cell_size_m, h, &mut out, &mut scratch);
            centre_level(heights, side, cell_size_m, h, &mut out, &mut scratch);
            h *= 2;
        }
        Hierarchy {
            side,
            cell_size_m,
            error_radius: out,
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

/// The children of vertex (c, r) on a `side` grid (see the module docs).
pub fn children(side: usize, c: usize, r: usize) -> impl Iterator<Item = (usize, usize)> {
    let offsets: [(i64, i64); 4] = match vertex_kind(side, c, r) {
        Some((h, true)) if h >= 2 => {
            let q = (h / 2) as i64;
            [(-q, -q), (q, -q), (-q, q), (q, q)]
        }
        Some((h, false)) => {
            let h = h as i64;
            [(-h, 0), (h, 0), (0, -h), (0, h)]
        }
        _ => [(0, 0); 4],
    };
    let n = side as i64;
    offsets.into_iter().filter_map(move |(dc, dr)| {
        let (nc, nr) = (c as i64 + dc, r as i64 + dr);
        ((dc, dr) != (0, 0) && nc >= 0 && nr >= 0 && nc < n && nr < n)
            .then_some((nc as usize, nr as usize))
    })
}

/// Height error of vertex `m` against the midpoint of `a`–`b`, as martini
/// and the seed compute it: the average in f64, the difference in f64.
#[inline]
fn own_error(heights: &[f32], a: usize, b: usize, m: usize) -> f64 {
    let average = (heights[a] as f64 + heights[b] as f64) / 2.0;
    (average - heights[m] as f64).abs()
}

/// Error and radius of vertex (c, r) from its own error and its children.
#[inline]
fn combine(
    heights: &[f32],
    side: usize,
    cell: f64,
    out: &[[f32; 2]],
    (c, r): (usize, usize),
    own: f64,
    children: &[(i64, i64)],
) -> [f32; 2] {
    let p = terrain_position(c, r, side, cell, heights[r * side + c] as f64);
    let mut error = own as f32;
    let mut radius = 0.0f64;
    for &(dc, dr) in children {
        let (nc, nr) = (c as i64 + dc, r as i64 + dr);
        if nc < 0 || nr < 0 || nc >= side as i64 || nr >= side as i64 {
            continue;
        }
        let (nc, nr) = (nc as usize, nr as usize);
        let k = nr * side + nc;
        let q = terrain_position(nc, nr, side, cell, heights[k] as f64);
        error = error.max(out[k][0]);
        let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
        radius = radius.max(d + out[k][1] as f64);
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

/// One level of the hierarchy: the vertices on rows `first, first + step, …`,
/// at the columns `columns(row)` gives as (start, step).
struct Level {
    first_row: usize,
    row_step: usize,
    columns: fn(usize, usize) -> (usize, usize),
    h: usize,
}

impl Level {
    /// Compute `value(c, r)` for every vertex of the level from the finished
    /// finer levels in `out`, then store the results. Values are computed in
    /// parallel into `scratch`, so `out` is only read while they are.
    fn run(
        &self,
        out: &mut [[f32; 2]],
        scratch: &mut Vec<[f32; 2]>,
        side: usize,
        value: impl Fn(&[[f32; 2]], usize, usize) -> [f32; 2] + Sync,
    ) {
        let rows: Vec<usize> = (self.first_row..side).step_by(self.row_step).collect();
        let per_row = (side - 1) / (2 * self.h) + 1;
        scratch.clear();
        scratch.resize(rows.len() * per_row, [0.0; 2]);
        let read: &[[f32; 2]] = out;
        scratch
            .par_chunks_mut(per_row)
            .zip(&rows)
            .for_each(|(values, &r)| {
                let (start, step) = (self.columns)(r, self.h);
                for (value_out, c) in values.iter_mut().zip((start..side).step_by(step)) {
                    *value_out = value(read, c, r);
                }
            });
        let written: &[[f32; 2]] = scratch;
        out.par_chunks_mut(side).enumerate().for_each(|(r, row)| {
            if r < self.first_row || (r - self.first_row) % self.row_step != 0 {
                return;
            }
            let k = (r - self.first_row) / self.row_step;
            let (start, step) = (self.columns)(r, self.h);
            for (v, c) in written[k * per_row..(k + 1) * per_row]
                .iter()
                .zip((start..side).step_by(step))
            {
                row[c] = *v;
            }
        });
    }
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
                    // Parents sit across the hypotenuse, as far from the vertex
                    // as its end points are: rotate (a − m) by ±90°.
                    let m = r * side + c;
                    let (ac, ar) = ((a % side) as i64 - c as i64, (a / side) as i64 - r as i64);
                    let at = |dc: i64, dr: i64| {
                        let (pc, pr) = (c as i64 + dc, r as i64 + dr);
                        (pc >= 0 && pr >= 0 && pc < side as i64 && pr < side as i64)
                            .then(|| pr as usize * side + pc as usize)
                    };
                    f(&Diamond {
                        vertex: m,
                        hypotenuse: [a, b],
                        parents: [at(-ar, ac), at(ar, -ac)],
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
        if (r / h) % 2 == 0 {
            (m - h, m + h)
        } else {
            (m - h * side, m + h * side)
        }
    } else if (c / (2 * h) + r / (2 * h)) % 2 == 0 {
        (m - h * side - h, m + h * side + h)
    } else {
        (m - h * side + h, m + h * side - h)
    }
}

/// Columns of edge vertices on row r: c ≡ h (mod 2h) on rows r ≡ 0, else c ≡ 0.
fn edge_columns(r: usize, h: usize) -> (usize, usize) {
    if (r / h) % 2 == 0 {
        (h, 2 * h)
    } else {
        (0, 2 * h)
    }
}

/// Columns of centre vertices: c ≡ h (mod 2h).
fn centre_columns(_r: usize, h: usize) -> (usize, usize) {
    (h, 2 * h)
}

/// Edge vertices of scale h: (c ≡ h, r ≡ 0) and (c ≡ 0, r ≡ h) modulo 2h.
fn edge_level(
    heights: &[f32],
    side: usize,
    cell: f64,
    h: usize,
    out: &mut [[f32; 2]],
    scratch: &mut Vec<[f32; 2]>,
) {
    let q = (h / 2) as i64;
    let kids: &[(i64, i64)] = if h >= 2 {
        &[(-q, -q), (q, -q), (-q, q), (q, q)]
    } else {
        &[]
    };
    let level = Level {
        first_row: 0,
        row_step: h,
        columns: edge_columns,
        h,
    };
    level.run(out, scratch, side, |read, c, r| {
        let (a, b) = hypotenuse(side, c, r, h, true);
        combine(
            heights,
            side,
            cell,
            read,
            (c, r),
            own_error(heights, a, b, r * side + c),
            kids,
        )
    });
}

/// Centre vertices of 2h-blocks: c ≡ h and r ≡ h modulo 2h.
fn centre_level(
    heights: &[f32],
    side: usize,
    cell: f64,
    h: usize,
    out: &mut [[f32; 2]],
    scratch: &mut Vec<[f32; 2]>,
) {
    let hi = h as i64;
    let kids = [(-hi, 0), (hi, 0), (0, -hi), (0, hi)];
    let level = Level {
        first_row: h,
        row_step: 2 * h,
        columns: centre_columns,
        h,
    };
    level.run(out, scratch, side, |read, c, r| {
        let (a, b) = hypotenuse(side, c, r, h, false);
        combine(
            heights,
            side,
            cell,
            read,
            (c, r),
            own_error(heights, a, b, r * side + c),
            &kids,
        )
    });
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
        let h = Hierarchy::compute(&heights, side, 30.0);
        assert_eq!(h.nesting_violations(&heights, 10), Vec::<String>::new());
        // Corners never split: zero. The centre carries the largest error.
        assert_eq!(h.error(0), 0.0);
        let max = h.error_radius.iter().map(|e| e[0]).fold(0.0, f32::max);
        assert_eq!(h.error(32 * side + 32), max);
    }

    #[test]
    fn planes_have_no_error() {
        let side = 17;
        let heights: Vec<f32> = (0..side * side)
            .map(|i| (i % side) as f32 * 2.0 - (i / side) as f32)
            .collect();
        let h = Hierarchy::compute(&heights, side, 1.0);
        assert!(h.error_radius.iter().all(|e| e[0] == 0.0));
        // Radii still bound every descendant: the centre's sphere reaches the corners' children.
        assert!(h.radius(8 * side + 8) > 0.0);
    }

    #[test]
    fn finest_radius_is_one_diagonal_step() {
        // A flat 3×3 grid: the centre's children are the edge midpoints at one cell.
        let h = Hierarchy::compute(&[0.0; 9], 3, 10.0);
        assert_eq!(h.radius(4), 10.0);
        assert_eq!(h.radius(1), 0.0);
        let kids: Vec<_> = h.children(1, 1).collect();
        assert_eq!(kids, vec![(0, 1), (2, 1), (1, 0), (1, 2)]);
    }

    #[test]
    fn detects_broken_nesting() {
        let side = 9;
        let heights = surface(side);
        let mut h = Hierarchy::compute(&heights, side, 1.0);
        h.error_radius[4 * side + 4][0] = 0.0;
        assert!(!h.nesting_violations(&heights, 10).is_empty());
    }
}
