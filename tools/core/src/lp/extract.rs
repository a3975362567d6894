//! The view-independent mesh: every triangle of the bisection hierarchy is
//! split while the error at its hypotenuse midpoint exceeds a tolerance.
//!
//! The traversal (starting triangles, child order, vertex numbering by
//! first use) follows @mapbox/martini's `getMesh`, so for the same errors the
//! vertex and triangle arrays are the same — the conformance tests compare
//! their digests.

use super::Hierarchy;

/// An indexed triangle mesh on grid vertices.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GridMesh {
    /// Vertex (column, row) pairs, numbered by first use.
    pub vertices: Vec<[u16; 2]>,
    /// Counter-clockwise in (column, row) order as martini emits them.
    pub triangles: Vec<[u32; 3]>,
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
    super::hierarchy::visit_bottom_up(side, |d| {
        let m = mask[d.vertex];
        let corners = d.hypotenuse.iter().chain(d.parents.iter().flatten());
        let own = corners.into_iter().any(|&k| mask[k] != m);
        flag[d.vertex] = own || d.children.iter().flatten().any(|&k| flag[k]);
    });
    flag
}
