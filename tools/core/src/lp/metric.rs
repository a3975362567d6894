//! How a vertex's own object-space error is measured ([`ErrorMetric`]),
//! and the arithmetic both metrics share: the largest vertical distance of
//! grid points from a triangle's plane, a vertex against its hypotenuse's
//! midpoint, and rounding up to f32 so that a stored bound stays a bound.

use serde::{Deserialize, Serialize};

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

/// Columns `c0..c1` and rows `r0..r1` a deviation is limited to (the part
/// of a triangle one tile holds), in the same coordinates as the corners.
pub type Clip = [i64; 4];

/// Largest vertical distance between the grid points inside triangle
/// `corners` (columns and rows of `heights`, rows `width` long) and the
/// plane through the corners at heights `corner_z`, metres; with `clip`,
/// over the points inside it only (which must lie in `heights`; the corners
/// need not). The legs must be axis-aligned or diagonal, as every triangle
/// of the hierarchy's (so rows cross edges at whole columns).
///
/// Each point's distance is computed from the triangle's own first column
/// on its row whatever the clip, so the clipped parts of a triangle give
/// exactly the distances of the whole: the largest over the parts is the
/// largest over the whole, bit for bit.
pub fn triangle_deviation(
    heights: &[f32],
    width: usize,
    corners: [(i64, i64); 3],
    corner_z: [f32; 3],
    clip: Option<Clip>,
) -> f64 {
    let width = width as i64;
    let [p0, p1, p2] = corners;
    let [z0, z1, z2] = corner_z.map(f64::from);
    // The plane z = z0 + dz_dc·(c − c0) + dz_dr·(r − r0).
    let (e1, e2) = ((p1.0 - p0.0, p1.1 - p0.1), (p2.0 - p0.0, p2.1 - p0.1));
    let (dz1, dz2) = (z1 - z0, z2 - z0);
    let det = (e1.0 * e2.1 - e1.1 * e2.0) as f64;
    let dz_dc = (dz1 * e2.1 as f64 - dz2 * e1.1 as f64) / det;
    let dz_dr = (dz2 * e1.0 as f64 - dz1 * e2.0 as f64) / det;
    let [c_lo, r_lo, c_hi, r_hi] = clip.unwrap_or([i64::MIN, i64::MIN, i64::MAX, i64::MAX]);
    let top = p0.1.min(p1.1).min(p2.1).max(r_lo);
    let bottom = p0.1.max(p1.1).max(p2.1).min(r_hi.saturating_sub(1));
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
        let start = z0 + dz_dr * (r - p0.1) as f64 + dz_dc * (first - p0.0) as f64;
        let (from, to) = (first.max(c_lo), last.min(c_hi.saturating_sub(1)));
        if from > to {
            continue;
        }
        let span = &heights[(r * width + from) as usize..=(r * width + to) as usize];
        largest = largest.max(span_deviation(span, start, dz_dc, (from - first) as f64));
    }
    largest
}

/// Largest |z − (start + slope·(offset + i))| over the heights `span[i]`,
/// in four independent lanes so that the loop vectorises (heights are
/// finite; `offset` is a whole number of columns).
#[inline]
fn span_deviation(span: &[f32], start: f64, slope: f64, offset: f64) -> f64 {
    let mut lanes = [0.0f64; 4];
    let chunks = span.chunks_exact(4);
    let rest = chunks.remainder();
    let mut x = offset;
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

/// Height error of a vertex of height `m` against the midpoint of a
/// hypotenuse from `a` to `b`, as martini and the seed compute it: the
/// average in f64, the difference in f64.
#[inline]
pub(super) fn midpoint_error(a: f32, b: f32, m: f32) -> f64 {
    let average = (a as f64 + b as f64) / 2.0;
    (average - m as f64).abs()
}

/// Smallest f32 not below `v` (v ≥ 0).
#[inline]
pub(super) fn round_up(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) < v {
        f.next_up()
    } else {
        f
    }
}
