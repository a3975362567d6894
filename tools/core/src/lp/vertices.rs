//! The grid's vertices: where each lies in the terrain frame, how many
//! levels of bisection a grid has, and the layouts (row-major, 64×64 tiles)
//! per-vertex arrays are stored in.

/// Where vertex (c, r) of a `side`-wide grid with `cell`-metre spacing and
/// height `z` lies in the terrain frame.
#[inline]
pub fn terrain_position(c: usize, r: usize, side: usize, cell: f64, z: f64) -> [f64; 3] {
    [c as f64 * cell, (side - 1 - r) as f64 * cell, z]
}

/// Order of per-vertex arrays in memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// Row after row, top row first (the bundle's layout).
    RowMajor,
    /// 64×64-vertex tiles in row-major order, each tile row-major: vertices
    /// near each other on the grid are near each other in memory.
    Tiled,
}

/// Side of a [`Layout::Tiled`] tile, vertices.
pub const TILE: usize = 64;

impl Layout {
    /// Position of vertex (c, r) of a `side`-wide grid in an array of this layout.
    #[inline]
    pub fn index(self, side: usize, c: usize, r: usize) -> usize {
        match self {
            Layout::RowMajor => r * side + c,
            Layout::Tiled => {
                let tiles_per_row = side.div_ceil(TILE);
                ((r / TILE) * tiles_per_row + c / TILE) * TILE * TILE + (r % TILE) * TILE + c % TILE
            }
        }
    }

    /// Array length for a `side`-wide grid.
    pub fn len(self, side: usize) -> usize {
        match self {
            Layout::RowMajor => side * side,
            Layout::Tiled => side.div_ceil(TILE).pow(2) * TILE * TILE,
        }
    }

    /// A row-major array rearranged into this layout (unused slots default).
    pub fn arrange<T: Copy + Default>(self, side: usize, row_major: &[T]) -> Vec<T> {
        let mut out = vec![T::default(); self.len(side)];
        for r in 0..side {
            for c in 0..side {
                out[self.index(side, c, r)] = row_major[r * side + c];
            }
        }
        out
    }
}

/// Number of bisection levels of a `side` = 2^k + 1 grid: 2k.
pub fn levels(side: usize) -> u32 {
    2 * (side - 1).trailing_zeros()
}
