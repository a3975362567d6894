//! Filling no-data holes in a height band by natural-neighbour interpolation.
//!
//! Each hole (a 4-connected run of no-data cells) is filled from the ring of
//! valid cells around it: the ring is Delaunay-triangulated in one bulk load
//! (spade) and every hole cell takes Sibson's natural-neighbour interpolant
//! (Sibson, "A brief description of natural neighbour interpolation", 1981),
//! which reproduces the ring exactly and has no overshoot.
//! Holes larger than a limit, and holes open to the grid edge (there is no
//! data beyond to interpolate from), are left as no-data.

use rayon::prelude::*;
use serde::Serialize;
use spade::{DelaunayTriangulation, HasPosition, Point2};

/// What a fill did.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct FillReport {
    pub holes_filled: usize,
    pub cells_filled: usize,
    /// Holes left as no-data: too large, or touching the grid edge.
    pub holes_left: usize,
    pub cells_left: usize,
}

struct RingCell {
    position: Point2<f64>,
    height: f64,
}

impl HasPosition for RingCell {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.position
    }
}

/// Fill the holes of at most `max_hole_cells` cells in `values` (row-major
/// `width`×`height`, NaN = no-data) in place.
pub fn fill_holes(
    values: &mut [f64],
    width: usize,
    height: usize,
    max_hole_cells: usize,
) -> FillReport {
    fill_holes_at(values, width, height, max_hole_cells, [0, 0])
}

/// [`fill_holes`] on a window of a larger raster whose first cell is
/// column `origin[0]`, row `origin[1]` of it: positions are the raster's,
/// so a hole and its ring inside the window are filled bit for bit as the
/// whole raster fills them. Holes touching the window's edge are left, as
/// holes at the raster's edge are.
pub fn fill_holes_at(
    values: &mut [f64],
    width: usize,
    height: usize,
    max_hole_cells: usize,
    origin: [usize; 2],
) -> FillReport {
    assert_eq!(values.len(), width * height);
    let holes = find_holes(values, width, height);
    let mut report = FillReport::default();
    let (fillable, left): (Vec<_>, Vec<_>) = holes
        .into_iter()
        .partition(|h| !h.touches_edge && h.cells.len() <= max_hole_cells);
    report.holes_left = left.len();
    report.cells_left = left.iter().map(|h| h.cells.len()).sum();

    let source: &[f64] = values;
    let filled: Vec<Vec<(usize, f64)>> = fillable
        .par_iter()
        .map(|hole| interpolate_hole(source, width, height, &hole.cells, origin))
        .collect();
    for cells in filled {
        report.holes_filled += 1;
        for (i, h) in cells {
            values[i] = h;
            report.cells_filled += 1;
        }
    }
    report
}

struct Hole {
    cells: Vec<usize>,
    touches_edge: bool,
}

/// 4-connected components of NaN cells, in row-major order of their first cell.
fn find_holes(values: &[f64], width: usize, height: usize) -> Vec<Hole> {
    let mut seen = vec![false; values.len()];
    let mut holes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..values.len() {
        if seen[start] || !values[start].is_nan() {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let mut hole = Hole {
            cells: Vec::new(),
            touches_edge: false,
        };
        while let Some(i) = stack.pop() {
            hole.cells.push(i);
            let (c, r) = (i % width, i / width);
            if c == 0 || r == 0 || c + 1 == width || r + 1 == height {
                hole.touches_edge = true;
            }
            for n in crate::grid::neighbours4(i, width, height) {
                if !seen[n] && values[n].is_nan() {
                    seen[n] = true;
                    stack.push(n);
                }
            }
        }
        hole.cells.sort_unstable();
        holes.push(hole);
    }
    holes
}

/// Natural-neighbour heights for one interior hole, at the positions of the
/// raster `origin` places the window in.
fn interpolate_hole(
    values: &[f64],
    width: usize,
    height: usize,
    cells: &[usize],
    origin: [usize; 2],
) -> Vec<(usize, f64)> {
    let position = |n: usize| {
        Point2::new(
            (origin[0] + n % width) as f64,
            (origin[1] + n / width) as f64,
        )
    };
    let mut ring: Vec<usize> = Vec::new();
    for &i in cells {
        let (c, r) = ((i % width) as i64, (i / width) as i64);
        for dr in -1..=1 {
            for dc in -1..=1 {
                let (nc, nr) = (c + dc, r + dr);
                if nc < 0 || nr < 0 || nc >= width as i64 || nr >= height as i64 {
                    continue;
                }
                let n = nr as usize * width + nc as usize;
                if !values[n].is_nan() {
                    ring.push(n);
                }
            }
        }
    }
    ring.sort_unstable();
    ring.dedup();
    let points: Vec<RingCell> = ring
        .iter()
        .map(|&n| RingCell {
            position: position(n),
            height: values[n],
        })
        .collect();
    let Ok(triangulation) = DelaunayTriangulation::<RingCell>::bulk_load_stable(points) else {
        return Vec::new();
    };
    let nn = triangulation.natural_neighbor();
    cells
        .iter()
        .filter_map(|&i| {
            nn.interpolate(|v| v.data().height, position(i))
                .map(|h| (i, h))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproduces_a_plane_inside_holes() {
        let (w, h) = (32, 24);
        let plane = |c: usize, r: usize| 3.0 + 0.5 * c as f64 - 0.25 * r as f64;
        let mut v: Vec<f64> = (0..w * h).map(|i| plane(i % w, i / w)).collect();
        for r in 5..12 {
            for c in 8..20 {
                v[r * w + c] = f64::NAN;
            }
        }
        v[20 * w + 3] = f64::NAN;
        let report = fill_holes(&mut v, w, h, 1000);
        assert_eq!(report.holes_filled, 2);
        assert_eq!(report.cells_filled, 7 * 12 + 1);
        for (i, value) in v.iter().enumerate() {
            assert!((value - plane(i % w, i / w)).abs() < 1e-9, "cell {i}");
        }
    }

    #[test]
    fn leaves_large_and_edge_holes() {
        let (w, h) = (10, 10);
        let mut v = vec![1.0; w * h];
        v[0] = f64::NAN; // touches the edge
        for r in 3..7 {
            for c in 3..7 {
                v[r * w + c] = f64::NAN; // 16 cells
            }
        }
        let report = fill_holes(&mut v, w, h, 15);
        assert_eq!(report.holes_filled, 0);
        assert_eq!(report.holes_left, 2);
        assert_eq!(report.cells_left, 17);
        assert!(v[0].is_nan() && v[4 * w + 4].is_nan());
    }

    /// A window holding a hole and its ring fills it bit for bit as the
    /// whole raster does, on a real DEM with holes punched in it.
    #[test]
    fn a_window_fills_its_holes_as_the_whole_raster_does() {
        let dem = crate::testdata::dem("gironde_257.f32");
        let (w, h) = (dem.side, dem.side);
        let mut whole: Vec<f64> = dem.heights.iter().map(|&z| z as f64).collect();
        for (c0, r0, cw, rh) in [(40, 50, 7, 5), (120, 130, 1, 1), (200, 30, 12, 3)] {
            for r in r0..r0 + rh {
                for c in c0..c0 + cw {
                    whole[r * w + c] = f64::NAN;
                }
            }
        }
        let original = whole.clone();
        fill_holes(&mut whole, w, h, 1000);
        // Windows around each hole, grown by 1 to 9 cells beyond its ring.
        for (c0, r0, c1, r1) in [(37, 47, 49, 57), (110, 120, 131, 140), (195, 20, 220, 40)] {
            let (ww, wh) = (c1 - c0, r1 - r0);
            let mut window: Vec<f64> = (r0..r1)
                .flat_map(|r| original[r * w + c0..r * w + c1].iter().copied())
                .collect();
            fill_holes_at(&mut window, ww, wh, 1000, [c0, r0]);
            for r in r0..r1 {
                for c in c0..c1 {
                    let (a, b) = (window[(r - r0) * ww + c - c0], whole[r * w + c]);
                    assert_eq!(a.to_bits(), b.to_bits(), "({c}, {r}): {a} vs {b}");
                }
            }
        }
    }
}
