//! Building a pyramid tile by tile, in memory bounded by a few tiles and
//! their halos whatever the region's size, with errors and radii equal bit
//! for bit to the single grid's (`lp::window` says why):
//!
//! 1. heights: each level-0 tile's heights and mask from the source;
//! 2. own errors: each level-0 tile's vertices (scale ≤ T/2) from the tile
//!    ± T/2, and each tile's part of the own errors of the lattice of tile
//!    corners (scale ≥ T), whose diamonds span many tiles;
//! 3. saturation: level-0 tiles' errors and radii from blocks of up to
//!    4×4 tiles ± T (the farthest a descendant of a tile's vertex lies);
//! 4. the lattice: the corners' errors and radii, level by level, from the
//!    parts and the tiles' centres, written into the tiles' corners;
//! 5. the drape derived from the heights (tint and hillshade), each tile
//!    from the tile ± 1 — or sampled from imagery ([`DrapeSource`]);
//! 6. coarser levels: each tile every other sample of its four children,
//!    its drape from its own samples (or from the imagery at its level's
//!    cell size).
//!
//! Every pass records its tiles as done (see `store`), so a killed build
//! resumes where it stopped and ends with the same bytes.

use super::layout::{TileKey, TileLayout};
use super::store::{Pass, TileArray, TileStore};
use crate::bundle::StageTiming;
use crate::grid::HeightGrid;
use crate::lp::window::{combine, own_errors, own_partial, saturate, HeightWindow, Rect};
use crate::lp::Vertex;
use crate::lp::{vertex_kind, ErrorMetric};
use crate::raster::tint::drape_pixel;
use crate::{Error, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Where a build reads the (2^n+1)² grid from: heights in metres and the
/// data mask of any rectangle of it.
pub trait HeightSource: Sync {
    fn window(&self, rect: Rect) -> Result<(Vec<f32>, Vec<u8>)>;
}

impl HeightSource for HeightGrid {
    fn window(&self, rect: Rect) -> Result<(Vec<f32>, Vec<u8>)> {
        let rows = rect.r0..rect.r0 + rect.height;
        let cut = |values: &[f32]| -> Vec<f32> {
            rows.clone()
                .flat_map(|r| {
                    values[r * self.side + rect.c0..r * self.side + rect.c0 + rect.width]
                        .iter()
                        .copied()
                })
                .collect()
        };
        let heights = cut(&self.heights);
        let mask = rows
            .flat_map(|r| {
                self.mask[r * self.side + rect.c0..r * self.side + rect.c0 + rect.width]
                    .iter()
                    .copied()
            })
            .collect();
        Ok((heights, mask))
    }
}

/// The imagery a pyramid's drape is sampled from instead of being derived
/// from the heights (the CLI warps it through GDAL, tile by tile).
pub trait DrapeSource: Sync {
    /// Tile `key`'s drape: RGBA8, a pixel a sample, `(T+1)²` row-major,
    /// each the imagery over the square of the level's cell centred on the
    /// sample's vertex (see `TileLayout::tile_geotransform`); alpha 0
    /// where the imagery has no data.
    fn tile_drape(&self, key: TileKey) -> Result<Vec<u8>>;
}

/// What a build computes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BuildOptions {
    pub metric: ErrorMetric,
    /// Vertex spacing at level 0, metres.
    pub cell_size_m: f64,
    /// Give each tile a drape: derived from its heights (tint and
    /// hillshade), or sampled from the imagery passed to [`build`].
    pub drape: bool,
}

/// How far a build has come: tiles of the current pass done and in all.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    pub pass: &'static str,
    pub done: usize,
    pub total: usize,
}

/// What a build found of the grid's data, and where its time went.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildReport {
    /// Lowest and highest height with data, metres.
    pub height_range_m: [f32; 2],
    pub valid_vertices: u64,
    /// Wall time of each pass, in the order they ran (a resumed build's
    /// passes count only what this run did).
    pub timings: Vec<StageTiming>,
}

/// Entries a level-0 tile's partial-errors slot needs: per coarse level,
/// the edge and centre lattice vertices whose diamonds can meet a tile.
pub fn partials_capacity(layout: &TileLayout) -> usize {
    16 * layout.levels() as usize + 16
}

/// Bytes a thread's tile work holds at its largest, per vertex of the
/// widest window (the saturation's, a tile and a tile's width around it):
/// heights, own errors and the errors and radii computed (4 + 4 + 8), and
/// the window's copy of the output (8). Measured: 100 MB peak for two
/// threads at 512-cell tiles, 21 B per window vertex.
const WORK_BYTES_PER_WINDOW_VERTEX: u64 = 24;

/// Bytes the tile work of a build of `layout` on `threads` threads holds
/// at once: one widest window a thread.
pub fn working_bytes(layout: &TileLayout, threads: usize) -> u64 {
    let window = (3 * layout.tile_cells as u64 + 1).pow(2);
    (threads as u64)
        .saturating_mul(window)
        .saturating_mul(WORK_BYTES_PER_WINDOW_VERTEX)
}

/// Refuse, before anything is written, a build whose concurrent tile work
/// ([`working_bytes`] on the pool's threads) exceeds the memory budget.
pub fn check_working_memory(layout: &TileLayout) -> Result<()> {
    let threads = rayon::current_num_threads();
    crate::memory::check(
        &format!(
            "building tiles of {} cells on {threads} threads",
            layout.tile_cells
        ),
        working_bytes(layout, threads),
        1,
        "use smaller tiles (--tile-size) or fewer threads (RAYON_NUM_THREADS)",
    )
}

/// One pass of a build over its tiles, in the order [`steps`] lists them.
/// A step's tiles are independent of each other; each step reads only
/// what the steps before it wrote, so the tiles of one step may be split
/// among processes (see `relevo prep --plan`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "step")]
pub enum Step {
    /// Level-0 heights and mask from the source.
    Heights,
    /// Level-0 own errors and the lattice's partial errors.
    OwnErrors,
    /// Level-0 errors and radii below the lattice.
    Saturate,
    /// The lattice of tile corners: one item, the whole lattice.
    Lattice,
    /// Level-0 drape.
    Drape,
    /// Level `level` (≥ 1) from its children.
    Coarse { level: u32 },
    /// Level `level`'s drape.
    CoarseDrape { level: u32 },
}

impl Step {
    /// What progress bars and messages call it.
    pub fn name(self) -> String {
        match self {
            Step::Heights => "heights".into(),
            Step::OwnErrors => "own errors".into(),
            Step::Saturate => "errors and radii".into(),
            Step::Lattice => "lattice".into(),
            Step::Drape => "drape".into(),
            Step::Coarse { level } => format!("level {level}"),
            Step::CoarseDrape { level } => format!("level {level} drape"),
        }
    }

    /// The stage its wall time is recorded under in the manifest.
    pub fn timing_name(self) -> &'static str {
        match self {
            Step::Heights => "heights",
            Step::OwnErrors => "own errors",
            Step::Saturate => "errors and radii",
            Step::Lattice => "lattice",
            Step::Drape => "drape",
            Step::Coarse { .. } => "coarser levels",
            Step::CoarseDrape { .. } => "coarser drapes",
        }
    }

    fn pass(self) -> Pass {
        match self {
            Step::Heights => Pass::Heights,
            Step::OwnErrors => Pass::OwnErrors,
            Step::Saturate => Pass::Saturate,
            Step::Lattice => Pass::Lattice,
            Step::Drape => Pass::Drape,
            Step::Coarse { .. } => Pass::Coarse,
            Step::CoarseDrape { .. } => Pass::CoarseDrape,
        }
    }

    /// The tiles it computes, row by row (the lattice: the level-0 tile
    /// (0, 0), under which its one mark is kept).
    pub fn tiles(self, layout: &TileLayout) -> Vec<TileKey> {
        match self {
            Step::Lattice => vec![TileKey {
                level: 0,
                x: 0,
                y: 0,
            }],
            Step::Coarse { level } | Step::CoarseDrape { level } => layout.tiles(level).collect(),
            _ => layout.tiles(0).collect(),
        }
    }

    /// Those of `tiles` not yet done.
    pub fn missing(self, store: &TileStore, tiles: &[TileKey]) -> Result<Vec<TileKey>> {
        let mut left = Vec::new();
        for &key in tiles {
            if !store.done(self.pass(), key)? {
                left.push(key);
            }
        }
        Ok(left)
    }
}

/// The steps of a build of `layout`, in order.
pub fn steps(layout: &TileLayout, drape: bool) -> Vec<Step> {
    let mut steps = vec![
        Step::Heights,
        Step::OwnErrors,
        Step::Saturate,
        Step::Lattice,
    ];
    if drape {
        steps.push(Step::Drape);
    }
    for level in 1..layout.levels() {
        steps.push(Step::Coarse { level });
        if drape {
            steps.push(Step::CoarseDrape { level });
        }
    }
    steps
}

/// Build every tile of `store` from `source`, the drape from `imagery`
/// when given (else derived from the heights), reporting progress.
pub fn build(
    source: &dyn HeightSource,
    imagery: Option<&dyn DrapeSource>,
    store: &TileStore,
    options: &BuildOptions,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<BuildReport> {
    let layout = store.layout;
    let mut timings: Vec<StageTiming> = Vec::new();
    for step in steps(&layout, options.drape) {
        let ms = run_step(
            Some(source),
            imagery,
            store,
            options,
            step,
            &step.tiles(&layout),
            progress,
        )?;
        StageTiming::add(&mut timings, step.timing_name(), ms);
    }
    let start = std::time::Instant::now();
    let (height_range_m, valid_vertices) = statistics(store)?;
    StageTiming::add(
        &mut timings,
        "statistics",
        start.elapsed().as_secs_f64() * 1e3,
    );
    Ok(BuildReport {
        height_range_m,
        valid_vertices,
        timings,
    })
}

/// Compute `tiles` of `step` (those not done yet), in parallel, marking
/// each when it is; the steps before must be complete. `source` is read
/// by [`Step::Heights`] alone, `imagery` (when the drape is not derived)
/// by the drape steps. Returns the wall time, ms.
pub fn run_step(
    source: Option<&dyn HeightSource>,
    imagery: Option<&dyn DrapeSource>,
    store: &TileStore,
    options: &BuildOptions,
    step: Step,
    tiles: &[TileKey],
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<f64> {
    let name = step.timing_name();
    let pass = step.pass();
    match step {
        Step::Heights => each(store, tiles, pass, name, progress, &|key| {
            let source = source
                .ok_or_else(|| Error::Input("the heights step needs the region's DEM".into()))?;
            heights(source, store, key)
        }),
        Step::OwnErrors => {
            let lattice_z = lattice_heights(store)?;
            each(store, tiles, pass, name, progress, &|key| {
                own_pass(store, options, &lattice_z, key)
            })
        }
        Step::Saturate => {
            let blocks = saturation_blocks(&store.layout, tiles);
            each_group(store, &blocks, pass, name, progress, &|keys| {
                saturate_pass(store, options, keys)
            })
        }
        Step::Lattice => {
            let start = std::time::Instant::now();
            let lattice_z = lattice_heights(store)?;
            for &key in tiles {
                if !store.done(pass, key)? {
                    lattice_pass(store, options, &lattice_z)?;
                    store.mark(pass, key)?;
                }
            }
            Ok(start.elapsed().as_secs_f64() * 1e3)
        }
        Step::Drape | Step::CoarseDrape { .. } if imagery.is_some() => {
            each(store, tiles, pass, name, progress, &|key| {
                let rgba = imagery.map(|i| i.tile_drape(key)).transpose()?;
                let rgba = rgba.unwrap_or_default();
                if rgba.len() != store.layout.tile_len() * 4 {
                    return Err(Error::Input(format!(
                        "the imagery gave tile {key:?} {} bytes of drape, not {}",
                        rgba.len(),
                        store.layout.tile_len() * 4
                    )));
                }
                store.write(TileArray::Drape, key, &rgba)
            })
        }
        Step::Drape | Step::CoarseDrape { .. } => {
            let range = height_range(store)?;
            each(store, tiles, pass, name, progress, &|key| {
                drape_pass(store, options, range, key)
            })
        }
        Step::Coarse { .. } => each(store, tiles, pass, name, progress, &|key| {
            coarse_pass(store, key)
        }),
    }
}

/// Run `work` on every tile of `tiles` not yet done in `pass`, in parallel,
/// marking each when it is.
fn each(
    store: &TileStore,
    tiles: &[TileKey],
    pass: Pass,
    name: &'static str,
    progress: &(dyn Fn(Progress) + Sync),
    work: &(dyn Fn(TileKey) -> Result<()> + Sync),
) -> Result<f64> {
    let groups: Vec<Vec<TileKey>> = tiles.iter().map(|&key| vec![key]).collect();
    each_group(store, &groups, pass, name, progress, &|keys| work(keys[0]))
}

/// Run `work` on every group of `groups` with a tile not yet done in
/// `pass`, in parallel, on the group's tiles not yet done, marking them
/// when it is; progress counts tiles.
fn each_group(
    store: &TileStore,
    groups: &[Vec<TileKey>],
    pass: Pass,
    name: &'static str,
    progress: &(dyn Fn(Progress) + Sync),
    work: &(dyn Fn(&[TileKey]) -> Result<()> + Sync),
) -> Result<f64> {
    let start = std::time::Instant::now();
    let done = AtomicUsize::new(0);
    let total = groups.iter().map(Vec::len).sum();
    let report = |n| {
        progress(Progress {
            pass: name,
            done: n,
            total,
        });
    };
    report(0);
    let results: Vec<Result<usize>> = groups
        .par_iter()
        .map(|group| {
            let mut left = Vec::with_capacity(group.len());
            for &key in group {
                if !store.done(pass, key)? {
                    left.push(key);
                }
            }
            if !left.is_empty() {
                work(&left)?;
                for &key in &left {
                    store.mark(pass, key)?;
                }
            }
            let n = done.fetch_add(group.len(), Ordering::Relaxed) + group.len();
            report(n);
            Ok(n)
        })
        .collect();
    for r in results {
        r?;
    }
    report(total);
    Ok(start.elapsed().as_secs_f64() * 1e3)
}

/// The rectangle of level-`level` samples a tile covers, grown by `margin`.
fn tile_rect(layout: &TileLayout, key: TileKey, margin: usize) -> Rect {
    let t = layout.tile_cells;
    let side = (layout.side - 1) / layout.stride(key.level) + 1;
    Rect::around(
        [key.x * t, key.y * t, (key.x + 1) * t, (key.y + 1) * t],
        margin,
        side,
    )
}

fn heights(source: &dyn HeightSource, store: &TileStore, key: TileKey) -> Result<()> {
    let rect = tile_rect(&store.layout, key, 0);
    let (heights, mask) = source.window(rect)?;
    if let Some(i) = heights.iter().position(|h| !h.is_finite()) {
        return Err(Error::Input(format!(
            "tile {key:?}: height {} at column {}, row {} is not a finite number",
            heights[i],
            rect.c0 + i % rect.width,
            rect.r0 + i / rect.width
        )));
    }
    let (mut lo, mut hi, mut count) = (f32::INFINITY, f32::NEG_INFINITY, 0u64);
    for (&h, &m) in heights.iter().zip(&mask) {
        if m == 1 {
            lo = lo.min(h);
            hi = hi.max(h);
            count += 1;
        }
    }
    store.write(TileArray::Height, key, &heights)?;
    store.write(TileArray::Mask, key, &mask)?;
    store.write_stats(key, (lo, hi, count))
}

/// The grid's lowest and highest height with data, from the level-0
/// tiles' statistics.
fn height_range(store: &TileStore) -> Result<[f32; 2]> {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for key in store.layout.tiles(0) {
        let (l, h, _) = store.read_stats(key)?;
        lo = lo.min(l);
        hi = hi.max(h);
    }
    Ok([lo, hi])
}

/// The grid's height range and vertices with data, from the level-0
/// tiles (border vertices counted once); an error when it has none.
pub fn statistics(store: &TileStore) -> Result<([f32; 2], u64)> {
    let range = height_range(store)?;
    // Count each vertex once: a tile's own are all but its last row and
    // column, except along the grid's far edges.
    let layout = store.layout;
    let (t, across) = (layout.tile_cells, layout.across(0));
    let mut valid = 0u64;
    for key in layout.tiles(0) {
        let mask: Vec<u8> = store.read(TileArray::Mask, key)?;
        let rows = if key.y + 1 == across { t + 1 } else { t };
        let cols = if key.x + 1 == across { t + 1 } else { t };
        for r in 0..rows {
            valid += mask[r * (t + 1)..r * (t + 1) + cols]
                .iter()
                .filter(|&&m| m == 1)
                .count() as u64;
        }
    }
    if valid == 0 {
        return Err(Error::Input("the grid holds no data".into()));
    }
    Ok((range, valid))
}

/// Heights of the lattice of tile corners (every T-th vertex), row-major.
fn lattice_heights(store: &TileStore) -> Result<Vec<f32>> {
    let layout = store.layout;
    let (t, n) = (layout.tile_cells, layout.across(0) + 1);
    let mut z = vec![0.0f32; n * n];
    for key in layout.tiles(0) {
        for (dy, dx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
            z[(key.y + dy) * n + key.x + dx] =
                store.read_one(TileArray::Height, key, dy * t * (t + 1) + dx * t)?;
        }
    }
    Ok(z)
}

/// Own errors of a level-0 tile's vertices, and its parts of the lattice's.
fn own_pass(
    store: &TileStore,
    options: &BuildOptions,
    lattice_z: &[f32],
    key: TileKey,
) -> Result<()> {
    let layout = store.layout;
    let t = layout.tile_cells;
    let tile = tile_rect(&layout, key, 0);
    let halo = tile_rect(&layout, key, t / 2);
    let heights: Vec<f32> = store.window(TileArray::Height, 0, halo)?;
    let window = HeightWindow {
        heights: &heights,
        rect: halo,
        side: layout.side,
        cell_size_m: options.cell_size_m,
    };
    store.write_own(key, &own_errors(&window, tile, options.metric, t / 2))?;
    let mut partials = Vec::new();
    if options.metric == ErrorMetric::Bound {
        let n = layout.across(0) + 1;
        let z_of = |(c, r): Vertex| lattice_z[(r / t) * n + c / t];
        for ly in 0..n {
            for lx in 0..n {
                let v = (lx * t, ly * t);
                let Some((h, _)) = vertex_kind(layout.side, v.0, v.1) else {
                    continue;
                };
                // The diamond reaches h from the vertex every way.
                let meets = v.0 + h >= tile.c0
                    && v.0 <= tile.c0 + tile.width - 1 + h
                    && v.1 + h >= tile.r0
                    && v.1 <= tile.r0 + tile.height - 1 + h;
                if meets {
                    let part = own_partial(&window, &z_of, v, tile);
                    if part > 0.0 {
                        partials.push(((ly * n + lx) as u32, part));
                    }
                }
            }
        }
    }
    store.write_partials(key, &partials)
}

/// Errors and radii of level-0 tiles' vertices below the lattice, from a
/// block of neighbouring tiles and a tile's width around it, saturated at
/// once. The margin is what the values need: from a tile's edge vertex of
/// scale T/2 the chain of children runs outwards T/4 (to a square centre),
/// T/4 (to its edge vertex), T/8, T/8, … — T in all. (A margin of T/2
/// gives different values on the crops.) Every vertex's value depends on
/// its descendants only, so it is the same whatever block computes it:
/// larger blocks share their margins between more tiles (a lone tile's
/// window is nine tiles' area, a block of 4×4 tiles' 2.25 a tile).
fn saturate_pass(store: &TileStore, options: &BuildOptions, keys: &[TileKey]) -> Result<()> {
    let layout = store.layout;
    let t = layout.tile_cells;
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for k in keys {
        (x0, y0, x1, y1) = (x0.min(k.x), y0.min(k.y), x1.max(k.x), y1.max(k.y));
    }
    let side = layout.side;
    let wide = Rect::around([x0 * t, y0 * t, (x1 + 1) * t, (y1 + 1) * t], t, side);
    let heights: Vec<f32> = store.window(TileArray::Height, 0, wide)?;
    let own = store.own_window(wide)?;
    let window = HeightWindow {
        heights: &heights,
        rect: wide,
        side,
        cell_size_m: options.cell_size_m,
    };
    let out = saturate(&window, &own, t / 2);
    drop((heights, own));
    let mut lp = vec![[0.0f32; 2]; layout.tile_len()];
    for &key in keys {
        let tile = tile_rect(&layout, key, 0);
        for r in 0..tile.height {
            for c in 0..tile.width {
                lp[r * tile.width + c] = out[wide.index((tile.c0 + c, tile.r0 + r))];
            }
        }
        store.write(TileArray::Lp, key, &lp)?;
    }
    Ok(())
}

/// Tiles a side of the largest saturation block tried: a 4×4 block's
/// window is 36 tiles' area, 2.25 a tile.
const MAX_SATURATION_BLOCK: usize = 4;

/// Most bytes the saturation's windows take together, one a thread.
const SATURATION_WINDOWS_BYTES: u64 = 768 << 20;

/// `tiles` (of level 0) in square blocks for the saturation, row by row:
/// the largest side of [`MAX_SATURATION_BLOCK`], halving down to 1, whose
/// windows, one per thread, stay within [`SATURATION_WINDOWS_BYTES`] and
/// half the memory budget; a block holds those of `tiles` it covers. The
/// blocks change the memory and the time, not the values.
fn saturation_blocks(layout: &TileLayout, tiles: &[TileKey]) -> Vec<Vec<TileKey>> {
    let (t, across) = (layout.tile_cells as u64, layout.across(0));
    let threads = rayon::current_num_threads() as u64;
    let limit = SATURATION_WINDOWS_BYTES.min(crate::memory::budget() / 2);
    let mut k = MAX_SATURATION_BLOCK.min(across);
    while k > 1 && threads * ((k as u64 + 2) * t + 1).pow(2) * WORK_BYTES_PER_WINDOW_VERTEX > limit
    {
        k /= 2;
    }
    let wanted: std::collections::HashSet<TileKey> = tiles.iter().copied().collect();
    let mut blocks = Vec::new();
    for by in (0..across).step_by(k) {
        for bx in (0..across).step_by(k) {
            let mut block = Vec::with_capacity(k * k);
            for y in by..(by + k).min(across) {
                for x in bx..(bx + k).min(across) {
                    block.push(TileKey { level: 0, x, y });
                }
            }
            block.retain(|key| wanted.contains(key));
            if !block.is_empty() {
                blocks.push(block);
            }
        }
    }
    blocks
}

/// Errors and radii of the lattice of tile corners, coarsest scales last,
/// written into every tile corner they are.
fn lattice_pass(store: &TileStore, options: &BuildOptions, lattice_z: &[f32]) -> Result<()> {
    let layout = store.layout;
    let level0: Vec<TileKey> = layout.tiles(0).collect();
    let (t, n, side) = (layout.tile_cells, layout.across(0) + 1, layout.side);
    // Own errors: the largest of the tiles' parts (Bound), else from the
    // vertex and its hypotenuse alone.
    let mut own = vec![0.0f32; n * n];
    if options.metric == ErrorMetric::Bound {
        for &key in &level0 {
            for (i, e) in store.read_partials(key)? {
                let i = i as usize;
                own[i] = own[i].max(e);
            }
        }
    } else {
        let z_of = |(c, r): Vertex| lattice_z[(r / t) * n + c / t];
        for ly in 0..n {
            for lx in 0..n {
                own[ly * n + lx] = crate::lp::window::midpoint_own(side, &z_of, (lx * t, ly * t));
            }
        }
    }
    // The tiles' centres (the scale-T edges' children), with their heights.
    let mut centres: HashMap<Vertex, ([f32; 2], f32)> = HashMap::new();
    let middle = (t / 2) * (t + 1) + t / 2;
    for &key in &level0 {
        let lp: Vec<[f32; 2]> = store.read(TileArray::Lp, key)?;
        let z: Vec<f32> = store.read(TileArray::Height, key)?;
        centres.insert(
            (key.x * t + t / 2, key.y * t + t / 2),
            (lp[middle], z[middle]),
        );
    }
    let mut values = vec![[0.0f32; 2]; n * n];
    let mut h = t;
    while h < side - 1 {
        for edge in [true, false] {
            for ly in 0..n {
                for lx in 0..n {
                    let v = (lx * t, ly * t);
                    if vertex_kind(side, v.0, v.1) != Some((h, edge)) {
                        continue;
                    }
                    let i = ly * n + lx;
                    values[i] = combine(
                        side,
                        options.cell_size_m,
                        (v, lattice_z[i]),
                        own[i],
                        (h, edge),
                        |(c, r)| {
                            if c % t == 0 && r % t == 0 {
                                let k = (r / t) * n + c / t;
                                Some((values[k], lattice_z[k]))
                            } else {
                                centres.get(&(c, r)).copied()
                            }
                        },
                    );
                }
            }
        }
        h *= 2;
    }
    for &key in &level0 {
        for (dy, dx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
            let value = values[(key.y + dy) * n + key.x + dx];
            store.write_one(TileArray::Lp, key, dy * t * (t + 1) + dx * t, value)?;
        }
    }
    Ok(())
}

/// A tile of level ≥ 1: every other sample of its four children.
fn coarse_pass(store: &TileStore, key: TileKey) -> Result<()> {
    let layout = store.layout;
    let t = layout.tile_cells;
    let rect = tile_rect(&layout, key, 0);
    // The same samples at the finer level: every other one of twice the rectangle.
    let finer = Rect {
        c0: rect.c0 * 2,
        r0: rect.r0 * 2,
        width: 2 * t + 1,
        height: 2 * t + 1,
    };
    let level = key.level - 1;
    let every_other = |values: Vec<u8>, per: usize| -> Vec<u8> {
        let mut out = Vec::with_capacity(layout.tile_len() * per);
        for r in 0..=t {
            for c in 0..=t {
                let i = (2 * r * finer.width + 2 * c) * per;
                out.extend_from_slice(&values[i..i + per]);
            }
        }
        out
    };
    for a in [TileArray::Height, TileArray::Mask, TileArray::Lp] {
        let per = a.bytes_per_vertex();
        let values: Vec<u8> = store.window(a, level, finer)?;
        store.write(a, key, &every_other(values, per))?;
    }
    Ok(())
}

/// A tile's drape from its samples and their neighbours'.
fn drape_pass(
    store: &TileStore,
    options: &BuildOptions,
    range: [f32; 2],
    key: TileKey,
) -> Result<()> {
    let layout = store.layout;
    let stride = layout.stride(key.level);
    let side = (layout.side - 1) / stride + 1;
    let tile = tile_rect(&layout, key, 0);
    let halo = tile_rect(&layout, key, 1);
    let heights: Vec<f32> = store.window(TileArray::Height, key.level, halo)?;
    let mask: Vec<u8> = store.read(TileArray::Mask, key)?;
    let z = |c: usize, r: usize| heights[halo.index((c, r))];
    let cell = options.cell_size_m * stride as f64;
    let mut rgba = vec![0u8; layout.tile_len() * 4];
    for r in 0..tile.height {
        for c in 0..tile.width {
            let i = r * tile.width + c;
            if mask[i] == 1 {
                let px = drape_pixel(&z, side, cell, range, (tile.c0 + c, tile.r0 + r));
                rgba[4 * i..4 * i + 4].copy_from_slice(&px);
            }
        }
    }
    store.write(TileArray::Drape, key, &rgba)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lp::Hierarchy;
    use crate::pyramid::store::TileStore;
    use crate::testdata;

    /// A crop as a grid with a few vertices without data.
    fn grid(dem: &testdata::Dem) -> HeightGrid {
        let mut mask = vec![1u8; dem.side * dem.side];
        for i in (0..mask.len()).step_by(97) {
            mask[i] = 0;
        }
        HeightGrid {
            side: dem.side,
            heights: dem.heights.clone(),
            mask,
            geotransform: crate::geo::GeoTransform::north_up(
                0.0,
                0.0,
                dem.cell_size_m,
                dem.cell_size_m,
            ),
        }
    }

    fn options(dem: &testdata::Dem, metric: ErrorMetric) -> BuildOptions {
        BuildOptions {
            metric,
            cell_size_m: dem.cell_size_m,
            drape: true,
        }
    }

    /// Every tile of every level holds the single grid's heights, mask and
    /// errors and radii at its vertices, bit for bit: on the four real
    /// crops, tiles of 32 cells (64 tiles at level 0, four levels), both
    /// metrics; level 0's drape is the single grid's derived drape.
    #[test]
    fn every_tile_holds_the_single_grids_values_bit_for_bit() {
        for dem in testdata::dems() {
            for metric in [ErrorMetric::Bound, ErrorMetric::Midpoint] {
                let g = grid(&dem);
                let single = Hierarchy::compute(&g.heights, g.side, dem.cell_size_m, metric);
                let range = g.height_range().unwrap();
                let drape = crate::raster::tint::terrain_drape(
                    &g.heights,
                    &g.mask,
                    g.side,
                    dem.cell_size_m,
                    range,
                );
                let dir = tempfile::tempdir().unwrap();
                let layout = TileLayout::new(g.side, 32).unwrap();
                let store =
                    TileStore::open(dir.path(), layout, partials_capacity(&layout)).unwrap();
                let report = build(&g, None, &store, &options(&dem, metric), &|_| {}).unwrap();
                assert_eq!(report.height_range_m, range);
                assert_eq!(report.valid_vertices as usize, g.valid_count());
                for level in 0..layout.levels() {
                    for key in layout.tiles(level) {
                        let lp: Vec<[f32; 2]> = store.read(TileArray::Lp, key).unwrap();
                        let heights: Vec<f32> = store.read(TileArray::Height, key).unwrap();
                        let mask: Vec<u8> = store.read(TileArray::Mask, key).unwrap();
                        let rgba: Vec<u8> = store.read(TileArray::Drape, key).unwrap();
                        for j in 0..layout.samples() {
                            for i in 0..layout.samples() {
                                let (c, r) = layout.vertex(key, (i, j));
                                let (k, v) = (j * layout.samples() + i, r * g.side + c);
                                let what = format!("{} {metric:?} {key:?} ({c}, {r})", dem.name);
                                assert_eq!(
                                    lp[k].map(f32::to_bits),
                                    single.error_radius[v].map(f32::to_bits),
                                    "{what}"
                                );
                                assert_eq!(
                                    (heights[k].to_bits(), mask[k]),
                                    (g.heights[v].to_bits(), g.mask[v]),
                                    "{what}"
                                );
                                if level == 0 {
                                    assert_eq!(
                                        rgba[4 * k..4 * k + 4],
                                        drape[4 * v..4 * v + 4],
                                        "{what}"
                                    );
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// A source that fails on its `fail_at`-th window.
    struct Failing<'a> {
        grid: &'a HeightGrid,
        calls: AtomicUsize,
        fail_at: usize,
    }

    impl HeightSource for Failing<'_> {
        fn window(&self, rect: Rect) -> Result<(Vec<f32>, Vec<u8>)> {
            if self.calls.fetch_add(1, Ordering::SeqCst) == self.fail_at {
                return Err(Error::Input("the source stopped".into()));
            }
            self.grid.window(rect)
        }
    }

    /// A build stopped part-way and run again in the same folder ends with
    /// the same bytes as one uninterrupted build; so do builds on one
    /// thread and on four.
    #[test]
    fn stopped_builds_resume_to_the_same_bytes_at_any_thread_count() {
        let dem = testdata::dem("fuji_257.f32");
        let g = grid(&dem);
        let layout = TileLayout::new(g.side, 32).unwrap();
        let files = TileStore::file_bytes;
        let run = |threads: usize, source: &dyn HeightSource, dir: &std::path::Path| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let store = TileStore::open(dir, layout, partials_capacity(&layout)).unwrap();
                build(
                    source,
                    None,
                    &store,
                    &options(&dem, ErrorMetric::Bound),
                    &|_| {},
                )
                .map(|_| ())
            })
        };
        let whole = tempfile::tempdir().unwrap();
        run(1, &g, whole.path()).unwrap();
        let four = tempfile::tempdir().unwrap();
        run(4, &g, four.path()).unwrap();
        assert!(
            files(whole.path()) == files(four.path()),
            "one thread and four differ"
        );
        let stopped = tempfile::tempdir().unwrap();
        let failing = Failing {
            grid: &g,
            calls: AtomicUsize::new(0),
            fail_at: 40,
        };
        assert!(run(2, &failing, stopped.path()).is_err());
        run(2, &g, stopped.path()).unwrap();
        assert!(
            files(whole.path()) == files(stopped.path()),
            "the resumed build differs"
        );
    }
}
