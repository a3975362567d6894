//! The view-independent mesh: every triangle of the bisection hierarchy is
//! split while the error at its hypotenuse midpoint exceeds a tolerance.
//!
//! The traversal (starting triangles, child order, vertex numbering by
//! first use) follows @mapbox/martini's `getMesh`, so for the same errors the
//! vertex and triangle arrays are the same — the conformance tests compare
//! their digests.

use super::hierarchy::Hierarchy;
use super::metric::triangle_deviation;
use rayon::prelude::*;

/// An indexed triangle mesh on grid vertices.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GridMesh {
    /// Vertex (column, row) pairs, numbered by first use.
    pub vertices: Vec<[u16; 2]>,
    /// Counter-clockwise in (column, row) order as martini emits them.
    pub triangles: Vec<[u32; 3]>,
}

impl GridMesh {
    /// The largest vertical distance between a grid point and the triangle
    /// of this mesh over it, metres (`heights` row-major, `side` wide).
    /// With errors of [`super::ErrorMetric::Bound`], at most the tolerance
    /// the mesh was extracted at.
    pub fn largest_deviation(&self, heights: &[f32], side: usize) -> f64 {
        self.triangles
            .par_iter()
            .map(|t| {
                let corner = |i: u32| {
                    let [c, r] = self.vertices[i as usize];
                    (c as i64, r as i64)
                };
                let corners = t.map(corner);
                let z = corners.map(|(c, r)| heights[r as usize * side + c as usize]);
                triangle_deviation(heights, side, corners, z, None)
            })
            .reduce(|| 0.0, f64::max)
    }
}

/// Extract the mesh whose vertices all have error ≤ `max_error` metres left
/// unsplit. With `mask`, triangles are also split wherever they would mix
/// masked (0) and real (1) vertices, and triangles touching a masked vertex
/// are dropped, so no triangle covers padding or voids.
pub fn extract(h: &Hierarchy, max_error: f32, mask: Option<&[u8]>) -> GridMesh {
    let side = h.side;
    assert!(
        side - 1 <= u16::MAX as usize + 1,
        "grid too large for u16 vertex coordinates"
    );
    let mixed = mask.map(|m| mask_boundaries(m, side));
    let split = |m: usize| h.error(m) > max_error || mixed.as_ref().is_some_and(|x| x[m]);
    let mut state = Walk {
        side,
        index: vec![0u32; side * side],
        mesh: GridMesh::default(),
    };
    let max = (side - 1) as i32;
    state.walk(0, 0, max, max, max, 0, &split, mask);
    state.walk(max, max, 0, 0, 0, max, &split, mask);
    state.mesh
}

struct Walk {
    side: usize,
    /// 1 + vertex number, 0 while unused.
    index: Vec<u32>,
    mesh: GridMesh,
}

impl Walk {
    /// Triangle a–b–c with hypotenuse a–b and right angle at c.
    #[allow(clippy::too_many_arguments)]
    fn walk(
        &mut self,
        ax: i32,
        ay: i32,
        bx: i32,
        by: i32,
        cx: i32,
        cy: i32,
        split: &impl Fn(usize) -> bool,
        mask: Option<&[u8]>,
    ) {
        let (mx, my) = ((ax + bx) >> 1, (ay + by) >> 1);
        let m = my as usize * self.side + mx as usize;
        if (ax - cx).abs() + (ay - cy).abs() > 1 && split(m) {
            self.walk(cx, cy, ax, ay, mx, my, split, mask);
            self.walk(bx, by, cx, cy, mx, my, split, mask);
            return;
        }
        let corners = [(ax, ay), (bx, by), (cx, cy)];
        if let Some(mask) = mask {
            if corners
                .iter()
                .any(|&(x, y)| mask[y as usize * self.side + x as usize] == 0)
            {
                return;
            }
        }
        let mut tri = [0u32; 3];
        for (t, (x, y)) in tri.iter_mut().zip(corners) {
            let i = y as usize * self.side + x as usize;
            if self.index[i] == 0 {
                self.mesh.vertices.push([x as u16, y as u16]);
                self.index[i] = self.mesh.vertices.len() as u32;
            }
            *t = self.index[i] - 1;
        }
        self.mesh.triangles.push(tri);
    }
}

/// Per vertex: whether its diamond (and so any triangle it splits) holds
/// both masked and real vertices. Computed bottom-up like the errors, so it
/// is nested: a flagged vertex's parents are flagged too.
pub fn mask_boundaries(mask: &[u8], side: usize) -> Vec<bool> {
    let mut flag = vec![false; side * side];
    super::diamond::visit_bottom_up(side, |d| {
        let m = mask[d.vertex];
        let corners = d.hypotenuse.iter().chain(d.parents.iter().flatten());
        let own = corners.into_iter().any(|&k| mask[k] != m);
        flag[d.vertex] = own || d.children.iter().flatten().any(|&k| flag[k]);
    });
    flag
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lp::ErrorMetric;
    use crate::testdata;

    /// Twice the plan area of the mesh's triangles, in cells², and whether
    /// any triangle touches a vertex where `touching` is true.
    fn area2_and_touch(
        mesh: &GridMesh,
        side: usize,
        touching: impl Fn(usize) -> bool,
    ) -> (i64, bool) {
        let mut area2 = 0i64;
        let mut touched = false;
        for t in &mesh.triangles {
            let p = t
                .map(|i| mesh.vertices[i as usize])
                .map(|v| (v[0] as i64, v[1] as i64));
            touched |= p
                .iter()
                .any(|&(c, r)| touching(r as usize * side + c as usize));
            area2 += ((p[1].0 - p[0].0) * (p[2].1 - p[0].1)
                - (p[1].1 - p[0].1) * (p[2].0 - p[0].0))
                .abs();
        }
        (area2, touched)
    }

    #[test]
    fn meshes_of_real_dems_tile_the_grid_and_leave_out_only_small_errors() {
        for dem in testdata::dems() {
            let side = dem.side;
            let h = Hierarchy::compute(&dem.heights, side, dem.cell_size_m, ErrorMetric::default());
            let mut previous = usize::MAX;
            for max_error in [0.0, 1.0, 10.0, 50.0] {
                let mesh = extract(&h, max_error, None);
                let (area2, _) = area2_and_touch(&mesh, side, |_| false);
                let what = format!("{} at {max_error} m", dem.name);
                assert_eq!(area2, 2 * ((side - 1) * (side - 1)) as i64, "{what}");
                let mut used = vec![false; side * side];
                for v in &mesh.vertices {
                    used[v[1] as usize * side + v[0] as usize] = true;
                }
                for (i, _) in used.iter().enumerate().filter(|(_, u)| !**u) {
                    assert!(h.error(i) <= max_error, "{what}: vertex {i} left out");
                }
                if max_error == 0.0 {
                    // Only vertices on planes (error exactly 0) may be left out.
                    assert!(mesh.vertices.len() > side * side / 2, "{what}");
                }
                assert!(mesh.vertices.len() <= previous, "{what}: more vertices");
                previous = mesh.vertices.len();
            }
        }
    }

    /// The guarantee `mesh --max-error` states: on every real crop and at
    /// several tolerances, no grid point is farther from the mesh than the
    /// tolerance with the bound metric; the midpoint metric (martini's)
    /// breaks it by several times on the same crops, with fewer triangles.
    #[test]
    fn bound_errors_keep_every_grid_point_within_the_tolerance() {
        let mut midpoint_worst = 0.0f64;
        for dem in testdata::dems() {
            let side = dem.side;
            let bound = Hierarchy::compute(&dem.heights, side, dem.cell_size_m, ErrorMetric::Bound);
            let midpoint =
                Hierarchy::compute(&dem.heights, side, dem.cell_size_m, ErrorMetric::Midpoint);
            for max_error in [0.5f32, 2.0, 5.0, 20.0] {
                let mesh = extract(&bound, max_error, None);
                let deviation = mesh.largest_deviation(&dem.heights, side);
                assert!(
                    deviation <= max_error as f64,
                    "{} at {max_error} m: a grid point {deviation} m from the mesh",
                    dem.name
                );
                let loose = extract(&midpoint, max_error, None);
                assert!(loose.triangles.len() <= mesh.triangles.len());
                midpoint_worst = midpoint_worst
                    .max(loose.largest_deviation(&dem.heights, side) / max_error as f64);
            }
        }
        assert!(
            midpoint_worst > 1.5,
            "midpoint meshes: {midpoint_worst}× the tolerance"
        );
    }

    /// `triangle_deviation` against a brute-force scan of the bounding box
    /// with an exact point-in-triangle test, on hierarchy-shaped triangles
    /// of a real DEM (axis-aligned and diagonal hypotenuses).
    #[test]
    fn triangle_deviation_scans_exactly_the_points_inside() {
        let dem = testdata::dem("fuji_257.f32");
        let side = dem.side as i64;
        let z = |c: i64, r: i64| dem.heights[(r * side + c) as usize] as f64;
        let brute = |t: [(i64, i64); 3]| {
            let [a, b, c] = t;
            let cross = |p: (i64, i64), q: (i64, i64), s: (i64, i64)| {
                (q.0 - p.0) * (s.1 - p.1) - (q.1 - p.1) * (s.0 - p.0)
            };
            let area = cross(a, b, c) as f64;
            let mut largest = 0.0f64;
            for r in 0..side {
                for col in 0..side {
                    let p = (col, r);
                    let (u, v, w) = (cross(b, c, p), cross(c, a, p), cross(a, b, p));
                    let inside = (u >= 0 && v >= 0 && w >= 0) || (u <= 0 && v <= 0 && w <= 0);
                    if inside {
                        let plane = (u as f64 * z(a.0, a.1)
                            + v as f64 * z(b.0, b.1)
                            + w as f64 * z(c.0, c.1))
                            / area;
                        largest = largest.max((z(col, r) - plane).abs());
                    }
                }
            }
            largest
        };
        for t in [
            [(0, 64), (64, 64), (32, 32)],
            [(64, 0), (64, 64), (96, 32)],
            [(0, 0), (32, 32), (32, 0)],
            [(32, 0), (0, 32), (0, 0)],
            [(100, 100), (108, 108), (100, 108)],
        ] {
            let z = t.map(|(c, r)| dem.heights[(r * side + c) as usize]);
            let fast = triangle_deviation(&dem.heights, dem.side, t, z, None);
            assert!(
                (fast - brute(t)).abs() < 1e-9,
                "{t:?}: {fast} vs {}",
                brute(t)
            );
            assert!(fast > 0.0, "{t:?}");
        }
    }

    #[test]
    fn a_mask_keeps_triangles_off_voids_and_covers_the_data() {
        // Gironde's sea floor (below 0 m) as the void: an irregular real coast.
        let dem = testdata::dem("gironde_257.f32");
        let side = dem.side;
        let h = Hierarchy::compute(&dem.heights, side, dem.cell_size_m, ErrorMetric::default());
        let mask: Vec<u8> = dem.heights.iter().map(|&z| u8::from(z >= 0.0)).collect();
        // Cells whose four corners all hold data: what the mesh must cover.
        let full_cells = (0..side - 1)
            .flat_map(|r| (0..side - 1).map(move |c| (c, r)))
            .filter(|&(c, r)| {
                [(c, r), (c + 1, r), (c, r + 1), (c + 1, r + 1)]
                    .iter()
                    .all(|&(c, r)| mask[r * side + c] == 1)
            })
            .count() as i64;
        for max_error in [0.0, 2.0, 20.0] {
            let mesh = extract(&h, max_error, Some(&mask));
            let (area2, touched) = area2_and_touch(&mesh, side, |i| mask[i] == 0);
            assert!(!touched, "a triangle touches the void at {max_error} m");
            // Whole data cells are covered; half cells along the coast may be too.
            assert!(area2 >= 2 * full_cells, "{area2} < {}", 2 * full_cells);
            assert!(area2 > 0);
        }
    }
}
