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

use super::{levels, terrain_position, Hierarchy, Layout};

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

/// A triangle strip over grid vertices (indices in the layout refined,
/// row-major unless [`Refiner::refine_in`] was given another). Consecutive
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
        self.indices.windows(3).enumerate().filter_map(|(k, w)| {
            let t = if k % 2 == 0 {
                [w[0], w[1], w[2]]
            } else {
                [w[1], w[0], w[2]]
            };
            (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]).then_some(t)
        })
    }
}

const ALL_INSIDE: u8 = 0b11_1111;

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
struct Ctx<'a> {
    error_radius: &'a [[f32; 2]],
    heights: &'a [f32],
    layout: Layout,
    side: usize,
    cell: f64,
    eye: [f64; 3],
    /// ν = λ/τ (activation; λ/τmin when morphing).
    nu_max: f64,
    /// λ/τmax when morphing.
    nu_min: Option<f64>,
    planes: Option<[[f64; 4]; 6]>,
}

impl Refiner {
    pub fn new() -> Self {
        Self::default()
    }

    /// Refine `h` (with its `heights`) for `p` and return the strip.
    pub fn refine(&mut self, h: &Hierarchy, heights: &[f32], p: &RefineParams) -> &Strip {
        self.refine_in(
            Layout::RowMajor,
            h.side,
            h.cell_size_m,
            &h.error_radius,
            heights,
            p,
        )
    }

    /// Refine from per-vertex arrays stored in `layout` (`error_radius` and
    /// `heights` both); the strip's indices are in that layout too.
    pub fn refine_in(
        &mut self,
        layout: Layout,
        side: usize,
        cell_size_m: f64,
        error_radius: &[[f32; 2]],
        heights: &[f32],
        p: &RefineParams,
    ) -> &Strip {
        let ctx = Ctx {
            error_radius,
            heights,
            layout,
            side,
            cell: cell_size_m,
            eye: p.eye,
            nu_max: p.lambda / p.tau_px,
            nu_min: p.morph_tau_max_px.map(|t| p.lambda / t),
            planes: p.planes,
        };
        let m = (side - 1) as i64;
        let hh = m / 2;
        let z = |c: i64, r: i64| heights[layout.index(side, c as usize, r as usize)];
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
        let idx = |v: (i64, i64)| layout.index(side, v.0 as usize, v.1 as usize) as u32;
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
    fn submesh(
        &mut self,
        ctx: &Ctx,
        i: (i64, i64),
        j: (i64, i64),
        [left, right]: [(i64, i64); 2],
        l: u32,
        mut inside: u8,
        [zl, za, zr]: [f32; 3],
    ) {
        if l == 0 {
            return;
        }
        let side = ctx.side;
        let vi = ctx.layout.index(side, i.0 as usize, i.1 as usize);
        let zi = ctx.heights[vi];
        let p = terrain_position(i.0 as usize, i.1 as usize, side, ctx.cell, zi as f64);
        let [delta, radius] = ctx.error_radius[vi];
        let (delta, radius) = (delta as f64, radius as f64);
        let d2 =
            (p[0] - ctx.eye[0]).powi(2) + (p[1] - ctx.eye[1]).powi(2) + (p[2] - ctx.eye[2]).powi(2);
        let d_max = ctx.nu_max * delta + radius;
        if d2 >= d_max * d_max {
            return; // inactive (ρ ≤ τ, eye outside the sphere)
        }
        if inside != ALL_INSIDE {
            if let Some(planes) = &ctx.planes {
                for (k, plane) in planes.iter().enumerate() {
                    if inside & (1 << k) != 0 {
                        continue;
                    }
                    let s = plane[0] * p[0] + plane[1] * p[1] + plane[2] * p[2] + plane[3];
                    if s < -radius {
                        return; // sphere wholly outside: keep the coarse triangle
                    }
                    if s > radius {
                        inside |= 1 << k;
                    }
                }
            }
        }
        // Seed eq. 8: t from squared distances across [d_min, d_max].
        let z = match ctx.nu_min {
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
        let zm = (zl + zr) / 2.0;
        if l > 1 {
            // Splitting at j makes two triangles with right angle j: the
            // first on the left end's side, then the right end's.
            let child_left = ((left.0 + i.0) / 2, (left.1 + i.1) / 2);
            let child_right = ((i.0 + right.0) / 2, (i.1 + right.1) / 2);
            self.submesh(ctx, j, child_left, [left, i], l - 1, inside, [zl, zm, z]);
            self.append(vi as u32, (l % 2) as u8, z);
            self.submesh(ctx, j, child_right, [i, right], l - 1, inside, [z, zm, zr]);
        } else {
            self.append(vi as u32, (l % 2) as u8, z);
        }
    }
}
