//! Object-space errors and bounding-sphere radii (LP seed §3.3, the
//! `IniciaErros` / `PropagaErrosRaios` pre-processing).
//!
//! The seed walks even and odd blocks recursively; here the same hierarchy
//! (its geometry: `diamond`) is computed in two passes over the grid
//! (`window`): every vertex's own error, then level by level, finest
//! first, every vertex of a level in parallel from the finished level
//! below. The same passes over a tile and its halo give the tile's values
//! bit for bit.
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

use super::diamond::{children, visit_bottom_up, Vertex};
pub use super::metric::ErrorMetric;
use super::vertices::terrain_position;
use super::window::{own_errors, saturate, HeightWindow, Rect};
use std::borrow::Cow;

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
        let window = HeightWindow {
            heights,
            rect: Rect::whole(side),
            side,
            cell_size_m,
        };
        let own = own_errors(&window, window.rect, metric, usize::MAX);
        let out = saturate(&window, &own, usize::MAX);
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
    pub fn children(&self, c: usize, r: usize) -> impl Iterator<Item = Vertex> {
        children(self.side, c, r)
    }
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
