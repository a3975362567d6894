//! The tile files of a pyramid being built: one file per array (heights,
//! mask, LP errors and radii, drape), each tile a fixed-size slot written
//! in place, and the scratch the build keeps between its passes (own
//! errors, the lattice's partial errors, per-tile statistics, progress).
//! Every write lands at its slot, so tiles are written in any order by any
//! thread, and a pass that is run again writes the same bytes.
//!
//! Progress is one byte per pass and slot, set after the tile's data is
//! written: after a killed build, `--resume` skips what is marked and the
//! result is byte for byte the uninterrupted one.

use super::layout::{TileKey, TileLayout};
use crate::lp::window::Rect;
use crate::{Error, Result};
use std::fs::{File, OpenOptions};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

/// The arrays of a tile, each in its own file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TileArray {
    /// Heights, f32 metres.
    Height,
    /// 1 where the grid has data, u8.
    Mask,
    /// `[error, radius]`, f32 metres.
    Lp,
    /// RGBA8.
    Drape,
}

impl TileArray {
    pub const ALL: [TileArray; 4] = [
        TileArray::Height,
        TileArray::Mask,
        TileArray::Lp,
        TileArray::Drape,
    ];

    /// Manifest key and file.
    pub fn name(self) -> (&'static str, &'static str) {
        match self {
            TileArray::Height => ("height", "tiles/height.f32"),
            TileArray::Mask => ("mask", "tiles/mask.u8"),
            TileArray::Lp => ("lp", "tiles/lp.f32x2"),
            TileArray::Drape => ("drape", "tiles/drape.rgba8"),
        }
    }

    /// Bytes a vertex takes.
    pub fn bytes_per_vertex(self) -> usize {
        match self {
            TileArray::Height | TileArray::Drape => 4,
            TileArray::Mask => 1,
            TileArray::Lp => 8,
        }
    }
}

/// The passes of a build whose progress is kept per tile.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pass {
    Heights = 0,
    OwnErrors = 1,
    Saturate = 2,
    /// The lattice of tile corners (one mark, slot 0).
    Lattice = 3,
    Drape = 4,
    Coarse = 5,
    CoarseDrape = 6,
}

const PASSES: usize = 7;

/// Bytes of a tile's statistics: lowest and highest height with data,
/// vertices with data.
const STATS_BYTES: usize = 16;

/// Open tile files in a folder.
pub struct TileStore {
    pub layout: TileLayout,
    dir: PathBuf,
    arrays: [File; 4],
    own: File,
    partials: File,
    stats: File,
    progress: File,
    /// Entries a tile's partials slot holds.
    pub partials_capacity: usize,
    /// Whether a mark waits for the data before it to reach the disk.
    durable: bool,
}

fn open(path: &Path, len: u64) -> Result<File> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    }
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(|e| Error::io(path, e))?;
    file.set_len(len).map_err(|e| Error::io(path, e))?;
    Ok(file)
}

impl TileStore {
    /// Open (or create, sized) the tile files of `layout` in `dir`; what a
    /// killed build wrote there is kept.
    pub fn open(dir: &Path, layout: TileLayout, partials_capacity: usize) -> Result<TileStore> {
        let count = layout.count() as u64;
        let len = layout.tile_len() as u64;
        let array = |a: TileArray| {
            open(
                &dir.join(a.name().1),
                count * len * a.bytes_per_vertex() as u64,
            )
        };
        let level0 = layout.across(0).pow(2) as u64;
        Ok(TileStore {
            arrays: [
                array(TileArray::Height)?,
                array(TileArray::Mask)?,
                array(TileArray::Lp)?,
                array(TileArray::Drape)?,
            ],
            own: open(&dir.join("scratch/own.f32"), level0 * len * 4)?,
            partials: open(
                &dir.join("scratch/partials.bin"),
                level0 * (8 * partials_capacity as u64 + 4),
            )?,
            stats: open(&dir.join("scratch/stats.bin"), level0 * STATS_BYTES as u64)?,
            progress: open(&dir.join("scratch/progress.bin"), count * PASSES as u64)?,
            layout,
            dir: dir.to_path_buf(),
            partials_capacity,
            durable: false,
        })
    }

    /// Make every [`TileStore::mark`] wait until the data written before it
    /// is on the disk (`fdatasync`): a mark then survives only with its
    /// tile, even when the machine fails — what jobs on a cluster's shared
    /// file system need. A killed process needs none of it (the kernel
    /// keeps what it wrote), so a local build does without.
    pub fn durable(mut self) -> TileStore {
        self.durable = true;
        self
    }

    /// Bytes the tile files and the scratch take for `layout`.
    pub fn bytes_needed(layout: &TileLayout, partials_capacity: usize) -> u64 {
        let (count, len) = (layout.count() as u64, layout.tile_len() as u64);
        let level0 = layout.across(0).pow(2) as u64;
        let tiles: u64 = TileArray::ALL
            .iter()
            .map(|a| count * len * a.bytes_per_vertex() as u64)
            .sum();
        tiles
            + level0 * (len * 4 + 8 * partials_capacity as u64 + 4 + STATS_BYTES as u64)
            + count * PASSES as u64
    }

    fn file(&self, a: TileArray) -> &File {
        &self.arrays[a as usize]
    }

    fn io(&self, file: &str, e: std::io::Error) -> Error {
        Error::io(self.dir.join(file), e)
    }

    /// Write tile `key`'s `a` (one tile's worth of elements).
    pub fn write<T: bytemuck::Pod>(&self, a: TileArray, key: TileKey, values: &[T]) -> Result<()> {
        let bytes: &[u8] = bytemuck::cast_slice(values);
        let size = self.layout.tile_len() * a.bytes_per_vertex();
        debug_assert_eq!(bytes.len(), size);
        let at = (self.layout.slot(key) * size) as u64;
        self.file(a)
            .write_all_at(bytes, at)
            .map_err(|e| self.io(a.name().1, e))
    }

    /// Read tile `key`'s `a`.
    pub fn read<T: bytemuck::Pod>(&self, a: TileArray, key: TileKey) -> Result<Vec<T>> {
        let n = self.layout.tile_len() * a.bytes_per_vertex() / size_of::<T>();
        let mut values = vec![T::zeroed(); n];
        let at = (self.layout.slot(key) * self.layout.tile_len() * a.bytes_per_vertex()) as u64;
        self.file(a)
            .read_exact_at(bytemuck::cast_slice_mut(&mut values), at)
            .map_err(|e| self.io(a.name().1, e))?;
        Ok(values)
    }

    /// One element of tile `key`'s `a`, at sample index `i`.
    pub fn read_one<T: bytemuck::Pod>(&self, a: TileArray, key: TileKey, i: usize) -> Result<T> {
        let mut value = T::zeroed();
        let at =
            ((self.layout.slot(key) * self.layout.tile_len() + i) * a.bytes_per_vertex()) as u64;
        self.file(a)
            .read_exact_at(bytemuck::bytes_of_mut(&mut value), at)
            .map_err(|e| self.io(a.name().1, e))?;
        Ok(value)
    }

    /// Write one element of tile `key`'s `a` at sample index `i`.
    pub fn write_one<T: bytemuck::Pod>(
        &self,
        a: TileArray,
        key: TileKey,
        i: usize,
        value: T,
    ) -> Result<()> {
        let size = a.bytes_per_vertex();
        let at = ((self.layout.slot(key) * self.layout.tile_len() + i) * size) as u64;
        self.file(a)
            .write_all_at(bytemuck::bytes_of(&value), at)
            .map_err(|e| self.io(a.name().1, e))
    }

    /// The samples of `a` at `level` over `rect` (in that level's sample
    /// columns and rows), assembled from the tiles that hold them.
    pub fn window<T: bytemuck::Pod>(&self, a: TileArray, level: u32, rect: Rect) -> Result<Vec<T>> {
        let t = self.layout.tile_cells;
        let samples = self.layout.samples();
        let per = a.bytes_per_vertex() / size_of::<T>();
        let mut out = vec![T::zeroed(); rect.len() * per];
        let across = self.layout.across(level);
        let (x0, y0) = (rect.c0 / t, rect.r0 / t);
        let (x1, y1) = (
            ((rect.c0 + rect.width - 1) / t).min(across - 1),
            ((rect.r0 + rect.height - 1) / t).min(across - 1),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let key = TileKey { level, x, y };
                let tile: Vec<T> = self.read(a, key)?;
                let (tc, tr) = (x * t, y * t);
                for r in rect.r0.max(tr)..(rect.r0 + rect.height).min(tr + samples) {
                    let c_from = rect.c0.max(tc);
                    let c_to = (rect.c0 + rect.width).min(tc + samples);
                    if c_from >= c_to {
                        continue;
                    }
                    let src = ((r - tr) * samples + (c_from - tc)) * per;
                    let dst = rect.index((c_from, r)) * per;
                    let n = (c_to - c_from) * per;
                    out[dst..dst + n].copy_from_slice(&tile[src..src + n]);
                }
            }
        }
        Ok(out)
    }

    /// Own errors of level-0 tile `key` (scratch).
    pub fn write_own(&self, key: TileKey, own: &[f32]) -> Result<()> {
        let at = (self.layout.slot(key) * self.layout.tile_len() * 4) as u64;
        self.own
            .write_all_at(bytemuck::cast_slice(own), at)
            .map_err(|e| self.io("scratch/own.f32", e))
    }

    /// Own errors over `rect` of level 0, from the tiles that hold them.
    pub fn own_window(&self, rect: Rect) -> Result<Vec<f32>> {
        let t = self.layout.tile_cells;
        let samples = self.layout.samples();
        let mut out = vec![0.0f32; rect.len()];
        let across = self.layout.across(0);
        for y in rect.r0 / t..=((rect.r0 + rect.height - 1) / t).min(across - 1) {
            for x in rect.c0 / t..=((rect.c0 + rect.width - 1) / t).min(across - 1) {
                let key = TileKey { level: 0, x, y };
                let mut tile = vec![0.0f32; self.layout.tile_len()];
                let at = (self.layout.slot(key) * self.layout.tile_len() * 4) as u64;
                self.own
                    .read_exact_at(bytemuck::cast_slice_mut(&mut tile), at)
                    .map_err(|e| self.io("scratch/own.f32", e))?;
                let (tc, tr) = (x * t, y * t);
                for r in rect.r0.max(tr)..(rect.r0 + rect.height).min(tr + samples) {
                    for c in rect.c0.max(tc)..(rect.c0 + rect.width).min(tc + samples) {
                        out[rect.index((c, r))] = tile[(r - tr) * samples + (c - tc)];
                    }
                }
            }
        }
        Ok(out)
    }

    /// The lattice's partial own errors level-0 tile `key` gives:
    /// (lattice vertex index, error).
    pub fn write_partials(&self, key: TileKey, partials: &[(u32, f32)]) -> Result<()> {
        if partials.len() > self.partials_capacity {
            return Err(Error::Input(format!(
                "tile {key:?}: {} partial errors, more than the {} a slot holds",
                partials.len(),
                self.partials_capacity
            )));
        }
        let mut bytes = (partials.len() as u32).to_le_bytes().to_vec();
        for (i, e) in partials {
            bytes.extend_from_slice(&i.to_le_bytes());
            bytes.extend_from_slice(&e.to_le_bytes());
        }
        let at = self.layout.slot(key) as u64 * (8 * self.partials_capacity as u64 + 4);
        self.partials
            .write_all_at(&bytes, at)
            .map_err(|e| self.io("scratch/partials.bin", e))
    }

    pub fn read_partials(&self, key: TileKey) -> Result<Vec<(u32, f32)>> {
        let size = 8 * self.partials_capacity + 4;
        let mut bytes = vec![0u8; size];
        let at = self.layout.slot(key) as u64 * size as u64;
        self.partials
            .read_exact_at(&mut bytes, at)
            .map_err(|e| self.io("scratch/partials.bin", e))?;
        let n = (u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as usize)
            .min(self.partials_capacity);
        Ok((0..n)
            .map(|k| {
                let b = &bytes[4 + 8 * k..12 + 8 * k];
                (
                    u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                    f32::from_le_bytes([b[4], b[5], b[6], b[7]]),
                )
            })
            .collect())
    }

    /// A level-0 tile's lowest and highest height with data and its
    /// vertices with data (∞, −∞, 0 without data).
    pub fn write_stats(&self, key: TileKey, (lo, hi, count): (f32, f32, u64)) -> Result<()> {
        let mut bytes = lo.to_le_bytes().to_vec();
        bytes.extend_from_slice(&hi.to_le_bytes());
        bytes.extend_from_slice(&count.to_le_bytes());
        self.stats
            .write_all_at(&bytes, (self.layout.slot(key) * STATS_BYTES) as u64)
            .map_err(|e| self.io("scratch/stats.bin", e))
    }

    pub fn read_stats(&self, key: TileKey) -> Result<(f32, f32, u64)> {
        let mut b = [0u8; STATS_BYTES];
        self.stats
            .read_exact_at(&mut b, (self.layout.slot(key) * STATS_BYTES) as u64)
            .map_err(|e| self.io("scratch/stats.bin", e))?;
        Ok((
            f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            f32::from_le_bytes([b[4], b[5], b[6], b[7]]),
            u64::from_le_bytes([b[8], b[9], b[10], b[11], b[12], b[13], b[14], b[15]]),
        ))
    }

    /// Whether `pass` finished for `key`.
    pub fn done(&self, pass: Pass, key: TileKey) -> Result<bool> {
        let mut b = [0u8];
        self.progress
            .read_exact_at(&mut b, self.progress_at(pass, key))
            .map_err(|e| self.io("scratch/progress.bin", e))?;
        Ok(b[0] == 1)
    }

    /// Record that `pass` finished for `key` (after its data is written).
    pub fn mark(&self, pass: Pass, key: TileKey) -> Result<()> {
        if self.durable {
            let scratch = [
                (&self.own, "scratch/own.f32"),
                (&self.partials, "scratch/partials.bin"),
                (&self.stats, "scratch/stats.bin"),
            ];
            for a in TileArray::ALL {
                self.file(a)
                    .sync_data()
                    .map_err(|e| self.io(a.name().1, e))?;
            }
            for (file, name) in scratch {
                file.sync_data().map_err(|e| self.io(name, e))?;
            }
        }
        self.progress
            .write_all_at(&[1], self.progress_at(pass, key))
            .map_err(|e| self.io("scratch/progress.bin", e))
    }

    fn progress_at(&self, pass: Pass, key: TileKey) -> u64 {
        (self.layout.slot(key) * PASSES + pass as usize) as u64
    }

    /// The tile files' bytes in `dir`, array by array (for tests that
    /// compare builds).
    #[cfg(test)]
    pub fn file_bytes(dir: &Path) -> Vec<Vec<u8>> {
        TileArray::ALL
            .iter()
            .map(|a| std::fs::read(dir.join(a.name().1)).unwrap_or_default())
            .collect()
    }

    /// Remove the scratch once the pyramid is complete.
    pub fn remove_scratch(self) -> Result<()> {
        let scratch = self.dir.join("scratch");
        drop(self);
        std::fs::remove_dir_all(&scratch).map_err(|e| Error::io(&scratch, e))
    }
}
