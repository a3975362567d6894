//! A grid summarised by blocks: the grid (heights, LP errors, the mask, the
//! drape) cut into at most 32 × 32 square blocks, each recorded by a short
//! hash of its values and a few statistics. A golden record keeps these as
//! text rows, one line per row of blocks, so that a change in review reads
//! as a change of a few lines, and a check can say which block changed
//! without the old bundle.

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// Most blocks along either axis.
const MOST_BLOCKS: usize = 32;

/// How a `width`×`height` raster is cut into square blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlockLayout {
    pub width: usize,
    pub height: usize,
    /// Side of a block, cells (the last row and column of blocks may be
    /// narrower).
    pub cells: usize,
}

impl BlockLayout {
    /// The layout of a `width`×`height` raster: blocks of the smallest side
    /// that keeps both counts within 32.
    pub fn of(width: usize, height: usize) -> BlockLayout {
        BlockLayout {
            width,
            height,
            cells: width.max(height).div_ceil(MOST_BLOCKS).max(1),
        }
    }

    /// Blocks across and down.
    pub fn blocks(&self) -> [usize; 2] {
        [
            self.width.div_ceil(self.cells),
            self.height.div_ceil(self.cells),
        ]
    }

    /// Columns `c0..c1` and rows `r0..r1` of block (`bx`, `by`).
    pub fn cells_of(&self, bx: usize, by: usize) -> [usize; 4] {
        let (c0, r0) = (bx * self.cells, by * self.cells);
        [
            c0,
            r0,
            (c0 + self.cells).min(self.width),
            (r0 + self.cells).min(self.height),
        ]
    }
}

/// What is recorded of each block, and how values are printed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BlockStatistics {
    /// Lowest, mean and highest value where the mask has data (metres).
    MinMeanMax,
    /// The largest value (metres).
    Max,
    /// How many cells have data.
    Count,
    /// Mean red, green and blue (levels).
    MeanColour,
}

impl BlockStatistics {
    /// Decimals each value is recorded with.
    fn decimals(self) -> usize {
        match self {
            BlockStatistics::MinMeanMax | BlockStatistics::Max => 3,
            BlockStatistics::Count => 0,
            BlockStatistics::MeanColour => 1,
        }
    }
}

/// A raster's blocks as recorded: their hashes and statistics, one text
/// line per row of blocks (`-` for a block without data).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BlockDigest {
    pub width: usize,
    pub height: usize,
    /// Side of a block, cells.
    pub block_cells: usize,
    pub statistics: BlockStatistics,
    /// Per row of blocks, the first 8 hex digits of each block's SHA-256
    /// (over its values and its mask), separated by spaces.
    pub hashes: Vec<String>,
    /// Per row of blocks, each block's statistics joined by `/`.
    pub values: Vec<String>,
}

/// One block read back from a digest.
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    pub hash: String,
    /// The statistics, or `None` for a block without data.
    pub values: Option<Vec<f64>>,
}

/// The values of a raster a digest is made of: `channels` values a cell,
/// row-major, and the data mask (1 data, 0 none) when there is one.
pub struct Cells<'a> {
    pub width: usize,
    pub height: usize,
    pub values: CellValues<'a>,
    pub mask: Option<&'a [u8]>,
}

/// Cell values of one of the kinds a bundle stores.
pub enum CellValues<'a> {
    /// One f32 a cell (heights).
    F32(&'a [f32]),
    /// The first of each pair (LP errors).
    FirstOfPairs(&'a [[f32; 2]]),
    /// The mask itself (counted).
    Mask(&'a [u8]),
    /// RGBA8 (the drape).
    Rgba(&'a [u8]),
}

impl Cells<'_> {
    fn has_data(&self, i: usize) -> bool {
        self.mask.is_none_or(|m| m[i] == 1)
    }

    /// The bytes hashed for cell `i`.
    fn bytes_of(&self, i: usize, into: &mut Vec<u8>) {
        match self.values {
            CellValues::F32(v) => into.extend_from_slice(&v[i].to_le_bytes()),
            CellValues::FirstOfPairs(v) => into.extend_from_slice(&v[i][0].to_le_bytes()),
            CellValues::Mask(v) => into.push(v[i]),
            CellValues::Rgba(v) => into.extend_from_slice(&v[4 * i..4 * i + 4]),
        }
        if let Some(m) = self.mask {
            into.push(m[i]);
        }
    }
}

/// Summarise `cells` block by block with `statistics`.
///
/// ```
/// use relevo_core::golden::blocks::{digest, BlockStatistics, CellValues, Cells};
/// let heights: Vec<f32> = (0..64 * 64).map(|i| (i % 64) as f32).collect();
/// let cells = Cells { width: 64, height: 64, values: CellValues::F32(&heights), mask: None };
/// let d = digest(&cells, BlockStatistics::MinMeanMax);
/// assert_eq!((d.block_cells, d.hashes.len()), (2, 32));
/// assert_eq!(d.blocks()[0][0].values, Some(vec![0.0, 0.5, 1.0]));
/// ```
pub fn digest(cells: &Cells, statistics: BlockStatistics) -> BlockDigest {
    let layout = BlockLayout::of(cells.width, cells.height);
    let [across, down] = layout.blocks();
    let decimals = statistics.decimals();
    let mut hashes = Vec::with_capacity(down);
    let mut values = Vec::with_capacity(down);
    let mut bytes = Vec::new();
    for by in 0..down {
        let (mut hash_row, mut value_row) = (Vec::new(), Vec::new());
        for bx in 0..across {
            let [c0, r0, c1, r1] = layout.cells_of(bx, by);
            bytes.clear();
            let mut stats = Accumulator::new(statistics);
            for r in r0..r1 {
                for c in c0..c1 {
                    let i = r * cells.width + c;
                    cells.bytes_of(i, &mut bytes);
                    if cells.has_data(i) {
                        stats.add(&cells.values, i);
                    }
                }
            }
            hash_row.push(hex::encode(&Sha256::digest(&bytes)[..4]));
            value_row.push(match stats.finish() {
                None => "-".to_string(),
                Some(v) => v
                    .iter()
                    .map(|x| format!("{x:.decimals$}"))
                    .collect::<Vec<_>>()
                    .join("/"),
            });
        }
        hashes.push(hash_row.join(" "));
        values.push(value_row.join(" "));
    }
    BlockDigest {
        width: cells.width,
        height: cells.height,
        block_cells: layout.cells,
        statistics,
        hashes,
        values,
    }
}

impl BlockDigest {
    /// The layout the digest was made with.
    pub fn layout(&self) -> BlockLayout {
        BlockLayout {
            width: self.width,
            height: self.height,
            cells: self.block_cells,
        }
    }

    /// The blocks, row by row; a malformed row (a record edited by hand)
    /// is an error naming it.
    pub fn parse(&self) -> Result<Vec<Vec<Block>>, String> {
        let [across, down] = self.layout().blocks();
        if self.hashes.len() != down || self.values.len() != down {
            return Err(format!(
                "{} hash rows and {} value rows, expected {down} of each",
                self.hashes.len(),
                self.values.len()
            ));
        }
        let width = match self.statistics {
            BlockStatistics::MinMeanMax | BlockStatistics::MeanColour => 3,
            BlockStatistics::Max | BlockStatistics::Count => 1,
        };
        let mut rows = Vec::with_capacity(down);
        for (by, (hash_row, value_row)) in self.hashes.iter().zip(&self.values).enumerate() {
            let hashes: Vec<&str> = hash_row.split(' ').collect();
            let values: Vec<&str> = value_row.split(' ').collect();
            if hashes.len() != across || values.len() != across {
                return Err(format!("block row {by}: expected {across} blocks"));
            }
            let mut row = Vec::with_capacity(across);
            for (hash, value) in hashes.into_iter().zip(values) {
                let values = match value {
                    "-" => None,
                    text => {
                        let parsed: Result<Vec<f64>, _> =
                            text.split('/').map(str::parse::<f64>).collect();
                        match parsed {
                            Ok(v) if v.len() == width && v.iter().all(|x| x.is_finite()) => Some(v),
                            _ => {
                                return Err(format!(
                                    "block row {by}: {text:?} is not {width} number(s)"
                                ))
                            }
                        }
                    }
                };
                row.push(Block {
                    hash: hash.to_string(),
                    values,
                });
            }
            rows.push(row);
        }
        Ok(rows)
    }

    /// The blocks; a digest made by [`digest`] always parses.
    pub fn blocks(&self) -> Vec<Vec<Block>> {
        self.parse().unwrap_or_default()
    }
}

/// Running statistics of one block.
struct Accumulator {
    statistics: BlockStatistics,
    count: usize,
    sum: [f64; 3],
    low: f64,
    high: f64,
}

impl Accumulator {
    fn new(statistics: BlockStatistics) -> Self {
        Accumulator {
            statistics,
            count: 0,
            sum: [0.0; 3],
            low: f64::INFINITY,
            high: f64::NEG_INFINITY,
        }
    }

    fn add(&mut self, values: &CellValues, i: usize) {
        if let CellValues::Mask(m) = values {
            self.count += usize::from(m[i] == 1);
            return;
        }
        self.count += 1;
        let v = match values {
            CellValues::F32(v) => f64::from(v[i]),
            CellValues::FirstOfPairs(v) => f64::from(v[i][0]),
            CellValues::Mask(_) => return,
            CellValues::Rgba(v) => {
                for k in 0..3 {
                    self.sum[k] += f64::from(v[4 * i + k]);
                }
                return;
            }
        };
        self.sum[0] += v;
        self.low = self.low.min(v);
        self.high = self.high.max(v);
    }

    fn finish(&self) -> Option<Vec<f64>> {
        let n = self.count as f64;
        match self.statistics {
            BlockStatistics::Count => Some(vec![n]),
            _ if self.count == 0 => None,
            BlockStatistics::MinMeanMax => Some(vec![self.low, self.sum[0] / n, self.high]),
            BlockStatistics::Max => Some(vec![self.high]),
            BlockStatistics::MeanColour => Some(self.sum.iter().map(|s| s / n).collect()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_cover_the_raster_in_at_most_32_blocks_a_side() {
        for (w, h) in [(129, 129), (1025, 1025), (349, 352), (3, 3), (65537, 17)] {
            let l = BlockLayout::of(w, h);
            let [across, down] = l.blocks();
            assert!(across <= 32 && down <= 32, "{w}×{h}");
            assert_eq!(l.cells_of(across - 1, down - 1)[2..], [w, h]);
        }
    }

    #[test]
    fn a_changed_cell_changes_its_block_only() {
        let mut heights: Vec<f32> = (0..129 * 129).map(|i| (i % 7) as f32).collect();
        let mask = vec![1u8; 129 * 129];
        let cells = |h: &[f32]| {
            digest(
                &Cells {
                    width: 129,
                    height: 129,
                    values: CellValues::F32(h),
                    mask: Some(&mask),
                },
                BlockStatistics::MinMeanMax,
            )
        };
        let before = cells(&heights).blocks();
        heights[60 * 129 + 70] += 5.0;
        let after = cells(&heights).blocks();
        let changed: Vec<(usize, usize)> = (0..before.len())
            .flat_map(|by| (0..before[by].len()).map(move |bx| (bx, by)))
            .filter(|&(bx, by)| before[by][bx] != after[by][bx])
            .collect();
        // Blocks of 5 cells: column 70, row 60 lie in block (14, 12).
        assert_eq!(changed, [(14, 12)]);
    }

    #[test]
    fn hand_edited_rows_are_refused() {
        let heights = vec![1.0f32; 16];
        let mut d = digest(
            &Cells {
                width: 4,
                height: 4,
                values: CellValues::F32(&heights),
                mask: None,
            },
            BlockStatistics::MinMeanMax,
        );
        d.values[0] = "1/2".into();
        assert!(d.parse().unwrap_err().contains("block row 0"));
    }
}
