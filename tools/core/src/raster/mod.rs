//! In-memory multiband rasters and the algorithms that turn tiles into one
//! clean grid: mosaicking with feathered overlaps, no-data filling, and the
//! decoding of RGB-encoded elevation tiles; 8-bit stretching, PNG encoding
//! and fitting into a frame for what people look at; a drape derived from
//! the terrain.

pub mod compare;
pub mod distance;
pub mod encoding;
pub mod fill;
pub mod fit;
pub mod mosaic;
pub mod png;
pub mod stretch;
pub mod tint;

/// A multiband raster held as `f64`, band-major (all of band 0, then band 1…),
/// rows top to bottom. `NaN` marks no-data: a cell is valid when every band
/// holds a number.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    pub width: usize,
    pub height: usize,
    pub bands: usize,
    pub data: Vec<f64>,
}

impl Raster {
    /// A raster where every cell is no-data.
    pub fn empty(width: usize, height: usize, bands: usize) -> Self {
        Raster {
            width,
            height,
            bands,
            data: vec![f64::NAN; width * height * bands],
        }
    }

    /// Wrap band-major data; `data.len()` must be `width·height·bands`.
    pub fn from_data(width: usize, height: usize, bands: usize, data: Vec<f64>) -> Self {
        assert_eq!(data.len(), width * height * bands, "raster data size");
        Raster {
            width,
            height,
            bands,
            data,
        }
    }

    pub fn cells(&self) -> usize {
        self.width * self.height
    }

    pub fn band(&self, b: usize) -> &[f64] {
        let n = self.cells();
        &self.data[b * n..(b + 1) * n]
    }

    pub fn band_mut(&mut self, b: usize) -> &mut [f64] {
        let n = self.cells();
        &mut self.data[b * n..(b + 1) * n]
    }

    /// Whether cell `i` (row-major index) holds data in every band.
    pub fn is_valid(&self, i: usize) -> bool {
        let n = self.cells();
        (0..self.bands).all(|b| !self.data[b * n + i].is_nan())
    }

    /// One flag per cell, row-major: true where every band holds data.
    pub fn valid_mask(&self) -> Vec<bool> {
        (0..self.cells()).map(|i| self.is_valid(i)).collect()
    }

    pub fn valid_count(&self) -> usize {
        (0..self.cells()).filter(|&i| self.is_valid(i)).count()
    }

    /// The raster of `bands` (1-based, in that order), validity unified.
    pub fn select_bands(&self, bands: &[usize]) -> Raster {
        let data = bands
            .iter()
            .flat_map(|&b| self.band(b - 1).iter().copied())
            .collect();
        let mut out = Raster::from_data(self.width, self.height, bands.len(), data);
        out.unify_validity();
        out
    }

    /// Copy `block` (same band count) into this raster with its top-left
    /// cell at (`col`, `row`); the block must fit.
    pub fn paste(&mut self, block: &Raster, col: usize, row: usize) {
        let w = block.width;
        for b in 0..self.bands {
            let width = self.width;
            let dst = self.band_mut(b);
            let src = block.band(b);
            for r in 0..block.height {
                let at = (row + r) * width + col;
                dst[at..at + w].copy_from_slice(&src[r * w..(r + 1) * w]);
            }
        }
    }

    /// Marks a cell no-data in every band when any band lacks data, so that
    /// validity is one per-cell notion.
    pub fn unify_validity(&mut self) {
        let n = self.cells();
        for i in 0..n {
            if !self.is_valid(i) {
                for b in 0..self.bands {
                    self.data[b * n + i] = f64::NAN;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_are_selected_and_blocks_pasted_in_place() {
        let r = Raster::from_data(2, 1, 3, vec![1.0, 2.0, 3.0, f64::NAN, 5.0, 6.0]);
        let s = r.select_bands(&[3, 1]);
        assert_eq!(s.bands, 2);
        assert_eq!(s.band(0), &[5.0, 6.0]);
        assert_eq!(s.band(1)[0], 1.0);
        let mut out = Raster::empty(3, 2, 1);
        out.paste(&Raster::from_data(2, 1, 1, vec![7.0, 8.0]), 1, 1);
        assert_eq!(out.band(0)[4..], [7.0, 8.0]);
        assert!(out.band(0)[..4].iter().all(|v| v.is_nan()));
    }
}
