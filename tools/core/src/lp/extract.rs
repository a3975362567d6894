//! The view-independent mesh: every triangle of the bisection hierarchy is
//! split while the error at its hypotenuse midpoint exceeds a tolerance.
//!
//! The traversal (starting triangles, child order, vertex numbering by
//! first use) follows @mapbox/martini's `getMesh`, so for the same errors the
//! vertex and triangle arrays are the same — the conformance tests compare
//! their digests.

use super::hierarchy::Hierarchy;
use super::metric::triangle_deviation;
use super::window::Rect;
use rayon::prelude::*;
use std::collections::HashMap;

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
        self.largest_deviation_of(
            &|c, r| heights[r * side + c],
            &|corners, z| triangle_deviation(heights, side, corners, z, None),
            &|| {},
        )
    }

    /// [`GridMesh::largest_deviation`] with the heights read through
    /// `height` (column, row) and each triangle's deviation measured by
    /// `deviation` (its corners and their heights), `release` called after
    /// each chunk of triangles — for a grid read tile by tile.
    pub fn largest_deviation_of(
        &self,
        height: &(dyn Fn(usize, usize) -> f32 + Sync),
        deviation: &(dyn Fn([(i64, i64); 3], [f32; 3]) -> f64 + Sync),
        release: &dyn Fn(),
    ) -> f64 {
        let mut largest = 0.0f64;
        for chunk in self.triangles.chunks(TRIANGLES_BETWEEN_RELEASES) {
            let part = chunk
                .par_iter()
                .map(|t| {
                    let corners = t.map(|i| {
                        let [c, r] = self.vertices[i as usize];
                        (c as i64, r as i64)
                    });
                    let z = corners.map(|(c, r)| height(c as usize, r as usize));
                    deviation(corners, z)
                })
                .reduce(|| 0.0, f64::max);
            largest = largest.max(part);
            release();
        }
        largest
    }
}

/// Triangles measured between two calls of the release in
/// [`GridMesh::largest_deviation_of`].
const TRIANGLES_BETWEEN_RELEASES: usize = 1 << 16;

/// Extract the mesh whose vertices all have error ≤ `max_error` metres left
/// unsplit. With `mask`, triangles are also split wherever they would mix
/// masked (0) and real (1) vertices, and triangles touching a masked vertex
/// are dropped, so no triangle covers padding or voids.
pub fn extract(h: &Hierarchy, max_error: f32, mask: Option<&[u8]>) -> GridMesh {
    let side = h.side;
    let error = |i: usize| h.error(i);
    let has_data = mask.map(|m| move |i: usize| m[i] != 0);
    walk(&MeshWalk {
        side,
        max_error,
        error: &error,
        has_data: has_data
            .as_ref()
            .map(|f| f as &(dyn Fn(usize) -> bool + Sync)),
        boundaries: None,
        window: None,
        max_vertices: usize::MAX,
    })
    .unwrap_or_default() // never: there is no vertex limit
}

/// What [`walk`] reads of a `side`² grid, by row-major vertex index: for a
/// grid in memory or one read tile by tile.
pub struct MeshWalk<'a> {
    pub side: usize,
    /// The tolerance, metres: a vertex whose error exceeds it is split.
    pub max_error: f32,
    /// A vertex's (saturated) object-space error, metres.
    pub error: &'a (dyn Fn(usize) -> f32 + Sync),
    /// Whether a vertex holds data; `None`: every vertex does.
    pub has_data: Option<&'a (dyn Fn(usize) -> bool + Sync)>,
    /// [`mask_boundaries`] of `has_data`, computed once by a caller that
    /// walks the same grid many times (window by window); `None`: the walk
    /// computes them (a pass over the whole grid).
    pub boundaries: Option<&'a VertexBits>,
    /// Keep only the triangles whose bounding box overlaps this rectangle
    /// of vertices with a positive area; `None`: the whole grid.
    pub window: Option<Rect>,
    /// The most vertices the mesh may have: the walk stops beyond.
    pub max_vertices: usize,
}

/// The mesh of [`extract`] for `input`: with a window, exactly the
/// triangles of the whole grid's mesh that meet it (a triangle's box
/// holds its children's, so the walk skips what lies outside without
/// changing what lies inside), numbered in the same traversal order.
/// `None` when it would have more than `max_vertices` vertices.
pub fn walk(input: &MeshWalk) -> Option<GridMesh> {
    let side = input.side;
    assert!(
        side - 1 <= u16::MAX as usize + 1,
        "grid too large for u16 vertex coordinates"
    );
    let computed;
    let mixed = match input.boundaries {
        Some(b) => Some(b),
        None => {
            computed = input.has_data.map(|d| mask_boundaries(side, d));
            computed.as_ref()
        }
    };
    let split = |m: usize| (input.error)(m) > input.max_error || mixed.is_some_and(|x| x.get(m));
    // A dense numbering for a whole grid when it is small, else only the
    // vertices used (a window's walk uses few of the grid's).
    let numbers = if input.window.is_none() && side * side <= DENSE_NUMBERING_VERTICES {
        Numbers::Dense(vec![0; side * side])
    } else {
        Numbers::Sparse(HashMap::new())
    };
    let mut state = Walk {
        side,
        max_vertices: input.max_vertices,
        numbers,
        mesh: GridMesh::default(),
        window: input
            .window
            .map(|w| [w.c0, w.r0, w.c0 + w.width - 1, w.r0 + w.height - 1].map(|v| v as i32)),
    };
    let max = (side - 1) as i32;
    state.walk(0, 0, max, max, max, 0, &split, input.has_data);
    state.walk(max, max, 0, 0, 0, max, &split, input.has_data);
    (state.mesh.vertices.len() <= input.max_vertices).then_some(state.mesh)
}

/// Grids up to this many vertices number theirs in a dense array (4 bytes
/// a vertex, 64 MiB at 4097²); larger ones in a map of the vertices used.
const DENSE_NUMBERING_VERTICES: usize = 4097 * 4097;

/// 1 + each used vertex's number (0: not used yet).
enum Numbers {
    Dense(Vec<u32>),
    Sparse(HashMap<usize, u32>),
}

impl Numbers {
    /// The vertex's number, `next` if it has none yet (and then it has).
    fn number(&mut self, i: usize, next: u32) -> u32 {
        let slot = match self {
            Numbers::Dense(v) => &mut v[i],
            Numbers::Sparse(m) => m.entry(i).or_insert(0),
        };
        if *slot == 0 {
            *slot = next + 1;
        }
        *slot - 1
    }
}

struct Walk {
    side: usize,
    max_vertices: usize,
    numbers: Numbers,
    mesh: GridMesh,
    /// Inclusive `[c0, r0, c1, r1]` the kept triangles' boxes must overlap.
    window: Option<[i32; 4]>,
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
        has_data: Option<&(dyn Fn(usize) -> bool + Sync)>,
    ) {
        if self.mesh.vertices.len() > self.max_vertices {
            return;
        }
        if let Some([c0, r0, c1, r1]) = self.window {
            // The box must overlap the window with a positive area.
            let (x0, x1) = (ax.min(bx).min(cx), ax.max(bx).max(cx));
            let (y0, y1) = (ay.min(by).min(cy), ay.max(by).max(cy));
            if x1 <= c0 || x0 >= c1 || y1 <= r0 || y0 >= r1 {
                return;
            }
        }
        let (mx, my) = ((ax + bx) >> 1, (ay + by) >> 1);
        let m = my as usize * self.side + mx as usize;
        if (ax - cx).abs() + (ay - cy).abs() > 1 && split(m) {
            self.walk(cx, cy, ax, ay, mx, my, split, has_data);
            self.walk(bx, by, cx, cy, mx, my, split, has_data);
            return;
        }
        let corners = [(ax, ay), (bx, by), (cx, cy)];
        if let Some(has_data) = has_data {
            if corners
                .iter()
                .any(|&(x, y)| !has_data(y as usize * self.side + x as usize))
            {
                return;
            }
        }
        let mut tri = [0u32; 3];
        for (t, (x, y)) in tri.iter_mut().zip(corners) {
            let next = self.mesh.vertices.len() as u32;
            *t = self
                .numbers
                .number(y as usize * self.side + x as usize, next);
            if *t == next {
                self.mesh.vertices.push([x as u16, y as u16]);
            }
        }
        self.mesh.triangles.push(tri);
    }
}

/// One bit per vertex of a grid.
pub struct VertexBits(Vec<u64>);

impl VertexBits {
    pub(crate) fn new(vertices: usize) -> Self {
        VertexBits(vec![0; vertices.div_ceil(64)])
    }

    #[inline]
    pub fn get(&self, i: usize) -> bool {
        self.0[i / 64] >> (i % 64) & 1 == 1
    }

    #[inline]
    pub(crate) fn set(&mut self, i: usize) {
        self.0[i / 64] |= 1 << (i % 64);
    }
}

/// Per vertex: whether its diamond (and so any triangle it splits) holds
/// both masked and real vertices (`has_data` tells them apart). Computed
/// bottom-up like the errors, so it is nested: a flagged vertex's parents
/// are flagged too. One bit a vertex, for grids of any size.
pub fn mask_boundaries(side: usize, has_data: &(dyn Fn(usize) -> bool + Sync)) -> VertexBits {
    let mut flag = VertexBits::new(side * side);
    super::diamond::visit_bottom_up(side, |d| {
        let m = has_data(d.vertex);
        let corners = d.hypotenuse.iter().chain(d.parents.iter().flatten());
        let own = corners.into_iter().any(|&k| has_data(k) != m);
        if own || d.children.iter().flatten().any(|&k| flag.get(k)) {
            flag.set(d.vertex);
        }
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

    /// A window's mesh is exactly the whole mesh's triangles whose boxes
    /// overlap it (with a positive area), with and without a mask, at
    /// several tolerances, on windows aligned with nothing in particular.
    #[test]
    fn a_window_keeps_exactly_the_whole_meshs_triangles_that_meet_it() {
        let dem = testdata::dem("gironde_257.f32");
        let side = dem.side;
        let h = Hierarchy::compute(&dem.heights, side, dem.cell_size_m, ErrorMetric::default());
        let mask: Vec<u8> = dem.heights.iter().map(|&z| u8::from(z >= 0.0)).collect();
        let error = |i: usize| h.error(i);
        let has_data = |i: usize| mask[i] != 0;
        let triangles = |m: &GridMesh| -> std::collections::BTreeSet<[[u16; 2]; 3]> {
            m.triangles
                .iter()
                .map(|t| t.map(|i| m.vertices[i as usize]))
                .collect()
        };
        for masked in [false, true] {
            for max_error in [0.5f32, 5.0, 40.0] {
                let input = |window| MeshWalk {
                    side,
                    max_error,
                    error: &error,
                    has_data: masked.then_some(&has_data as &(dyn Fn(usize) -> bool + Sync)),
                    boundaries: None,
                    window,
                    max_vertices: usize::MAX,
                };
                let whole = walk(&input(None)).unwrap();
                // The mask's boundaries computed once give the same mesh.
                let bits = mask_boundaries(side, &has_data);
                let shared = MeshWalk {
                    boundaries: masked.then_some(&bits),
                    ..input(None)
                };
                assert_eq!(
                    walk(&shared).unwrap(),
                    whole,
                    "masked {masked}, {max_error} m"
                );
                assert_eq!(whole, extract(&h, max_error, masked.then_some(&mask)));
                for rect in [
                    [0, 0, 256, 256],
                    [37, 101, 150, 222],
                    [128, 0, 129, 64],
                    [5, 5, 9, 6],
                ] {
                    let [c0, r0, c1, r1] = rect;
                    let window = Rect {
                        c0,
                        r0,
                        width: c1 - c0 + 1,
                        height: r1 - r0 + 1,
                    };
                    let part = walk(&input(Some(window))).unwrap();
                    let expected: std::collections::BTreeSet<_> = triangles(&whole)
                        .into_iter()
                        .filter(|t| {
                            let cs = t.map(|v| v[0] as usize);
                            let rs = t.map(|v| v[1] as usize);
                            let (x0, x1) = (*cs.iter().min().unwrap(), *cs.iter().max().unwrap());
                            let (y0, y1) = (*rs.iter().min().unwrap(), *rs.iter().max().unwrap());
                            x1 > c0 && x0 < c1 && y1 > r0 && y0 < r1
                        })
                        .collect();
                    let what = format!("{rect:?} at {max_error} m, masked {masked}");
                    assert!(!expected.is_empty() || masked, "{what}: an empty window");
                    assert_eq!(triangles(&part), expected, "{what}");
                    assert_eq!(
                        part.triangles.len(),
                        expected.len(),
                        "{what}: a triangle twice"
                    );
                }
                // A vertex limit below the mesh's size stops the walk.
                let limited = MeshWalk {
                    max_vertices: whole.vertices.len() - 1,
                    ..input(None)
                };
                assert!(walk(&limited).is_none());
            }
        }
    }
}
