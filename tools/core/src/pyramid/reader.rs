//! A pyramid opened for reading: its manifest checked, its four tile files
//! mapped into memory, any tile's arrays handed out as slices without a
//! copy, the tiles a camera sees, and the checks `relevo validate` runs.

use super::build::HeightSource;
use super::layout::{TileKey, TileLayout};
use super::store::TileArray;
use super::{PyramidManifest, FORMAT_VERSION};
use crate::bundle::{sha256_file, BundleFiles, MANIFEST_FILE, PYRAMID_FORMAT};
use crate::camera::Camera;
use crate::geo::GeoTransform;
use crate::lp::terrain_position;
use crate::lp::window::Rect;
use crate::{Error, Result};
use memmap2::Mmap;
use std::path::{Path, PathBuf};

/// Level 0 over a rectangle of the grid, row-major over it.
#[derive(Debug, Clone, PartialEq)]
pub struct GridWindow {
    pub rect: Rect,
    pub heights: Vec<f32>,
    pub mask: Vec<u8>,
    /// `[error, radius]`.
    pub lp: Vec<[f32; 2]>,
    /// The drape, RGBA8, a pixel a vertex.
    pub drape: Vec<u8>,
}

/// An opened pyramid.
pub struct Pyramid {
    pub dir: PathBuf,
    pub manifest: PyramidManifest,
    pub layout: TileLayout,
    maps: [Mmap; 4],
}

impl BundleFiles for Pyramid {
    fn dir(&self) -> &Path {
        &self.dir
    }
    fn files(&self) -> &std::collections::BTreeMap<String, crate::bundle::Artifact> {
        &self.manifest.files
    }
    fn terrain_frame(&self) -> crate::geo::TerrainFrame {
        self.frame()
    }
}

impl HeightSource for Pyramid {
    fn window(&self, rect: Rect) -> Result<(Vec<f32>, Vec<u8>)> {
        let w = self.level0_window(rect)?;
        Ok((w.heights, w.mask))
    }
}

/// One tile's arrays, `(T+1)²` samples row-major, mapped.
#[derive(Debug, Clone, Copy)]
pub struct TileView<'a> {
    pub key: TileKey,
    pub heights: &'a [f32],
    pub mask: &'a [u8],
    pub lp: &'a [[f32; 2]],
    /// RGBA8.
    pub drape: &'a [u8],
}

impl Pyramid {
    /// Open the pyramid at `dir`: the manifest's format, version and tiling
    /// checked, every tile file a regular file of the size the tiling says,
    /// mapped. Errors name the file and the problem.
    pub fn open(dir: &Path) -> Result<Pyramid> {
        let path = dir.join(MANIFEST_FILE);
        let text = crate::files::read_to_string(&path)?;
        let manifest: PyramidManifest =
            serde_json::from_str(&text).map_err(|e| Error::Manifest {
                path: path.clone(),
                json: e,
            })?;
        if manifest.format != PYRAMID_FORMAT {
            return Err(Error::invalid(
                &path,
                format!(
                    "format is {:?}, expected {PYRAMID_FORMAT:?}",
                    manifest.format
                ),
            ));
        }
        if manifest.format_version != FORMAT_VERSION {
            return Err(Error::invalid(
                &path,
                format!(
                    "pyramid format version {} is not supported (this build reads {FORMAT_VERSION})",
                    manifest.format_version
                ),
            ));
        }
        let bad = |p: String| Error::invalid(&path, p);
        if !(manifest.grid.cell_size_m.is_finite() && manifest.grid.cell_size_m > 0.0) {
            return Err(bad(format!(
                "cell size {} is not a positive number",
                manifest.grid.cell_size_m
            )));
        }
        if manifest.grid.side > crate::bundle::MAX_SIDE {
            return Err(bad(format!(
                "grid side {} exceeds {}",
                manifest.grid.side,
                crate::bundle::MAX_SIDE
            )));
        }
        let layout = TileLayout::new(manifest.grid.side, manifest.tiling.tile_cells)
            .map_err(|e| bad(e.to_string()))?;
        if (manifest.tiling.levels, manifest.tiling.tiles) != (layout.levels(), layout.count()) {
            return Err(bad(format!(
                "tiling says {} levels and {} tiles; a {}² grid in tiles of {} cells has {} and {}",
                manifest.tiling.levels,
                manifest.tiling.tiles,
                layout.side,
                layout.tile_cells,
                layout.levels(),
                layout.count()
            )));
        }
        let map = |a: TileArray| -> Result<Mmap> {
            let (key, file) = a.name();
            let artifact = manifest
                .files
                .get(key)
                .ok_or_else(|| bad(format!("no {key} file")))?;
            if artifact.file != file {
                return Err(bad(format!(
                    "{key}: file {:?}, expected {file:?}",
                    artifact.file
                )));
            }
            let file_path = dir.join(file);
            let handle = crate::files::open_regular(&file_path)?;
            let len = handle
                .metadata()
                .map_err(|e| Error::io(&file_path, e))?
                .len();
            let expected = (layout.count() * layout.tile_len() * a.bytes_per_vertex()) as u64;
            if len != expected {
                return Err(Error::invalid(
                    &file_path,
                    format!(
                        "is {len} bytes; {} tiles of {}² samples need {expected}",
                        layout.count(),
                        layout.samples()
                    ),
                ));
            }
            // SAFETY: the file is a regular file of the checked length;
            // readers only read the map, and a bundle is never written in
            // place (writers build a new folder and rename it).
            unsafe { Mmap::map(&handle) }.map_err(|e| Error::io(&file_path, e))
        };
        crate::bundle::check_files_stay_inside(dir, manifest.files.values())?;
        Ok(Pyramid {
            maps: [
                map(TileArray::Height)?,
                map(TileArray::Mask)?,
                map(TileArray::Lp)?,
                map(TileArray::Drape)?,
            ],
            dir: dir.to_path_buf(),
            manifest,
            layout,
        })
    }

    /// Drop the mapped pages read so far from this process's memory (they
    /// stay in the page cache and are read again when touched): a pass
    /// over every tile then holds a few tiles' pages at a time, not the
    /// whole pyramid's. A hint; a kernel that refuses it changes nothing.
    pub fn release_pages(&self) {
        for map in &self.maps {
            // SAFETY: the maps are read-only shared mappings of files no
            // one writes in place (see `open`), so dropping their pages
            // loses nothing: a later read faults the same bytes back in.
            let _ = unsafe { map.unchecked_advise(memmap2::UncheckedAdvice::DontNeed) };
        }
    }

    /// Tile `key`'s arrays, mapped.
    pub fn tile(&self, key: TileKey) -> Result<TileView<'_>> {
        if !self.layout.holds(key) {
            return Err(Error::invalid(&self.dir, format!("has no tile {key:?}")));
        }
        Ok(self.tile_held(key))
    }

    /// Tile `key`'s arrays, for a key the layout holds (the caller's
    /// arithmetic guarantees it).
    pub(crate) fn tile_held(&self, key: TileKey) -> TileView<'_> {
        let slot = self.layout.slot(key);
        let n = self.layout.tile_len();
        let slice = |a: TileArray| {
            let size = n * a.bytes_per_vertex();
            &self.maps[a as usize][slot * size..(slot + 1) * size]
        };
        TileView {
            key,
            heights: bytemuck::cast_slice(slice(TileArray::Height)),
            mask: slice(TileArray::Mask),
            lp: bytemuck::cast_slice(slice(TileArray::Lp)),
            drape: slice(TileArray::Drape),
        }
    }

    /// The terrain frame of the level-0 grid.
    pub fn frame(&self) -> crate::geo::TerrainFrame {
        let g = &self.manifest.grid;
        crate::geo::TerrainFrame {
            side: g.side,
            cell_size_m: g.cell_size_m,
            geotransform: g.geotransform,
        }
    }

    /// The tiles of `level` whose box (their extent, between the lowest and
    /// highest height) meets `camera`'s frustum.
    pub fn tiles_meeting(&self, camera: &Camera, level: u32) -> Vec<TileKey> {
        let planes = camera.frustum_planes();
        let [lo, hi] = self.manifest.grid.height_range_m.map(f64::from);
        let (side, cell) = (self.layout.side, self.manifest.grid.cell_size_m);
        self.layout
            .tiles(level)
            .filter(|&key| {
                let ([c0, r0, c1, r1], _) = self.layout.vertices(key);
                let a = terrain_position(c0, r1, side, cell, lo);
                let b = terrain_position(c1, r0, side, cell, hi);
                // Outside when the box's corner farthest along a plane's
                // normal is behind it.
                planes.iter().all(|p| {
                    let x = if p[0] >= 0.0 { b[0] } else { a[0] };
                    let y = if p[1] >= 0.0 { b[1] } else { a[1] };
                    let z = if p[2] >= 0.0 { b[2] } else { a[2] };
                    p[0] * x + p[1] * y + p[2] * z + p[3] >= 0.0
                })
            })
            .collect()
    }

    /// Each sample of level `level`'s lattice over `rect` (lattice columns
    /// and rows: level-0 vertex (u·2^level, v·2^level) is lattice vertex
    /// (u, v)), row by row: `f(tile, its sample)`.
    fn for_each_sample(&self, level: u32, rect: Rect, mut f: impl FnMut(&TileView, usize)) {
        let (t, samples) = (self.layout.tile_cells, self.layout.samples());
        let last = self.layout.across(level) - 1;
        for v in rect.r0..rect.r0 + rect.height {
            let y = (v / t).min(last);
            let mut x = usize::MAX;
            let mut tile = None;
            for u in rect.c0..rect.c0 + rect.width {
                if (u / t).min(last) != x {
                    x = (u / t).min(last);
                    tile = Some(self.tile_held(TileKey { level, x, y }));
                }
                if let Some(tile) = &tile {
                    f(tile, (v - y * t) * samples + (u - x * t));
                }
            }
        }
    }

    /// Level `level`'s drape over lattice rectangle `rect` (RGBA8, row by
    /// row), and the geotransform that places its pixels: pixel (i, j) is
    /// centred on the lattice vertex (c0 + i, r0 + j), as the grid's
    /// geotransform centres level-0 pixels on vertices.
    pub fn lattice_drape(&self, level: u32, rect: Rect) -> Result<(Vec<u8>, GeoTransform)> {
        crate::memory::check(
            &format!(
                "a {}×{} window of level {level}'s drape",
                rect.width, rect.height
            ),
            rect.len() as u64,
            4,
            "take a smaller window",
        )?;
        let mut rgba = Vec::with_capacity(rect.len() * 4);
        self.for_each_sample(level, rect, |tile, k| {
            rgba.extend_from_slice(&tile.drape[4 * k..4 * k + 4]);
        });
        let geo = self
            .layout
            .lattice_geotransform(&self.manifest.grid.geotransform, level, rect);
        Ok((rgba, geo))
    }

    /// Level `level`'s heights and mask over lattice rectangle `rect`, row
    /// by row.
    pub fn lattice_heights(&self, level: u32, rect: Rect) -> Result<(Vec<f32>, Vec<u8>)> {
        crate::memory::check(
            &format!(
                "a {}×{} window of level {level}'s heights",
                rect.width, rect.height
            ),
            rect.len() as u64,
            5,
            "take a smaller window",
        )?;
        let (mut heights, mut mask) = (
            Vec::with_capacity(rect.len()),
            Vec::with_capacity(rect.len()),
        );
        self.for_each_sample(level, rect, |tile, k| {
            heights.push(tile.heights[k]);
            mask.push(tile.mask[k]);
        });
        Ok((heights, mask))
    }

    /// Level 0 over `rect` of the grid as whole arrays, assembled from the
    /// tiles — for callers that hold a window that fits in memory (the
    /// comparisons with a single grid).
    pub fn level0_window(&self, rect: Rect) -> Result<GridWindow> {
        crate::memory::check(
            &format!("a {}×{} window of the pyramid", rect.width, rect.height),
            rect.len() as u64,
            17,
            "take a smaller window",
        )?;
        let (t, samples) = (self.layout.tile_cells, self.layout.samples());
        let across = self.layout.across(0);
        let mut heights = vec![0.0f32; rect.len()];
        let mut mask = vec![0u8; rect.len()];
        let mut lp = vec![[0.0f32; 2]; rect.len()];
        let mut drape = vec![0u8; rect.len() * 4];
        for y in rect.r0 / t..=((rect.r0 + rect.height - 1) / t).min(across - 1) {
            for x in rect.c0 / t..=((rect.c0 + rect.width - 1) / t).min(across - 1) {
                let tile = self.tile(TileKey { level: 0, x, y })?;
                let (tc, tr) = (x * t, y * t);
                for r in rect.r0.max(tr)..(rect.r0 + rect.height).min(tr + samples) {
                    for c in rect.c0.max(tc)..(rect.c0 + rect.width).min(tc + samples) {
                        let (i, k) = (rect.index((c, r)), (r - tr) * samples + (c - tc));
                        heights[i] = tile.heights[k];
                        mask[i] = tile.mask[k];
                        lp[i] = tile.lp[k];
                        drape[4 * i..4 * i + 4].copy_from_slice(&tile.drape[4 * k..4 * k + 4]);
                    }
                }
            }
        }
        Ok(GridWindow {
            rect,
            heights,
            mask,
            lp,
            drape,
        })
    }
}

/// Every problem `relevo validate` finds in a pyramid, one line each (at
/// most a few of each kind): files whose hash differs from the manifest's
/// (when `hashes`), samples a reader would refuse (a mask not 0/1, a height
/// not finite where there is data, an error or radius not finite and
/// non-negative), neighbours that disagree on the border they share, and
/// tiles that disagree with the finer tiles under them.
pub fn validate(p: &Pyramid, hashes: bool) -> Vec<String> {
    let mut problems = Vec::new();
    if hashes {
        for (key, a) in &p.manifest.files {
            match sha256_file(&p.dir.join(&a.file)) {
                Err(e) => problems.push(e.to_string()),
                Ok((_, sha)) if sha != a.sha256 => {
                    problems.push(format!(
                        "{key}: {} has sha256 {sha}, manifest says {}",
                        a.file, a.sha256
                    ));
                }
                Ok(_) => {}
            }
        }
        if !problems.is_empty() {
            return problems;
        }
    }
    let layout = p.layout;
    let samples = layout.samples();
    let t = layout.tile_cells;
    let most = 8;
    for level in 0..layout.levels() {
        for key in layout.tiles(level) {
            if problems.len() >= most {
                return problems;
            }
            if key.x % 4 == 0 {
                // A few tiles (and those they are compared with) at a
                // time in memory, whatever the region's width.
                p.release_pages();
            }
            let Ok(tile) = p.tile(key) else { continue };
            if let Some(i) = tile.mask.iter().position(|&m| m > 1) {
                problems.push(format!("tile {key:?}: mask {} at sample {i}", tile.mask[i]));
            }
            if let Some(i) =
                (0..tile.heights.len()).find(|&i| tile.mask[i] == 1 && !tile.heights[i].is_finite())
            {
                problems.push(format!(
                    "tile {key:?}: height {} at sample {i} is not finite",
                    tile.heights[i]
                ));
            }
            if let Some(i) = tile
                .lp
                .iter()
                .position(|v| !v.iter().all(|x| x.is_finite() && *x >= 0.0))
            {
                problems.push(format!(
                    "tile {key:?}: LP {:?} at sample {i} is not finite and non-negative",
                    tile.lp[i]
                ));
            }
            // The border shared with the right and lower neighbours.
            for (dx, dy) in [(1, 0), (0, 1)] {
                let next = TileKey {
                    level,
                    x: key.x + dx,
                    y: key.y + dy,
                };
                let Ok(other) = p.tile(next) else { continue };
                for k in 0..samples {
                    let (i, j) = if dx == 1 {
                        (k * samples + t, k * samples)
                    } else {
                        (t * samples + k, k)
                    };
                    if !same_sample(&tile, i, &other, j) {
                        problems.push(format!(
                            "tiles {key:?} and {next:?} disagree at their shared sample {k}"
                        ));
                        break;
                    }
                }
            }
            // Every sample is the finer tile's sample at the same vertex.
            if level > 0 {
                let mut disagreement = None;
                'samples: for r in 0..samples {
                    for c in 0..samples {
                        let (gc, gr) = layout.vertex(key, (c, r));
                        let stride = layout.stride(level - 1);
                        let (fc, fr) = (gc / stride, gr / stride);
                        let child = TileKey {
                            level: level - 1,
                            x: (fc / t).min(layout.across(level - 1) - 1),
                            y: (fr / t).min(layout.across(level - 1) - 1),
                        };
                        let Ok(finer) = p.tile(child) else { continue };
                        let j = (fr - child.y * t) * samples + (fc - child.x * t);
                        if !same_sample(&tile, r * samples + c, &finer, j) {
                            disagreement = Some((c, r, child));
                            break 'samples;
                        }
                    }
                }
                if let Some((c, r, child)) = disagreement {
                    problems.push(format!(
                        "tile {key:?}: sample ({c}, {r}) disagrees with tile {child:?}"
                    ));
                }
            }
        }
    }
    problems
}

/// Whether sample `i` of `a` and sample `j` of `b` hold the same bits.
fn same_sample(a: &TileView, i: usize, b: &TileView, j: usize) -> bool {
    a.heights[i].to_bits() == b.heights[j].to_bits()
        && a.mask[i] == b.mask[j]
        && a.lp[i].map(f32::to_bits) == b.lp[j].map(f32::to_bits)
}
