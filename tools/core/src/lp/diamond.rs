//! The hierarchy's geometry on a (2^n+1)² grid: which vertex has which
//! scale, the hypotenuse it bisects, the right-angle vertices of its
//! triangles (its parents) and its children.
//!
//! - an *edge* vertex of scale h lies mid-way along an axis-aligned block edge
//!   of length 2h; its triangles' hypotenuse is that edge, and its children
//!   are the four diagonal neighbours at (±h/2, ±h/2) (none when h = 1);
//! - a *centre* vertex of a 2h-block lies mid-way along the block's diagonal,
//!   which runs top-left to bottom-right when the block's index (bx + by) is
//!   even and top-right to bottom-left when odd; its children are the four
//!   edge midpoints at distance h.
//!
//! Coordinates are global columns and rows of the `side`² grid, whatever
//! part of it a caller holds.

/// A vertex as column and row.
pub type Vertex = (usize, usize);

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
pub(super) fn child_offsets(h: usize, edge: bool) -> [(i64, i64); 4] {
    let (q, hi) = ((h / 2) as i64, h as i64);
    if edge {
        [(-q, -q), (q, -q), (-q, q), (q, q)]
    } else {
        [(-hi, 0), (hi, 0), (0, -hi), (0, hi)]
    }
}

/// The children of vertex (c, r) on a `side` grid (see the module docs).
pub fn children(side: usize, c: usize, r: usize) -> impl Iterator<Item = Vertex> {
    let offsets = match vertex_kind(side, c, r) {
        Some((h, edge)) => child_offsets(h, edge),
        None => [(0, 0); 4],
    };
    offsets
        .into_iter()
        .filter(|&offset| offset != (0, 0))
        .filter_map(move |offset| step(side, (c, r), offset))
}

/// `v` moved by `offset`, when that stays on the `side` grid.
#[inline]
pub(super) fn step(side: usize, (c, r): Vertex, (dc, dr): (i64, i64)) -> Option<Vertex> {
    let (nc, nr) = (c as i64 + dc, r as i64 + dr);
    let n = side as i64;
    (nc >= 0 && nr >= 0 && nc < n && nr < n).then_some((nc as usize, nr as usize))
}

/// End points of the hypotenuse that vertex (c, r) of scale h bisects.
pub(super) fn hypotenuse((c, r): Vertex, h: usize, edge: bool) -> (Vertex, Vertex) {
    if edge {
        if (r / h).is_multiple_of(2) {
            ((c - h, r), (c + h, r))
        } else {
            ((c, r - h), (c, r + h))
        }
    } else if (c / (2 * h) + r / (2 * h)).is_multiple_of(2) {
        ((c - h, r - h), (c + h, r + h))
    } else {
        ((c + h, r - h), (c - h, r + h))
    }
}

/// The right-angle vertices of the (one or two) triangles whose hypotenuse
/// vertex `m` bisects, `a` being one end of that hypotenuse: across the
/// hypotenuse, as far from the vertex as its end points are, so (a − m)
/// rotated by ±90°. `None` where one would fall outside the grid.
pub(super) fn parents(side: usize, m: Vertex, a: Vertex) -> [Option<Vertex>; 2] {
    let (ac, ar) = (a.0 as i64 - m.0 as i64, a.1 as i64 - m.1 as i64);
    [step(side, m, (-ar, ac)), step(side, m, (ar, -ac))]
}

/// Columns of edge vertices on row r: c ≡ h (mod 2h) on rows r ≡ 0, else c ≡ 0.
pub(super) fn edge_columns(r: usize, h: usize) -> (usize, usize) {
    if (r / h).is_multiple_of(2) {
        (h, 2 * h)
    } else {
        (0, 2 * h)
    }
}

/// Columns of centre vertices: c ≡ h (mod 2h).
pub(super) fn centre_columns(_r: usize, h: usize) -> (usize, usize) {
    (h, 2 * h)
}

/// A level's columns on a row: the first and the step.
pub(super) type Columns = fn(usize, usize) -> (usize, usize);

/// The first row and the row step of the edge (`edge`) or centre vertices
/// of scale `h`, and the function giving their first column and column
/// step on a row.
pub(super) fn level_rows(h: usize, edge: bool) -> (usize, usize, Columns) {
    if edge {
        (0, h, edge_columns)
    } else {
        (h, 2 * h, centre_columns)
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
    let index = |(c, r): Vertex| r * side + c;
    let mut h = 1;
    while h < side - 1 {
        for edge in [true, false] {
            let (first_row, row_step, columns) = level_rows(h, edge);
            for r in (first_row..side).step_by(row_step) {
                let (start, step) = columns(r, h);
                for c in (start..side).step_by(step) {
                    let (a, b) = hypotenuse((c, r), h, edge);
                    let mut kids = [None; 4];
                    for (k, v) in kids.iter_mut().zip(children(side, c, r)) {
                        *k = Some(index(v));
                    }
                    f(&Diamond {
                        vertex: index((c, r)),
                        hypotenuse: [index(a), index(b)],
                        parents: parents(side, (c, r), a).map(|p| p.map(index)),
                        children: kids,
                    });
                }
            }
        }
        h *= 2;
    }
}
