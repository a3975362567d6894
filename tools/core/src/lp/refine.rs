//! View-dependent refinement into one triangle strip (LP seed §3.4–3.7:
//! `RefinaMalha`, `RefinaSubMalha`, `AnexaStrip`, `RefinaSubMalhaVisivel`,
//! `RefinaSubMalhaMorph`).
//!
//! A vertex is *active* when its projected error exceeds the tolerance τ,
//! ρ = λ·δ / (|o − p| − r) > τ (seed eq. 2), or when the eye is inside its
//! sphere. Nesting makes the active set closed under parents, so the mesh
//! has no T-junctions for any camera. Refinement descends only into active
//! vertices; with culling it also stops at vertices whose sphere lies
//! wholly outside a frustum plane (outside regions keep coarse triangles,
//! nothing inside is lost). With geomorphing, a band [τmin, τmax] blends
//! each vertex's height between the edge it replaces and its own (seed eqs.
//! 3–8), cascading through the heights of already-morphed ancestors.

use super::hierarchy::Hierarchy;
use super::vertices::{levels, terrain_position, Layout};

/// What to refine for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineParams {
    /// Eye position in the terrain frame, metres.
    pub eye: [f64; 3],
    /// Pixels per radian, λ = viewport width / horizontal field of view.
    pub lambda: f64,
    /// Screen-space tolerance τ in pixels (τmin when morphing).
    pub tau_px: f64,
    /// τmax of the geomorphing band; `None` for no morphing.
    pub morph_tau_max_px: Option<f64>,
    /// Frustum planes (inward unit normals, terrain frame); `None` to refine
    /// everywhere.
    pub planes: Option<[[f64; 4]; 6]>,
}

impl RefineParams {
    /// Parameters for a camera: its eye, λ and (when `cull`) its frustum.
    pub fn for_camera(
        camera: &crate::camera::Camera,
        tau_px: f64,
        morph_tau_max_px: Option<f64>,
        cull: bool,
    ) -> Self {
        RefineParams {
            eye: camera.position.to_array(),
            lambda: camera.lambda(),
            tau_px,
            morph_tau_max_px,
            planes: cull.then(|| camera.frustum_planes()),
        }
    }
}

/// A triangle strip over grid vertices (indices as the [`VertexSource`]
/// refined names them: row-major for a grid's arrays). Consecutive
/// triples are triangles of alternating orientation; triples with a
/// repeated vertex are degenerate and draw nothing.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Strip {
    pub indices: Vec<u32>,
    /// With geomorphing: the height to draw for each strip entry, metres.
    pub morphed_z: Vec<f32>,
}

impl Strip {
    /// The non-degenerate triangles, all wound the same way as the first.
    pub fn triangles(&self) -> impl Iterator<Item = [u32; 3]> + '_ {
        self.triangle_entries().map(|e| e.map(|k| self.indices[k]))
    }

    /// The non-degenerate triangles as positions in the strip (so that
    /// per-entry data such as [`Strip::morphed_z`] can be read), wound as
    /// [`Strip::triangles`].
    pub fn triangle_entries(&self) -> impl Iterator<Item = [usize; 3]> + '_ {
        self.indices.windows(3).enumerate().filter_map(|(k, w)| {
            let (t, e) = if k % 2 == 0 {
                ([w[0], w[1], w[2]], [k, k + 1, k + 2])
            } else {
                ([w[1], w[0], w[2]], [k + 1, k, k + 2])
            };
            (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]).then_some(e)
        })
    }
}

const ALL_INSIDE: u8 = 0b11_1111;

/// Where a refinement reads its vertices: a grid's arrays
/// ([`GridArrays`]), or the part of a pyramid's hierarchy whose tiles are
/// resident (`pyramid::paging`).
pub trait VertexSource {
    /// Vertices a side of the grid, 2^n + 1.
    fn side(&self) -> usize;
    /// Distance between neighbouring vertices, metres.
    fn cell_size_m(&self) -> f64;
    /// Vertex (c, r)'s height (metres) and `[error, radius]`, or `None`
    /// when the source does not hold it: such a vertex is never active.
    /// The vertices held must be closed under parents (every parent of a
    /// held vertex is held, the four corners always) for the mesh to stay
    /// crack-free.
    fn vertex(&self, c: usize, r: usize) -> Option<(f32, [f32; 2])>;
    /// The strip index that names vertex (c, r).
    fn index(&self, c: usize, r: usize) -> u32;
}

/// A whole grid's per-vertex arrays in one [`Layout`], errors and radii
/// beside heights.
#[derive(Debug, Clone, Copy)]
pub struct GridArrays<'a> {
    pub layout: Layout,
    pub side: usize,
    pub cell_size_m: f64,
    pub error_radius: &'a [[f32; 2]],
    pub heights: &'a [f32],
}

impl<'a> GridArrays<'a> {
    /// A row-major hierarchy and its heights.
    pub fn new(h: &'a Hierarchy, heights: &'a [f32]) -> Self {
        GridArrays {
            layout: Layout::RowMajor,
            side: h.side,
            cell_size_m: h.cell_size_m,
            error_radius: &h.error_radius,
            heights,
        }
    }
}

impl VertexSource for GridArrays<'_> {
    fn side(&self) -> usize {
        self.side
    }

    fn cell_size_m(&self) -> f64 {
        self.cell_size_m
    }

    #[inline]
    fn vertex(&self, c: usize, r: usize) -> Option<(f32, [f32; 2])> {
        let i = self.layout.index(self.side, c, r);
        Some((self.heights[i], self.error_radius[i]))
    }

    #[inline]
    fn index(&self, c: usize, r: usize) -> u32 {
        self.layout.index(self.side, c, r) as u32
    }
}

/// Reusable refinement state: the strip buffers grow to the largest mesh
/// seen and are reused, so a refinement allocates nothing once warm.
#[derive(Debug, Default)]
pub struct Refiner {
    strip: Strip,
    parity: u8,
    /// Whether this refinement records morphed heights.
    morph: bool,
}

/// Everything the recursion reads, bundled to keep its signature short.
struct Ctx<'a, S> {
    source: &'a S,
    side: usize,
    cell: f64,
    eye: [f64; 3],
    /// ν = λ/τ (activation; λ/τmin when morphing).
    nu_max: f64,
    /// λ/τmax when morphing.
    nu_min: Option<f64>,
    planes: Option<[[f64; 4]; 6]>,
}

impl<'a, S: VertexSource> Ctx<'a, S> {
    fn new(source: &'a S, p: &RefineParams) -> Self {
        Ctx {
            source,
            side: source.side(),
            cell: source.cell_size_m(),
            eye: p.eye,
            nu_max: p.lambda / p.tau_px,
            nu_min: p.morph_tau_max_px.map(|t| p.lambda / t),
            planes: p.planes,
        }
    }

    /// Height of vertex (c, r) as stored: a corner, or an end of the
    /// hypotenuse of a triangle reached (held, as a parent of one).
    fn z(&self, (c, r): (i64, i64)) -> f32 {
        self.source
            .vertex(c as usize, r as usize)
            .map_or(0.0, |v| v.0)
    }

    /// The strip index of vertex (c, r).
    fn index(&self, (c, r): (i64, i64)) -> u32 {
        self.source.index(c as usize, r as usize)
    }

    /// Is vertex `i` in the mesh? `None` when the source does not hold it,
    /// when it is inactive (ρ ≤ τ, eye outside its sphere) or culled (its sphere wholly outside a frustum
    /// plane not yet known to contain the branch, per `inside`); else the
    /// planes known to contain its subtree and the height to draw it at,
    /// morphed towards `za` (the height it replaces) within the band.
    #[inline]
    fn vertex(&self, i: (i64, i64), mut inside: u8, za: f32) -> Option<(u8, f32)> {
        let (zi, [delta, radius]) = self.source.vertex(i.0 as usize, i.1 as usize)?;
        let p = terrain_position(i.0 as usize, i.1 as usize, self.side, self.cell, zi as f64);
        let (delta, radius) = (delta as f64, radius as f64);
        let d2 = (p[0] - self.eye[0]).powi(2)
            + (p[1] - self.eye[1]).powi(2)
            + (p[2] - self.eye[2]).powi(2);
        let d_max = self.nu_max * delta + radius;
        if d2 >= d_max * d_max {
            return None; // inactive (ρ ≤ τ, eye outside the sphere)
        }
        if inside != ALL_INSIDE {
            if let Some(planes) = &self.planes {
                for (k, plane) in planes.iter().enumerate() {
                    if inside & (1 << k) != 0 {
                        continue;
                    }
                    let s = plane[0] * p[0] + plane[1] * p[1] + plane[2] * p[2] + plane[3];
                    if s < -radius {
                        return None; // sphere wholly outside: keep the coarse triangle
                    }
                    if s > radius {
                        inside |= 1 << k;
                    }
                }
            }
        }
        // Seed eq. 8: t from squared distances across [d_min, d_max].
        let z = match self.nu_min {
            None => zi,
            Some(nu_min) => {
                let d_min = nu_min * delta + radius;
                let t = if d2 <= d_min * d_min {
                    1.0
                } else {
                    (d_max * d_max - d2) / (d_max * d_max - d_min * d_min)
                };
                (t * zi as f64 + (1.0 - t) * za as f64) as f32
            }
        };
        Some((inside, z))
    }
}

impl Refiner {
    pub fn new() -> Self {
        Self::default()
    }

    /// Refine `h` (with its `heights`) for `p` and return the strip.
    ///
    /// ```
    /// use relevo_core::camera::Camera;
    /// use relevo_core::lp::refine::{RefineParams, Refiner};
    /// use relevo_core::lp::{ErrorMetric, Hierarchy};
    /// let side = 65;
    /// let heights: Vec<f32> = (0..side * side)
    ///     .map(|i| (((i % side) as f32) * 0.3).sin() * 40.0 + (i / side) as f32)
    ///     .collect();
    /// let h = Hierarchy::compute(&heights, side, 30.0, ErrorMetric::Bound);
    /// let camera = Camera {
    ///     position: glam::DVec3::new(960.0, -200.0, 300.0),
    ///     heading_deg: 0.0,
    ///     pitch_deg: -20.0,
    ///     incl_px: 360.0,
    ///     fov_x_deg: 60.0,
    ///     width: 1280,
    ///     height: 720,
    ///     near_m: 1.0,
    ///     far_m: 10_000.0,
    /// };
    /// let mut refiner = Refiner::new();
    /// // τ = 1 px, no geomorphing, culled to the frustum.
    /// let fine = refiner.refine(&h, &heights, &RefineParams::for_camera(&camera, 1.0, None, true));
    /// let fine_triangles = fine.triangles().count();
    /// let coarse = refiner.refine(&h, &heights, &RefineParams::for_camera(&camera, 8.0, None, true));
    /// assert!(coarse.triangles().count() < fine_triangles);
    /// ```
    pub fn refine(&mut self, h: &Hierarchy, heights: &[f32], p: &RefineParams) -> &Strip {
        self.refine_source(&GridArrays::new(h, heights), p)
    }

    /// Refine the vertices `source` holds for `p`; the strip's indices are
    /// the source's.
    pub fn refine_source(&mut self, source: &impl VertexSource, p: &RefineParams) -> &Strip {
        let ctx = Ctx::new(source, p);
        let side = ctx.side;
        let m = (side - 1) as i64;
        let hh = m / 2;
        let z = |c: i64, r: i64| ctx.z((c, r));
        let (sw, se, ne, nw) = ((0, m), (m, m), (m, 0), (0, 0));
        let centre = (hh, hh);
        let inside = if p.planes.is_some() { 0 } else { ALL_INSIDE };
        // The centre replaces the diagonal from the north-west to the south-east corner.
        let za = (z(nw.0, nw.1) + z(se.0, se.1)) / 2.0;
        let n = levels(side);

        self.strip.indices.clear();
        self.strip.morphed_z.clear();
        self.parity = 0;
        self.morph = ctx.nu_min.is_some();
        let idx = |v: (i64, i64)| ctx.index(v);
        self.push(idx(sw), z(sw.0, sw.1));
        self.push(idx(sw), z(sw.0, sw.1));
        let quadrants = [
            ((hh, m), se, sw),
            ((m, hh), ne, se),
            ((hh, 0), nw, ne),
            ((0, hh), sw, nw),
        ];
        for (split, corner, left) in quadrants {
            // (left, corner) are the end points of the split vertex's edge.
            let ends = [left, corner];
            self.submesh(
                &ctx,
                centre,
                split,
                ends,
                n,
                inside,
                [z(left.0, left.1), za, z(corner.0, corner.1)],
            );
            self.append(idx(corner), 1, z(corner.0, corner.1));
        }
        self.strip.indices.remove(0);
        if self.morph {
            self.strip.morphed_z.remove(0);
        }
        &self.strip
    }

    fn push(&mut self, v: u32, z: f32) {
        self.strip.indices.push(v);
        if self.morph {
            self.strip.morphed_z.push(z);
        }
    }

    /// Seed's `AnexaStrip`: add `v` unless it is one of the last two; when
    /// the parity of the turn does not alternate, repeat the second-to-last
    /// vertex so the strip turns the right way.
    fn append(&mut self, v: u32, parity: u8, z: f32) {
        let n = self.strip.indices.len();
        let (before_last, last) = (self.strip.indices[n - 2], self.strip.indices[n - 1]);
        if v != last && v != before_last {
            if parity != self.parity {
                self.parity = parity;
            } else {
                let z_before = if self.morph {
                    self.strip.morphed_z[n - 2]
                } else {
                    0.0
                };
                self.push(before_last, z_before);
            }
            self.push(v, z);
        }
    }

    /// Seed's `RefinaSubMalha` (with culling and morphing): the triangle
    /// with right-angle vertex `i` whose hypotenuse `j` bisects, at level
    /// `l`. `ends` are the hypotenuse's end points, the one the strip comes
    /// from first; `[zl, za, zr]` are the drawn heights of those end points
    /// around `za`, the height `i` falls back to when morphing.
    #[allow(clippy::too_many_arguments)]
    fn submesh<S: VertexSource>(
        &mut self,
        ctx: &Ctx<S>,
        i: (i64, i64),
        j: (i64, i64),
        [left, right]: [(i64, i64); 2],
        l: u32,
        inside: u8,
        [zl, za, zr]: [f32; 3],
    ) {
        if l == 0 {
            return;
        }
        let Some((inside, z)) = ctx.vertex(i, inside, za) else {
            return;
        };
        let vi = ctx.index(i);
        let zm = (zl + zr) / 2.0;
        if l > 1 {
            // Splitting at j makes two triangles with right angle j: the
            // first on the left end's side, then the right end's.
            let child_left = ((left.0 + i.0) / 2, (left.1 + i.1) / 2);
            let child_right = ((i.0 + right.0) / 2, (i.1 + right.1) / 2);
            self.submesh(ctx, j, child_left, [left, i], l - 1, inside, [zl, zm, z]);
            self.append(vi, (l % 2) as u8, z);
            self.submesh(ctx, j, child_right, [i, right], l - 1, inside, [z, zm, zr]);
        } else {
            self.append(vi, (l % 2) as u8, z);
        }
    }
}

/// Height of the refined mesh of `source` for `p` at terrain-frame point
/// (`x_m`, `y_m`), metres: the same activation, culling and geomorphing as
/// [`Refiner::refine_source`], followed down the one branch of the bintree that
/// holds the point (O(levels), no mesh built), then interpolated linearly
/// in the leaf triangle. What the viewer stands objects on, so that they
/// stand on the surface drawn rather than on the full-resolution grid.
/// `None` outside the grid.
pub fn mesh_height(
    source: &impl VertexSource,
    p: &RefineParams,
    x_m: f64,
    y_m: f64,
) -> Option<f64> {
    let ctx = Ctx::new(source, p);
    let side = ctx.side;
    let m = (side - 1) as i64;
    // The point in grid units (column, row; row 0 north).
    let q = [x_m / ctx.cell, m as f64 - y_m / ctx.cell];
    if !(0.0..=m as f64).contains(&q[0]) || !(0.0..=m as f64).contains(&q[1]) {
        return None;
    }
    let hh = m / 2;
    let (sw, se, ne, nw) = ((0, m), (m, m), (m, 0), (0, 0));
    let centre = (hh, hh);
    let inside = if p.planes.is_some() { 0 } else { ALL_INSIDE };
    let za = (ctx.z(nw) + ctx.z(se)) / 2.0;
    // The quadrant (triangle with its right angle at the centre and a side
    // of the square as hypotenuse) holding the point, as in `refine_source`.
    let (dc, dr) = (q[0] - hh as f64, q[1] - hh as f64);
    let (split, left, corner) = if dr.abs() >= dc.abs() {
        if dr >= 0.0 {
            ((hh, m), sw, se)
        } else {
            ((hh, 0), nw, ne)
        }
    } else if dc >= 0.0 {
        ((m, hh), ne, se)
    } else {
        ((0, hh), sw, nw)
    };
    let walked = locate(
        &ctx,
        q,
        centre,
        split,
        [left, corner],
        levels(side),
        inside,
        [ctx.z(left), za, ctx.z(corner)],
    );
    Some(walked.unwrap_or_else(|| {
        // The centre is not in the mesh: the square's two triangles split
        // along the north-west to south-east diagonal.
        let apex = if q[0] - q[1] >= 0.0 { ne } else { sw };
        interpolate(q, [nw, se, apex], [ctx.z(nw), ctx.z(se), ctx.z(apex)])
    }) as f64)
}

/// [`Refiner::submesh`]'s walk down the branch holding `q`: `None` when `i`
/// is not in the mesh (the caller's triangle is the leaf); else the height
/// at `q` in the leaf below triangle (left, right, i).
#[allow(clippy::too_many_arguments)]
fn locate<S: VertexSource>(
    ctx: &Ctx<S>,
    q: [f64; 2],
    i: (i64, i64),
    j: (i64, i64),
    [left, right]: [(i64, i64); 2],
    l: u32,
    inside: u8,
    [zl, za, zr]: [f32; 3],
) -> Option<f32> {
    if l == 0 {
        return None;
    }
    let (inside, z) = ctx.vertex(i, inside, za)?;
    if l > 1 {
        // The segment from i to j (the hypotenuse's midpoint) halves the
        // triangle: the point is on the left end's side or the right's.
        let cross = |a: (i64, i64)| {
            (j.0 - i.0) as f64 * (a.1 - i.1) as f64 - (j.1 - i.1) as f64 * (a.0 - i.0) as f64
        };
        let side_of_q =
            (j.0 - i.0) as f64 * (q[1] - i.1 as f64) - (j.1 - i.1) as f64 * (q[0] - i.0 as f64);
        let zm = (zl + zr) / 2.0;
        let below = if side_of_q * cross(left) >= 0.0 {
            let child = ((left.0 + i.0) / 2, (left.1 + i.1) / 2);
            locate(ctx, q, j, child, [left, i], l - 1, inside, [zl, zm, z])
        } else {
            let child = ((i.0 + right.0) / 2, (i.1 + right.1) / 2);
            locate(ctx, q, j, child, [i, right], l - 1, inside, [z, zm, zr])
        };
        if below.is_some() {
            return below;
        }
    }
    Some(interpolate(q, [left, right, i], [zl, zr, z]))
}

/// Linear interpolation at `q` of heights `z` given at the triangle's
/// vertices (grid units).
fn interpolate(q: [f64; 2], v: [(i64, i64); 3], z: [f32; 3]) -> f32 {
    let p = v.map(|(c, r)| [c as f64, r as f64]);
    let det = (p[1][1] - p[2][1]) * (p[0][0] - p[2][0]) + (p[2][0] - p[1][0]) * (p[0][1] - p[2][1]);
    let a = ((p[1][1] - p[2][1]) * (q[0] - p[2][0]) + (p[2][0] - p[1][0]) * (q[1] - p[2][1])) / det;
    let b = ((p[2][1] - p[0][1]) * (q[0] - p[2][0]) + (p[0][0] - p[2][0]) * (q[1] - p[2][1])) / det;
    (a * z[0] as f64 + b * z[1] as f64 + (1.0 - a - b) * z[2] as f64) as f32
}

#[cfg(test)]
pub(crate) mod tests {
    //! Properties of the refined mesh on four real DEM crops: crack-free
    //! strips closed under parents for random cameras, τ = 0 keeping every
    //! vertex, culling keeping what is visible, geomorphing continuity.
    use super::*;
    use crate::camera::Camera;
    use crate::lp::terrain_position;
    use crate::lp::visit_bottom_up;
    use crate::lp::ErrorMetric;
    use crate::testdata::{self, Lcg};
    use glam::DVec3;
    use std::collections::HashMap;

    pub(crate) struct Terrain {
        pub(crate) name: &'static str,
        pub(crate) heights: Vec<f32>,
        pub(crate) h: Hierarchy<'static>,
    }

    /// The real DEM crops with their hierarchies.
    pub(crate) fn terrains() -> Vec<Terrain> {
        testdata::dems()
            .into_iter()
            .map(|d| Terrain {
                name: d.name,
                h: Hierarchy::compute(&d.heights, d.side, d.cell_size_m, ErrorMetric::default()),
                heights: d.heights,
            })
            .collect()
    }

    /// Cameras inside, above and beside the terrain, looking anywhere.
    pub(crate) fn cameras(t: &Terrain, count: usize, seed: u64) -> Vec<Camera> {
        let mut rng = Lcg(seed);
        let extent = (t.h.side - 1) as f64 * t.h.cell_size_m;
        let top = t.heights.iter().cloned().fold(f32::MIN, f32::max) as f64;
        (0..count)
            .map(|k| {
                let (x, y) = match k % 3 {
                    0 => (rng.next() * extent, rng.next() * extent), // over the terrain
                    1 => (
                        -0.5 * extent + rng.next() * 0.4 * extent,
                        rng.next() * extent,
                    ), // beside it
                    _ => (rng.next() * extent, 1.1 * extent + rng.next() * extent),
                };
                let z = top + 50.0 + rng.next() * extent * 0.3 * (k % 2) as f64;
                Camera {
                    position: DVec3::new(x, y, z),
                    heading_deg: rng.next() * 360.0,
                    pitch_deg: -89.0 + rng.next() * 120.0,
                    incl_px: 540.0,
                    fov_x_deg: 30.0 + rng.next() * 60.0,
                    width: 1920,
                    height: 1080,
                    near_m: 1.0,
                    far_m: extent * 3.0,
                }
            })
            .collect()
    }

    #[test]
    fn mesh_height_is_the_height_of_the_triangle_drawn_there() {
        let mut refiner = Refiner::new();
        let mut rng = Lcg(5);
        // Points where the coarse mesh is more than 0.5 m off the grid's
        // own surface: standing on the mesh is not standing on the grid.
        let mut off_the_grid = 0;
        for t in terrains() {
            let side = t.h.side;
            let extent = (side - 1) as f64 * t.h.cell_size_m;
            for (k, camera) in cameras(&t, 12, 31).iter().enumerate() {
                let morph = (k % 2 == 0).then_some(6.0);
                let p = RefineParams::for_camera(camera, 2.0, morph, k % 3 != 0);
                let strip = refiner.refine(&t.h, &t.heights, &p).clone();
                let grid = |v: u32| ((v as usize % side) as i64, (v as usize / side) as i64);
                for _ in 0..40 {
                    let (x, y) = (rng.next() * extent, rng.next() * extent);
                    let q = [x / t.h.cell_size_m, (side - 1) as f64 - y / t.h.cell_size_m];
                    // The strip's triangle holding the point, by brute force.
                    let drawn = strip
                        .triangle_entries()
                        .find_map(|e| {
                            let v = e.map(|k| grid(strip.indices[k]));
                            let z = e.map(|k| match morph {
                                Some(_) => strip.morphed_z[k],
                                None => t.heights[strip.indices[k] as usize],
                            });
                            let w = barycentric(q, v)?;
                            Some(w[0] * z[0] as f64 + w[1] * z[1] as f64 + w[2] * z[2] as f64)
                        })
                        .expect("the strip covers the grid");
                    let walked =
                        mesh_height(&GridArrays::new(&t.h, &t.heights), &p, x, y).expect("inside");
                    let fine = RefineParams {
                        tau_px: 1e-3,
                        morph_tau_max_px: None,
                        ..p
                    };
                    let full = mesh_height(&GridArrays::new(&t.h, &t.heights), &fine, x, y)
                        .expect("inside");
                    off_the_grid += usize::from((walked - full).abs() > 0.5);
                    assert!(
                        (walked - drawn).abs() < 1e-3,
                        "{} camera {k} at ({x:.1}, {y:.1}): walked {walked} drawn {drawn}",
                        t.name
                    );
                }
            }
            let p = RefineParams::for_camera(&cameras(&t, 1, 1)[0], 2.0, None, false);
            assert_eq!(
                mesh_height(&GridArrays::new(&t.h, &t.heights), &p, -1.0, 0.0),
                None
            );
        }
        assert!(off_the_grid > 100, "{off_the_grid}");
    }

    /// Barycentric weights of `q` in the triangle `v` (grid units), when it
    /// lies inside (with a small tolerance for points on an edge).
    fn barycentric(q: [f64; 2], v: [(i64, i64); 3]) -> Option<[f64; 3]> {
        let p = v.map(|(c, r)| [c as f64, r as f64]);
        let det =
            (p[1][1] - p[2][1]) * (p[0][0] - p[2][0]) + (p[2][0] - p[1][0]) * (p[0][1] - p[2][1]);
        let a =
            ((p[1][1] - p[2][1]) * (q[0] - p[2][0]) + (p[2][0] - p[1][0]) * (q[1] - p[2][1])) / det;
        let b =
            ((p[2][1] - p[0][1]) * (q[0] - p[2][0]) + (p[0][0] - p[2][0]) * (q[1] - p[2][1])) / det;
        let w = [a, b, 1.0 - a - b];
        w.iter().all(|&w| w >= -1e-9).then_some(w)
    }

    fn parents(side: usize) -> HashMap<usize, Vec<usize>> {
        let mut map = HashMap::new();
        visit_bottom_up(side, |d| {
            map.insert(d.vertex, d.parents.iter().flatten().copied().collect());
        });
        map
    }

    /// Every edge used once lies on the grid border, every other edge twice,
    /// and the triangles' areas add up to the whole grid.
    pub(crate) fn assert_watertight(strip: &Strip, side: usize, what: &str) {
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        let mut area2 = 0i64;
        let xy = |v: u32| ((v as usize % side) as i64, (v as usize / side) as i64);
        let mut orientation = 0i64;
        for t in strip.triangles() {
            let (a, b, c) = (xy(t[0]), xy(t[1]), xy(t[2]));
            let cross = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
            assert!(cross != 0, "{what}: flat triangle");
            if orientation == 0 {
                orientation = cross.signum();
            }
            assert_eq!(
                cross.signum(),
                orientation,
                "{what}: triangles wound both ways"
            );
            area2 += cross.abs();
            for (p, q) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *edges.entry((p.min(q), p.max(q))).or_default() += 1;
            }
        }
        let m = (side - 1) as i64;
        assert_eq!(
            area2,
            2 * m * m,
            "{what}: triangles do not tile the grid exactly"
        );
        for ((p, q), n) in edges {
            let (a, b) = (xy(p), xy(q));
            let on_border =
                (a.0 == b.0 && (a.0 == 0 || a.0 == m)) || (a.1 == b.1 && (a.1 == 0 || a.1 == m));
            match n {
                1 => assert!(on_border, "{what}: open edge {a:?}-{b:?} inside the grid"),
                2 => {}
                _ => panic!("{what}: edge {a:?}-{b:?} used {n} times"),
            }
        }
    }

    #[test]
    fn random_cameras_give_crack_free_meshes_closed_under_parents() {
        let mut refiner = Refiner::new();
        for t in terrains() {
            let side = t.h.side;
            let parents = parents(side);
            for (k, cam) in cameras(&t, 24, 7).iter().enumerate() {
                for (tau, cull) in [(1.0, true), (4.0, false), (0.5, true)] {
                    let p = RefineParams::for_camera(cam, tau, None, cull);
                    let strip = refiner.refine(&t.h, &t.heights, &p).clone();
                    let what = format!("{} camera {k} τ={tau} cull={cull}", t.name);
                    assert_watertight(&strip, side, &what);
                    let active: std::collections::HashSet<usize> =
                        strip.indices.iter().map(|&v| v as usize).collect();
                    for &v in &active {
                        for &parent in parents.get(&v).map(|p| p.as_slice()).unwrap_or(&[]) {
                            assert!(
                                active.contains(&parent),
                                "{what}: vertex {v} active without parent {parent}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn zero_tolerance_keeps_every_vertex_and_culling_keeps_what_is_visible() {
        let mut refiner = Refiner::new();
        for t in terrains().into_iter().take(2) {
            let side = t.h.side;
            let cam = &cameras(&t, 1, 3)[0];
            let all = refiner
                .refine(
                    &t.h,
                    &t.heights,
                    &RefineParams::for_camera(cam, 0.0, None, false),
                )
                .clone();
            let used: std::collections::HashSet<u32> = all.indices.iter().copied().collect();
            assert_eq!(
                used.len(),
                side * side,
                "{}: τ = 0 must keep every vertex",
                t.name
            );

            // With culling, every vertex active without it whose sphere is not
            // wholly outside the frustum stays active; none is added.
            for cam in cameras(&t, 12, 11) {
                let free: std::collections::HashSet<u32> = refiner
                    .refine(
                        &t.h,
                        &t.heights,
                        &RefineParams::for_camera(&cam, 1.0, None, false),
                    )
                    .indices
                    .iter()
                    .copied()
                    .collect();
                let culled: std::collections::HashSet<u32> = refiner
                    .refine(
                        &t.h,
                        &t.heights,
                        &RefineParams::for_camera(&cam, 1.0, None, true),
                    )
                    .indices
                    .iter()
                    .copied()
                    .collect();
                assert!(culled.is_subset(&free));
                let planes = cam.frustum_planes();
                for &v in &free {
                    let (c, r) = (v as usize % side, v as usize / side);
                    let p =
                        terrain_position(c, r, side, t.h.cell_size_m, t.heights[v as usize] as f64);
                    let radius = t.h.radius(v as usize) as f64;
                    let outside = planes
                        .iter()
                        .any(|q| q[0] * p[0] + q[1] * p[1] + q[2] * p[2] + q[3] < -radius);
                    if !outside {
                        assert!(
                            culled.contains(&v),
                            "{}: visible vertex ({c}, {r}) culled",
                            t.name
                        );
                    }
                }
            }
        }
    }

    /// Per drawn vertex: its drawn height, and the height of the edge it
    /// splits (average of its hypotenuse end points as drawn).
    fn drawn(
        strip: &Strip,
        heights: &[f32],
        ends: &HashMap<usize, [usize; 2]>,
    ) -> HashMap<u32, (f64, f64)> {
        let z: HashMap<u32, f64> = if strip.morphed_z.is_empty() {
            strip
                .indices
                .iter()
                .map(|&v| (v, heights[v as usize] as f64))
                .collect()
        } else {
            strip
                .indices
                .iter()
                .copied()
                .zip(strip.morphed_z.iter().map(|&z| z as f64))
                .collect()
        };
        z.iter()
            .map(|(&v, &zv)| {
                let edge = ends
                    .get(&(v as usize))
                    .map_or(zv, |[a, b]| (z[&(*a as u32)] + z[&(*b as u32)]) / 2.0);
                (v, (zv, edge))
            })
            .collect()
    }

    /// The surface jumps when a vertex appears or vanishes away from the
    /// edge it splits, or when a drawn height moves: measure the largest such
    /// change per small camera step, with and without geomorphing.
    #[test]
    fn geomorphing_keeps_the_surface_continuous_as_the_camera_moves() {
        let t = terrains().remove(3); // fuji, 257², 30 m cells
        let side = t.h.side;
        let extent = (side - 1) as f64 * t.h.cell_size_m;
        let mut ends = HashMap::new();
        visit_bottom_up(side, |d| {
            ends.insert(d.vertex, d.hypotenuse);
        });
        let mut refiner = Refiner::new();
        let mut worst = [0.0f64; 2];
        for (k, morph) in [Some(6.0), None].into_iter().enumerate() {
            let mut previous: Option<HashMap<u32, (f64, f64)>> = None;
            for step in 0..80 {
                let cam = Camera {
                    position: DVec3::new(0.2 * extent + step as f64 * 5.0, 0.5 * extent, 4500.0),
                    heading_deg: 80.0,
                    pitch_deg: -25.0,
                    incl_px: 540.0,
                    fov_x_deg: 60.0,
                    width: 1920,
                    height: 1080,
                    near_m: 1.0,
                    far_m: 1e6,
                };
                let strip = refiner.refine(
                    &t.h,
                    &t.heights,
                    &RefineParams::for_camera(&cam, 2.0, morph, false),
                );
                let now = drawn(strip, &t.heights, &ends);
                if let Some(prev) = &previous {
                    for (v, &(z, edge)) in &now {
                        let change = match prev.get(v) {
                            Some(&(z0, _)) => (z - z0).abs(),
                            None => (z - edge).abs(), // appeared
                        };
                        worst[k] = worst[k].max(change);
                    }
                    for (v, &(z0, edge0)) in prev {
                        if !now.contains_key(v) {
                            worst[k] = worst[k].max((z0 - edge0).abs()); // vanished
                        }
                    }
                }
                previous = Some(now);
            }
        }
        eprintln!(
            "largest surface change per 5 m camera step: morphing {:.3} m, without {:.3} m",
            worst[0], worst[1]
        );
        assert!(
            worst[1] > 1.0,
            "the path should cross refinement thresholds"
        );
        assert!(
            worst[0] < worst[1] / 5.0,
            "morphing {} vs popping {}",
            worst[0],
            worst[1]
        );
    }
}
