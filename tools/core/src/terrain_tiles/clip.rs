//! A region's mesh cut into one tile: its triangles clipped to the tile's
//! rectangle (in longitude and latitude), and the rest of the tile filled
//! down to the ellipsoid.
//!
//! Neighbouring tiles must meet exactly, so every vertex a cut makes is
//! computed from what both tiles share, never from the order the clipping
//! ran in: a point where an edge of the mesh crosses a tile line is
//! interpolated along that edge (its endpoints in a fixed order) and put on
//! the line exactly; a tile corner inside a triangle takes the triangle's
//! plane (its corners in a fixed order). Both tiles then hold bit-identical
//! positions, heights and normals along their common edge.

use super::ellipsoid::east_north_up;
use std::collections::HashMap;

/// A triangle mesh on the ellipsoid.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SurfaceMesh {
    /// Longitude and latitude, degrees.
    pub lon_lat_deg: Vec<[f64; 2]>,
    /// Heights above the WGS84 ellipsoid, metres.
    pub height_m: Vec<f64>,
    /// Unit normals, ECEF.
    pub normal: Vec<[f64; 3]>,
    /// Counter-clockwise seen from above (east right, north up).
    pub triangles: Vec<[u32; 3]>,
}

impl SurfaceMesh {
    fn push(&mut self, lon_lat: [f64; 2], height_m: f64, normal: [f64; 3]) -> u32 {
        self.lon_lat_deg.push(lon_lat);
        self.height_m.push(height_m);
        self.normal.push(normal);
        (self.lon_lat_deg.len() - 1) as u32
    }

    /// Twice the signed area of triangle `t` in degrees² (positive:
    /// counter-clockwise).
    fn doubled_area(&self, t: [u32; 3]) -> f64 {
        let [a, b, c] = t.map(|i| self.lon_lat_deg[i as usize]);
        (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
    }
}

/// A tile line: a meridian (longitude) or a parallel (latitude), degrees,
/// as bits so that it can key a vertex.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Line {
    Meridian(u64),
    Parallel(u64),
}

impl Line {
    fn value(self) -> f64 {
        match self {
            Line::Meridian(v) | Line::Parallel(v) => f64::from_bits(v),
        }
    }
    fn axis(self) -> usize {
        match self {
            Line::Meridian(_) => 0,
            Line::Parallel(_) => 1,
        }
    }
}

/// Where a vertex of a clipped triangle comes from; it fixes how the vertex
/// is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Origin {
    /// A vertex of the mesh.
    Vertex(u32),
    /// Edge (a, b), a < b, crossing a tile line.
    Crossing(u32, u32, Line),
    /// A tile corner (meridian, parallel) inside triangle (sorted corners).
    Corner([u32; 3], u64, u64),
}

/// A clipped polygon's vertex: its origin and position.
#[derive(Debug, Clone, Copy)]
struct Point {
    origin: Origin,
    lon_lat: [f64; 2],
}

/// The mesh edge two consecutive points of a clipped triangle lie on, if
/// they lie on one (else they lie on a tile line).
fn common_edge(p: Origin, q: Origin) -> Option<(u32, u32)> {
    let sorted = |a: u32, b: u32| (a.min(b), a.max(b));
    match (p, q) {
        (Origin::Vertex(a), Origin::Vertex(b)) => Some(sorted(a, b)),
        (Origin::Vertex(a), Origin::Crossing(x, y, _))
        | (Origin::Crossing(x, y, _), Origin::Vertex(a)) => (a == x || a == y).then_some((x, y)),
        (Origin::Crossing(a, b, _), Origin::Crossing(x, y, _)) => {
            ((a, b) == (x, y)).then_some((a, b))
        }
        _ => None,
    }
}

/// Position, height and normal of a point, computed from its origin alone.
fn attributes(mesh: &SurfaceMesh, origin: Origin) -> ([f64; 2], f64, [f64; 3]) {
    let at = |i: u32| {
        let i = i as usize;
        (mesh.lon_lat_deg[i], mesh.height_m[i], mesh.normal[i])
    };
    match origin {
        Origin::Vertex(v) => at(v),
        Origin::Crossing(a, b, line) => {
            let ((pa, ha, na), (pb, hb, nb)) = (at(a), at(b));
            let axis = line.axis();
            let t = (line.value() - pa[axis]) / (pb[axis] - pa[axis]);
            let mut p = [0, 1].map(|k| pa[k] + t * (pb[k] - pa[k]));
            p[axis] = line.value();
            let n = [0, 1, 2].map(|k| na[k] + t * (nb[k] - na[k]));
            (p, ha + t * (hb - ha), normalised(n))
        }
        Origin::Corner(sorted, lon, lat) => {
            let p = [f64::from_bits(lon), f64::from_bits(lat)];
            let [(a, ha, na), (b, hb, nb), (c, hc, nc)] = sorted.map(at);
            // Barycentric weights of p in (a, b, c).
            let det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
            let wb = ((p[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (p[1] - a[1])) / det;
            let wc = ((b[0] - a[0]) * (p[1] - a[1]) - (p[0] - a[0]) * (b[1] - a[1])) / det;
            let wa = 1.0 - wb - wc;
            let n = [0, 1, 2].map(|k| wa * na[k] + wb * nb[k] + wc * nc[k]);
            (p, wa * ha + wb * hb + wc * hc, normalised(n))
        }
    }
}

fn normalised(n: [f64; 3]) -> [f64; 3] {
    super::ellipsoid::unit(n).unwrap_or([0.0, 0.0, 1.0])
}

/// Clip triangle `t` of `mesh` to `bounds` (`[west, south, east, north]`):
/// the convex polygon left, as points with their origins.
fn clip_triangle(mesh: &SurfaceMesh, t: [u32; 3], bounds: [f64; 4]) -> Vec<Point> {
    let mut sorted = t;
    sorted.sort_unstable();
    let mut polygon: Vec<Point> = t
        .iter()
        .map(|&v| Point {
            origin: Origin::Vertex(v),
            lon_lat: mesh.lon_lat_deg[v as usize],
        })
        .collect();
    let [w, s, e, n] = bounds;
    // (line, keep the side ≥ value?)
    let planes = [
        (Line::Meridian(w.to_bits()), true),
        (Line::Meridian(e.to_bits()), false),
        (Line::Parallel(s.to_bits()), true),
        (Line::Parallel(n.to_bits()), false),
    ];
    for (line, keep_above) in planes {
        if polygon.is_empty() {
            break;
        }
        let inside = |p: &Point| {
            let v = p.lon_lat[line.axis()];
            if keep_above {
                v >= line.value()
            } else {
                v <= line.value()
            }
        };
        let mut out = Vec::with_capacity(polygon.len() + 2);
        for i in 0..polygon.len() {
            let (p, q) = (polygon[i], polygon[(i + 1) % polygon.len()]);
            let (p_in, q_in) = (inside(&p), inside(&q));
            if p_in {
                out.push(p);
            }
            if p_in != q_in {
                out.push(crossing(mesh, sorted, p, q, line));
            }
        }
        polygon = out;
    }
    polygon
}

/// The point where segment p–q of a clipped triangle (`sorted` corners)
/// crosses `line`.
fn crossing(mesh: &SurfaceMesh, sorted: [u32; 3], p: Point, q: Point, line: Line) -> Point {
    let origin = match common_edge(p.origin, q.origin) {
        Some((a, b)) => {
            let o = Origin::Crossing(a, b, line);
            // An edge crossing exactly at an endpoint is that vertex.
            let lon_lat = attributes(mesh, o).0;
            if lon_lat == mesh.lon_lat_deg[a as usize] {
                Origin::Vertex(a)
            } else if lon_lat == mesh.lon_lat_deg[b as usize] {
                Origin::Vertex(b)
            } else {
                o
            }
        }
        // p–q runs along the other kind of tile line: a tile corner.
        None => match line {
            Line::Meridian(lon) => Origin::Corner(sorted, lon, p.lon_lat[1].to_bits()),
            Line::Parallel(lat) => Origin::Corner(sorted, p.lon_lat[0].to_bits(), lat),
        },
    };
    Point {
        origin,
        lon_lat: attributes(mesh, origin).0,
    }
}

/// The part of `mesh` (triangles `candidates`) inside `bounds`, and the
/// rest of the rectangle filled: its corners on the ellipsoid (height 0)
/// joined to the edge of the mesh by a constrained Delaunay triangulation,
/// so the tile has no hole. `covered` says which of the result's triangles
/// carry the region's data (the first ones); the others are fill.
pub fn tile_patch(
    mesh: &SurfaceMesh,
    candidates: &[u32],
    bounds: [f64; 4],
) -> (SurfaceMesh, usize) {
    let mut patch = SurfaceMesh::default();
    let mut index: HashMap<Origin, u32> = HashMap::new();
    for &t in candidates {
        let triangle = mesh.triangles[t as usize];
        let polygon = clip_triangle(mesh, triangle, bounds);
        if polygon.len() < 3 {
            continue;
        }
        let mut sorted = triangle;
        sorted.sort_unstable();
        let ids: Vec<u32> = polygon
            .iter()
            .map(|p| {
                *index.entry(p.origin).or_insert_with(|| {
                    let (lon_lat, h, n) = attributes(mesh, p.origin);
                    patch.push(lon_lat, h, n)
                })
            })
            .collect();
        for k in 1..ids.len() - 1 {
            let tri = [ids[0], ids[k], ids[k + 1]];
            if tri[0] != tri[1]
                && tri[1] != tri[2]
                && tri[0] != tri[2]
                && patch.doubled_area(tri) > 0.0
            {
                patch.triangles.push(tri);
            }
        }
    }
    let covered = patch.triangles.len();
    fill(&mut patch, bounds);
    (patch, covered)
}

/// Fill what the triangles of `patch` leave of `bounds` (see
/// [`tile_patch`]).
fn fill(patch: &mut SurfaceMesh, bounds: [f64; 4]) {
    use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};
    let [w, s, e, n] = bounds;
    let tile_area = (e - w) * (n - s);
    let covered: f64 = patch
        .triangles
        .iter()
        .map(|&t| patch.doubled_area(t) / 2.0)
        .sum();
    if covered >= tile_area * (1.0 - 1e-12) {
        return;
    }
    // The edges of the covered part that are not on the tile's border.
    let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &patch.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let on_border = |p: [f64; 2]| p[0] == w || p[0] == e || p[1] == s || p[1] == n;
    let mut border: Vec<(u32, u32)> = uses
        .into_iter()
        .filter(|&((a, b), count)| {
            let (pa, pb) = (patch.lon_lat_deg[a as usize], patch.lon_lat_deg[b as usize]);
            // On one side of the tile, not across it.
            let along_border = (pa[0] == pb[0] && (pa[0] == w || pa[0] == e))
                || (pa[1] == pb[1] && (pa[1] == s || pa[1] == n));
            count == 1 && !along_border
        })
        .map(|(edge, _)| edge)
        .collect();
    border.sort_unstable();
    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> =
        ConstrainedDelaunayTriangulation::new();
    // CDT vertex → patch vertex.
    let mut vertex_of: HashMap<usize, u32> = HashMap::new();
    let mut insert = |cdt: &mut ConstrainedDelaunayTriangulation<Point2<f64>>,
                      patch: &mut SurfaceMesh,
                      p: [f64; 2],
                      existing: Option<u32>| {
        let handle = cdt.insert(Point2::new(p[0], p[1])).ok()?;
        let id = *vertex_of.entry(handle.index()).or_insert_with(|| {
            existing.unwrap_or_else(|| {
                let up = east_north_up(p[0], p[1])[2];
                patch.push(p, 0.0, up)
            })
        });
        Some((handle, id))
    };
    for v in 0..patch.lon_lat_deg.len() as u32 {
        if on_border(patch.lon_lat_deg[v as usize]) {
            insert(&mut cdt, patch, patch.lon_lat_deg[v as usize], Some(v));
        }
    }
    let mut handles: HashMap<u32, spade::handles::FixedVertexHandle> = HashMap::new();
    for &(a, b) in &border {
        for v in [a, b] {
            if let std::collections::hash_map::Entry::Vacant(slot) = handles.entry(v) {
                if let Some((h, _)) =
                    insert(&mut cdt, patch, patch.lon_lat_deg[v as usize], Some(v))
                {
                    slot.insert(h);
                }
            }
        }
    }
    // A lattice on the ellipsoid wherever the mesh does not reach (the
    // corners among it), so that the fill's flat triangles follow the
    // Earth's curve: a tile of level z is 180/2^z degrees, a fill triangle
    // at most 1/16 of that, whose chord sinks R θ²/8 — 30 km at level 0,
    // a quarter as much each level, within the level's geometric error.
    let covered_triangles = patch.triangles.len();
    let lookup = Coverage::new(patch, covered_triangles, bounds);
    for j in 0..=FILL_LATTICE {
        for i in 0..=FILL_LATTICE {
            let p = [lattice(w, e, i), lattice(s, n, j)];
            if !lookup.covers(patch, p) {
                insert(&mut cdt, patch, p, None);
            }
        }
    }
    for &(a, b) in &border {
        if let (Some(&ha), Some(&hb)) = (handles.get(&a), handles.get(&b)) {
            if ha != hb && cdt.can_add_constraint(ha, hb) {
                cdt.add_constraint(ha, hb);
            }
        }
    }
    let mut fill_triangles = Vec::new();
    for face in cdt.inner_faces() {
        let ids = face
            .vertices()
            .map(|v| vertex_of.get(&v.fix().index()).copied());
        let [Some(a), Some(b), Some(c)] = ids else {
            continue;
        };
        let centroid = [0, 1].map(|k| {
            (patch.lon_lat_deg[a as usize][k]
                + patch.lon_lat_deg[b as usize][k]
                + patch.lon_lat_deg[c as usize][k])
                / 3.0
        });
        if lookup.covers(patch, centroid) {
            continue;
        }
        let mut t = [a, b, c];
        if patch.doubled_area(t) < 0.0 {
            t.swap(1, 2);
        }
        if patch.doubled_area(t) > 0.0 {
            fill_triangles.push(t);
        }
    }
    patch.triangles.extend(fill_triangles);
}

/// Intervals of the fill's lattice along a tile's side.
const FILL_LATTICE: usize = 16;

/// Lattice line `i` of [`FILL_LATTICE`] between `lo` and `hi`, the ends
/// exact (a tile's side is its neighbour's).
fn lattice(lo: f64, hi: f64, i: usize) -> f64 {
    match i {
        0 => lo,
        FILL_LATTICE => hi,
        _ => lo + (hi - lo) * i as f64 / FILL_LATTICE as f64,
    }
}

/// Which of a patch's covered triangles lie in each cell of a grid over the
/// tile, to tell whether a point is covered.
pub struct Coverage {
    bounds: [f64; 4],
    cells: usize,
    lists: Vec<Vec<u32>>,
}

impl Coverage {
    /// The first `count` triangles of `patch` over `bounds`.
    pub fn new(patch: &SurfaceMesh, count: usize, bounds: [f64; 4]) -> Coverage {
        let cells = ((count as f64).sqrt().ceil() as usize).clamp(1, 256);
        let mut lists = vec![Vec::new(); cells * cells];
        let [w, s, e, n] = bounds;
        let cell_of = |v: f64, lo: f64, hi: f64| {
            (((v - lo) / (hi - lo) * cells as f64) as usize).min(cells - 1)
        };
        for (i, t) in patch.triangles[..count].iter().enumerate() {
            let p = t.map(|v| patch.lon_lat_deg[v as usize]);
            let (x0, x1) = (
                p.iter().map(|q| q[0]).fold(f64::INFINITY, f64::min),
                p.iter().map(|q| q[0]).fold(f64::NEG_INFINITY, f64::max),
            );
            let (y0, y1) = (
                p.iter().map(|q| q[1]).fold(f64::INFINITY, f64::min),
                p.iter().map(|q| q[1]).fold(f64::NEG_INFINITY, f64::max),
            );
            for cy in cell_of(y0, s, n)..=cell_of(y1, s, n) {
                for cx in cell_of(x0, w, e)..=cell_of(x1, w, e) {
                    lists[cy * cells + cx].push(i as u32);
                }
            }
        }
        Coverage {
            bounds,
            cells,
            lists,
        }
    }

    /// Whether `p` (degrees) lies in one of the triangles.
    pub fn covers(&self, patch: &SurfaceMesh, p: [f64; 2]) -> bool {
        let [w, s, e, n] = self.bounds;
        if !(w..=e).contains(&p[0]) || !(s..=n).contains(&p[1]) {
            return false;
        }
        let cell = |v: f64, lo: f64, hi: f64| {
            (((v - lo) / (hi - lo) * self.cells as f64) as usize).min(self.cells - 1)
        };
        self.lists[cell(p[1], s, n) * self.cells + cell(p[0], w, e)]
            .iter()
            .any(|&i| {
                let [a, b, c] = patch.triangles[i as usize].map(|v| patch.lon_lat_deg[v as usize]);
                let side = |u: [f64; 2], v: [f64; 2]| {
                    (v[0] - u[0]) * (p[1] - u[1]) - (p[0] - u[0]) * (v[1] - u[1])
                };
                side(a, b) >= 0.0 && side(b, c) >= 0.0 && side(c, a) >= 0.0
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles over the unit square at heights 0, 10, 20, 30.
    fn square() -> SurfaceMesh {
        SurfaceMesh {
            lon_lat_deg: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
            height_m: vec![0.0, 10.0, 20.0, 30.0],
            normal: vec![[0.0, 0.0, 1.0]; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    #[test]
    fn neighbouring_tiles_meet_exactly() {
        let mesh = square();
        let all = [0, 1];
        // Four tiles meeting at (0.3, 0.6), all inside the square.
        let tiles = [
            [0.0, 0.0, 0.3, 0.6],
            [0.3, 0.0, 1.0, 0.6],
            [0.0, 0.6, 0.3, 1.0],
            [0.3, 0.6, 1.0, 1.0],
        ];
        let patches: Vec<SurfaceMesh> = tiles
            .iter()
            .map(|&b| tile_patch(&mesh, &all, b).0)
            .collect();
        // Every point on a tile line is in every tile that has that line, with the same height.
        let on_line = |p: &SurfaceMesh, line: &dyn Fn([f64; 2]) -> bool| {
            let mut v: Vec<(u64, u64, u64)> = (0..p.lon_lat_deg.len())
                .filter(|&i| line(p.lon_lat_deg[i]))
                .map(|i| {
                    (
                        p.lon_lat_deg[i][0].to_bits(),
                        p.lon_lat_deg[i][1].to_bits(),
                        p.height_m[i].to_bits(),
                    )
                })
                .collect();
            v.sort_unstable();
            v
        };
        let meridian = |q: [f64; 2]| q[0] == 0.3 && q[1] <= 0.6;
        assert_eq!(
            on_line(&patches[0], &meridian),
            on_line(&patches[1], &meridian)
        );
        let parallel = |q: [f64; 2]| q[1] == 0.6;
        let mut lower = on_line(&patches[0], &parallel);
        lower.extend(on_line(&patches[1], &parallel));
        lower.sort_unstable();
        lower.dedup();
        let mut upper = on_line(&patches[2], &parallel);
        upper.extend(on_line(&patches[3], &parallel));
        upper.sort_unstable();
        upper.dedup();
        assert_eq!(lower, upper);
        let corner = patches[0]
            .lon_lat_deg
            .iter()
            .position(|&q| q == [0.3, 0.6])
            .expect("the tile corner is a vertex");
        let h = patches[0].height_m[corner];
        // (0.3, 0.6) lies in triangle 0-2-3, the plane h = 30 y − 10 x.
        assert!((h - (30.0 * 0.6 - 10.0 * 0.3)).abs() < 1e-9, "{h}");
        // The tiles cover the square: areas add up, nothing filled.
        for (p, b) in patches.iter().zip(tiles) {
            let area: f64 = p.triangles.iter().map(|&t| p.doubled_area(t) / 2.0).sum();
            assert!((area - (b[2] - b[0]) * (b[3] - b[1])).abs() < 1e-12);
        }
    }

    #[test]
    fn a_tile_larger_than_the_mesh_is_filled_down_to_the_ellipsoid() {
        let mesh = square();
        let bounds = [-1.0, -1.0, 3.0, 2.0];
        let (patch, covered) = tile_patch(&mesh, &[0, 1], bounds);
        assert_eq!(covered, 2);
        let area: f64 = patch
            .triangles
            .iter()
            .map(|&t| patch.doubled_area(t) / 2.0)
            .sum();
        assert!((area - 12.0).abs() < 1e-9, "{area}");
        // The fill's own vertices are a lattice on the ellipsoid, corners
        // included, none of it under the mesh.
        assert!(
            patch.lon_lat_deg.len() > 4 + 200,
            "{}",
            patch.lon_lat_deg.len()
        );
        for i in 4..patch.lon_lat_deg.len() {
            assert_eq!(patch.height_m[i], 0.0);
            let [x, y] = patch.lon_lat_deg[i];
            assert!(!((0.0..=1.0).contains(&x) && (0.0..=1.0).contains(&y)));
        }
        assert!(patch.lon_lat_deg.contains(&[3.0, 2.0]));
        assert!(patch.triangles.iter().all(|&t| patch.doubled_area(t) > 0.0));
        // A tile the mesh does not reach: the lattice's two triangles a cell.
        let (empty, covered) = tile_patch(&mesh, &[0, 1], [5.0, 5.0, 6.0, 6.0]);
        let cells = FILL_LATTICE * FILL_LATTICE;
        assert_eq!((covered, empty.triangles.len()), (0, 2 * cells));
    }
}
