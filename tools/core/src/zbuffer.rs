//! The Z-buffer baselines of Szenberg 1997, ch. 3: the grid drawn as
//! geometry by a generic rasterizer, in the seven representations the thesis
//! compares with its floating horizon (table 3.1) — each cell seen as an
//! axis-aligned block of its height.
//!
//! Positions are in the terrain frame relative to [`ZMesh::origin`]
//! (f32 keeps centimetres); colours come from the caller (the drape at the
//! vertex, or a height ramp). Cells with a masked vertex are left out.

/// One of the thesis's representations \[a\]–\[g\].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Representation {
    /// \[a\] one point at the centre of each block's top face.
    Points,
    /// \[b\] the top face of each block.
    TopFaces,
    /// \[c\] the vertical faces between neighbouring blocks (the ones facing
    /// the viewer survive back-face culling).
    FrontFaces,
    /// \[d\] a vertical segment from the base to each block's top.
    Segments,
    /// \[e\] the blocks themselves, six faces each.
    Blocks,
    /// \[f\] the tops triangulated by their diagonals, one colour a triangle.
    FlatTriangles,
    /// \[g\] the same triangles, colours interpolated between vertices.
    SmoothTriangles,
}

impl Representation {
    /// All seven, in the thesis's order.
    pub const ALL: [Representation; 7] = [
        Representation::Points,
        Representation::TopFaces,
        Representation::FrontFaces,
        Representation::Segments,
        Representation::Blocks,
        Representation::FlatTriangles,
        Representation::SmoothTriangles,
    ];

    /// The thesis's letter, `a` to `g`.
    pub fn letter(self) -> char {
        (b'a' + Self::ALL.iter().position(|&r| r == self).unwrap_or(0) as u8) as char
    }

    /// The representation of a letter `a` to `g`.
    pub fn from_letter(letter: char) -> Option<Representation> {
        let k = (letter as u32).checked_sub('a' as u32)? as usize;
        Self::ALL.get(k).copied()
    }

    /// What the rasterizer draws.
    pub fn primitive(self) -> Primitive {
        match self {
            Representation::Points => Primitive::Points,
            Representation::Segments => Primitive::Lines,
            _ => Primitive::Triangles,
        }
    }
}

/// The rasterizer's primitive for a representation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Primitive {
    Points,
    Lines,
    Triangles,
}

/// Geometry of one representation.
#[derive(Debug, Clone, PartialEq)]
pub struct ZMesh {
    pub representation: Representation,
    /// Terrain-frame point the positions are relative to, metres.
    pub origin: [f64; 3],
    /// Vertices: one per point, two per segment, three per triangle.
    pub positions: Vec<[f32; 3]>,
    pub colours: Vec<[u8; 4]>,
}

impl ZMesh {
    /// Points, segments or triangles drawn.
    pub fn primitives(&self) -> usize {
        self.positions.len()
            / match self.representation.primitive() {
                Primitive::Points => 1,
                Primitive::Lines => 2,
                Primitive::Triangles => 3,
            }
    }
}

/// Most grid vertices a representation is built for (2049²): the blocks of
/// a larger grid hold more than a billion vertices.
pub const MAX_VERTICES: usize = 2049 * 2049;

/// Build `representation` of the `side`² grid of `heights` (metres,
/// row-major, row 0 north) with `cell`-metre spacing; `colour(i)` is the
/// colour of vertex `i`. `None` when the grid is larger than
/// [`MAX_VERTICES`].
pub fn build(
    representation: Representation,
    heights: &[f32],
    mask: &[u8],
    side: usize,
    cell: f64,
    colour: &dyn Fn(usize) -> [u8; 4],
) -> Option<ZMesh> {
    if side * side > MAX_VERTICES {
        return None;
    }
    let extent = (side - 1) as f64 * cell;
    let base = heights
        .iter()
        .zip(mask)
        .filter(|(_, &m)| m == 1)
        .map(|(&h, _)| h)
        .fold(f32::INFINITY, f32::min);
    let base = if base.is_finite() { base as f64 } else { 0.0 };
    let origin = [extent / 2.0, extent / 2.0, base];
    let mut mesh = ZMesh {
        representation,
        origin,
        positions: Vec::new(),
        colours: Vec::new(),
    };
    // Terrain (x, y, z) relative to the origin.
    let at = |x: f64, y: f64, z: f64| {
        [
            (x - origin[0]) as f32,
            (y - origin[1]) as f32,
            (z - origin[2]) as f32,
        ]
    };
    let x_of = |c: usize| c as f64 * cell;
    let y_of = |r: usize| (side - 1 - r) as f64 * cell;
    let z_of = |i: usize| heights[i] as f64;
    let half = cell / 2.0;
    let push = |mesh: &mut ZMesh, points: &[[f32; 3]], colours: &[[u8; 4]]| {
        mesh.positions.extend_from_slice(points);
        mesh.colours.extend_from_slice(colours);
    };
    // A quad as two counter-clockwise triangles (seen from its front).
    let quad = |q: [[f32; 3]; 4]| [q[0], q[1], q[2], q[0], q[2], q[3]];
    for r in 0..side {
        for c in 0..side {
            let i = r * side + c;
            if mask[i] == 0 {
                continue;
            }
            let (x, y, z, k) = (x_of(c), y_of(r), z_of(i), colour(i));
            // The block of vertex i spans half a cell around it.
            let (x0, x1, y0, y1) = (x - half, x + half, y - half, y + half);
            let top = quad([at(x0, y0, z), at(x1, y0, z), at(x1, y1, z), at(x0, y1, z)]);
            match representation {
                Representation::Points => push(&mut mesh, &[at(x, y, z)], &[k]),
                Representation::Segments => {
                    push(&mut mesh, &[at(x, y, base), at(x, y, z)], &[k; 2]);
                }
                Representation::TopFaces => push(&mut mesh, &top, &[k; 6]),
                Representation::FrontFaces | Representation::Blocks => {
                    let full = representation == Representation::Blocks;
                    if full {
                        push(&mut mesh, &top, &[k; 6]);
                        let bottom = quad([
                            at(x0, y1, base),
                            at(x1, y1, base),
                            at(x1, y0, base),
                            at(x0, y0, base),
                        ]);
                        push(&mut mesh, &bottom, &[k; 6]);
                    }
                    // Side faces: down to the base for blocks, down to the
                    // lower neighbour's top otherwise (the visible steps).
                    let sides = [
                        (
                            c + 1 < side,
                            r * side + c + 1,
                            [at(x1, y0, 0.0), at(x1, y1, 0.0)],
                        ),
                        (
                            c > 0,
                            (r * side + c).wrapping_sub(1),
                            [at(x0, y1, 0.0), at(x0, y0, 0.0)],
                        ),
                        (
                            r > 0,
                            i.wrapping_sub(side),
                            [at(x1, y1, 0.0), at(x0, y1, 0.0)],
                        ),
                        (r + 1 < side, i + side, [at(x0, y0, 0.0), at(x1, y0, 0.0)]),
                    ];
                    for (exists, neighbour, [a, b]) in sides {
                        let floor = if full {
                            base
                        } else if exists && mask[neighbour] == 1 {
                            z_of(neighbour)
                        } else {
                            base
                        };
                        if floor >= z {
                            continue;
                        }
                        let lift = |p: [f32; 3], h: f64| [p[0], p[1], (h - origin[2]) as f32];
                        push(
                            &mut mesh,
                            &quad([lift(a, floor), lift(b, floor), lift(b, z), lift(a, z)]),
                            &[k; 6],
                        );
                    }
                }
                Representation::FlatTriangles | Representation::SmoothTriangles => {
                    // Cell (c, r)–(c+1, r+1) split by its diagonal (thesis fig. 3.1).
                    if c + 1 == side || r + 1 == side {
                        continue;
                    }
                    let corners = [i, i + 1, i + side + 1, i + side];
                    if corners.iter().any(|&v| mask[v] == 0) {
                        continue;
                    }
                    let p = |v: usize| at(x_of(v % side), y_of(v / side), z_of(v));
                    let [nw, ne, se, sw] = corners;
                    for tri in [[sw, se, ne], [sw, ne, nw]] {
                        let colours = if representation == Representation::FlatTriangles {
                            [colour(tri[0]); 3]
                        } else {
                            tri.map(colour)
                        };
                        push(&mut mesh, &tri.map(p), &colours);
                    }
                }
            }
        }
    }
    Some(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testdata;

    #[test]
    fn letters_name_the_thesis_representations() {
        for (k, r) in Representation::ALL.iter().enumerate() {
            assert_eq!(
                Representation::from_letter((b'a' + k as u8) as char),
                Some(*r)
            );
        }
        assert_eq!(Representation::Blocks.letter(), 'e');
        assert_eq!(Representation::from_letter('h'), None);
    }

    #[test]
    fn representations_of_a_real_dem_have_the_expected_sizes() {
        let dem = testdata::dem("srtm_ref_257.f32");
        let (side, n) = (dem.side, dem.side * dem.side);
        let mask = vec![1u8; n];
        let grey = |_: usize| [128, 128, 128, 255];
        let build = |r| build(r, &dem.heights, &mask, side, dem.cell_size_m, &grey).unwrap();
        assert_eq!(build(Representation::Points).primitives(), n);
        assert_eq!(build(Representation::Segments).primitives(), n);
        assert_eq!(build(Representation::TopFaces).primitives(), 2 * n);
        let cells = (side - 1) * (side - 1);
        assert_eq!(build(Representation::FlatTriangles).primitives(), 2 * cells);
        assert_eq!(
            build(Representation::SmoothTriangles).primitives(),
            2 * cells
        );
        // Blocks: top and bottom, and sides down to the lowest point of the grid.
        let blocks = build(Representation::Blocks).primitives();
        assert!(blocks > 4 * n && blocks <= 12 * n, "{blocks}");
        // Front faces only where a block stands above its neighbour.
        let front = build(Representation::FrontFaces).primitives();
        assert!(front > 0 && front < blocks, "{front}");
        // Heights are kept to the centimetre relative to the origin.
        let m = build(Representation::Points);
        let top = m.positions.iter().map(|p| p[2]).fold(f32::MIN, f32::max) as f64 + m.origin[2];
        let highest = dem.heights.iter().copied().fold(f32::MIN, f32::max) as f64;
        assert!((top - highest).abs() < 0.01);
    }
}
