//! A pyramid as a [`MeshSource`]: the mesh of a region of any size, or of
//! a window of it, extracted through the level-0 tiles without assembling
//! the grid. Errors, heights and the mask are read from the mapped tiles
//! vertex by vertex; each triangle's deviation is measured tile by tile
//! (clipped parts give the whole's distances bit for bit, see
//! [`triangle_deviation`]); the texture comes from the finest level whose
//! drape over the window fits [`MAX_TEXTURE_SIDE`]. The mesh is the single
//! grid's, triangle for triangle, for the same errors.

use super::layout::TileKey;
use super::reader::{Pyramid, TileView};
use crate::geo::TerrainFrame;
use crate::lp::export::{DrapeImage, MeshSource};
use crate::lp::extract::VertexBits;
use crate::lp::metric::triangle_deviation;
use crate::lp::window::Rect;
use crate::Result;
use std::borrow::Cow;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The largest texture side a mesh gets, texels: what glTF viewers load
/// everywhere. A larger window takes its texture from a coarser level.
pub const MAX_TEXTURE_SIDE: usize = 8192;

/// A pyramid read for a mesh: its tiles, and its data mask gathered into
/// one bit a vertex (the walk reads it several times a vertex).
pub struct PyramidMesh<'a> {
    pyramid: &'a Pyramid,
    has_data: VertexBits,
    /// Errors read so far: the walk reads them all over the grid, so the
    /// mapped pages are dropped every [`ERRORS_BETWEEN_RELEASES`] reads.
    errors_read: AtomicUsize,
}

/// Error reads between two releases of the mapped pages.
const ERRORS_BETWEEN_RELEASES: usize = 1 << 16;

impl<'a> PyramidMesh<'a> {
    /// Gather `pyramid`'s mask (one bit a vertex, checked against the
    /// memory budget).
    pub fn new(pyramid: &'a Pyramid) -> Result<Self> {
        let layout = pyramid.layout;
        let side = layout.side;
        crate::memory::check(
            &format!("the {side}×{side} grid's data mask, a bit a vertex"),
            (side * side).div_ceil(8) as u64,
            1,
            "prepare the region with a coarser cell size",
        )?;
        let mut has_data = VertexBits::new(side * side);
        let (t, samples) = (layout.tile_cells, layout.samples());
        for key in layout.tiles(0) {
            let tile = pyramid.tile_held(key);
            for j in 0..samples {
                for i in 0..samples {
                    if tile.mask[j * samples + i] != 0 {
                        has_data.set((key.y * t + j) * side + key.x * t + i);
                    }
                }
            }
            pyramid.release_pages();
        }
        Ok(PyramidMesh {
            pyramid,
            has_data,
            errors_read: AtomicUsize::new(0),
        })
    }

    /// The level-`level` tile holding lattice vertex (`u`, `v`) of that
    /// level, and the vertex's place in it.
    fn sample(&self, level: u32, u: usize, v: usize) -> (TileView<'a>, usize) {
        let layout = self.pyramid.layout;
        let (t, last) = (layout.tile_cells, layout.across(level) - 1);
        let (x, y) = ((u / t).min(last), (v / t).min(last));
        let tile = self.pyramid.tile_held(TileKey { level, x, y });
        (tile, (v - y * t) * layout.samples() + (u - x * t))
    }
}

impl MeshSource for PyramidMesh<'_> {
    fn frame(&self) -> TerrainFrame {
        self.pyramid.frame()
    }

    fn height(&self, c: usize, r: usize) -> f32 {
        let (tile, k) = self.sample(0, c, r);
        tile.heights[k]
    }

    fn error(&self, i: usize) -> f32 {
        if self
            .errors_read
            .fetch_add(1, Ordering::Relaxed)
            .is_multiple_of(ERRORS_BETWEEN_RELEASES)
        {
            self.pyramid.release_pages();
        }
        let side = self.pyramid.layout.side;
        let (tile, k) = self.sample(0, i % side, i / side);
        tile.lp[k][0]
    }

    fn has_data(&self, i: usize) -> bool {
        self.has_data.get(i)
    }

    fn deviation(&self, corners: [(i64, i64); 3], corner_z: [f32; 3]) -> f64 {
        let layout = self.pyramid.layout;
        let (t, samples, last) = (layout.tile_cells, layout.samples(), layout.across(0) - 1);
        let columns = corners.map(|p| p.0 as usize);
        let rows = corners.map(|p| p.1 as usize);
        let lo = |v: [usize; 3]| (v[0].min(v[1]).min(v[2]) / t).min(last);
        let hi = |v: [usize; 3]| (v[0].max(v[1]).max(v[2]) / t).min(last);
        let mut largest = 0.0f64;
        for y in lo(rows)..=hi(rows) {
            for x in lo(columns)..=hi(columns) {
                let tile = self.pyramid.tile_held(TileKey { level: 0, x, y });
                let (tc, tr) = ((x * t) as i64, (y * t) as i64);
                let local = corners.map(|(c, r)| (c - tc, r - tr));
                let clip = [0, 0, samples as i64, samples as i64];
                largest = largest.max(triangle_deviation(
                    tile.heights,
                    samples,
                    local,
                    corner_z,
                    Some(clip),
                ));
            }
        }
        largest
    }

    fn has_drape(&self) -> bool {
        true
    }

    fn drape(&self, rect: Rect) -> Result<Option<DrapeImage<'_>>> {
        let layout = self.pyramid.layout;
        // The finest level whose lattice over the rectangle fits.
        let level = (0..layout.levels())
            .find(|&l| {
                let s = layout.stride(l);
                rect.width.max(rect.height).div_ceil(s) < MAX_TEXTURE_SIDE
            })
            .unwrap_or(layout.levels() - 1);
        let s = layout.stride(level);
        let lattice_last = (layout.side - 1) / s;
        let (u0, v0) = (rect.c0 / s, rect.r0 / s);
        let u1 = (rect.c0 + rect.width - 1).div_ceil(s).min(lattice_last);
        let v1 = (rect.r0 + rect.height - 1).div_ceil(s).min(lattice_last);
        let lattice = Rect {
            c0: u0,
            r0: v0,
            width: u1 - u0 + 1,
            height: v1 - v0 + 1,
        };
        let (rgba, geotransform) = self.pyramid.lattice_drape(level, lattice)?;
        self.pyramid.release_pages();
        Ok(Some(DrapeImage {
            rgba: Cow::Owned(rgba),
            width: lattice.width,
            height: lattice.height,
            geotransform,
        }))
    }

    fn release(&self) {
        self.pyramid.release_pages();
    }
}
