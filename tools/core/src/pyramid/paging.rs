//! A pyramid paged for a moving camera, as the viewer flies over a region
//! of any size: tiles read on a background thread into a cache under a
//! memory budget (the least recently used go first), and each frame the
//! *cut* — the resident tiles a refinement reads: the finest the camera
//! needs where they have arrived, coarser ones where they have not yet —
//! with the vertices it holds as a [`VertexSource`] for `lp::refine`.
//!
//! **Which tiles a camera needs.** A vertex finer than a tile's lattice
//! descends from the centre c of one of the lattice's cells, whose parents
//! p, q are the ends of a diagonal; nesting bounds its error by
//! min(δp, δq) and its radius by min(rp, rq) − |p − c| (LP seed §3.3:
//! saturated errors, nested spheres). A tile is split into its four
//! children when its box, grown by the largest such radius, comes nearer
//! the eye than ν·δ + r (ν = λ/τ, seed eq. 2) and meets the frustum — the
//! only places a finer vertex can be active.
//!
//! **No cracks while tiles load.** A vertex is held when it lies on the
//! lattice of every leaf tile that touches it, and leaves touching along
//! an edge or a corner differ by at most one level (a restricted
//! quadtree: where a neighbour is two levels coarser, it is split when
//! its children are resident, else the finer side is merged). Then every
//! parent of a held vertex is held, the refinement's active set stays
//! closed under parents, and the mesh has no T-junction whatever has
//! arrived. Once every tile the camera needs is resident the cut holds
//! every vertex that can be active, and the mesh equals the single grid's
//! triangle for triangle (both tested below on real crops).

use super::layout::{TileKey, TileLayout};
use super::reader::Pyramid;
use crate::grid::{vertex_normal, EIGHT_NEIGHBOURS};
use crate::lp::refine::{RefineParams, VertexSource};
use crate::lp::terrain_position;
use crate::{Error, Result};
use std::collections::{HashMap, HashSet};
use std::sync::mpsc::{channel, Receiver};
use std::sync::{Arc, Condvar, Mutex};

/// One tile read out of the pyramid's files: `(T+1)²` samples row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedTile {
    pub key: TileKey,
    pub heights: Vec<f32>,
    pub mask: Vec<u8>,
    /// `[error, radius]`, metres.
    pub lp: Vec<[f32; 2]>,
    /// RGBA8, a pixel a vertex (empty when the pyramid has no drape).
    pub drape: Vec<u8>,
    /// Upper bounds of the error and the radius (metres) of every vertex
    /// finer than this tile's lattice inside it; zero on level 0.
    finer_bound_m: [f64; 2],
    /// Lowest and highest height of the lattice, metres.
    height_range_m: [f32; 2],
}

impl LoadedTile {
    /// Read tile `key` of `p` (its pages fault in here, off the drawing
    /// thread) and bound what lies below it.
    pub fn read(p: &Pyramid, key: TileKey) -> Result<LoadedTile> {
        let view = p.tile(key)?;
        let samples = p.layout.samples();
        let mut finer = [0.0f64, 0.0];
        if key.level > 0 {
            // Half a lattice cell's diagonal: how far a cell's centre lies
            // from its corners, at least.
            let half_diagonal =
                p.layout.stride(key.level) as f64 * p.manifest.grid.cell_size_m / 2f64.sqrt();
            for j in 0..samples - 1 {
                for i in 0..samples - 1 {
                    let at = |di: usize, dj: usize| view.lp[(j + dj) * samples + i + di];
                    for (a, b) in [(at(0, 0), at(1, 1)), (at(1, 0), at(0, 1))] {
                        let error = f64::from(a[0].min(b[0]));
                        let radius = f64::from(a[1].min(b[1])) - half_diagonal;
                        finer = [finer[0].max(error), finer[1].max(radius)];
                    }
                }
            }
        }
        let range = view
            .heights
            .iter()
            .fold([f32::INFINITY, f32::NEG_INFINITY], |[lo, hi], &z| {
                [lo.min(z), hi.max(z)]
            });
        Ok(LoadedTile {
            key,
            heights: view.heights.to_vec(),
            mask: view.mask.to_vec(),
            lp: view.lp.to_vec(),
            drape: view.drape.to_vec(),
            finer_bound_m: finer,
            height_range_m: range,
        })
    }

    /// Bytes the tile holds in memory.
    pub fn bytes(&self) -> usize {
        self.heights.len() * 4 + self.mask.len() + self.lp.len() * 8 + self.drape.len()
    }
}

/// The pyramid's tiles and its level-0 grid, as the cut needs them.
#[derive(Debug, Clone, Copy)]
struct Geometry {
    layout: TileLayout,
    cell_size_m: f64,
    /// The grid's lowest and highest height, metres.
    height_range_m: [f32; 2],
}

impl Geometry {
    fn of(p: &Pyramid) -> Geometry {
        Geometry {
            layout: p.layout,
            cell_size_m: p.manifest.grid.cell_size_m,
            height_range_m: p.manifest.grid.height_range_m,
        }
    }

    fn top(&self) -> TileKey {
        TileKey {
            level: self.layout.levels() - 1,
            x: 0,
            y: 0,
        }
    }

    /// Whether a vertex finer than `tile`'s lattice may be active or in
    /// view for `p` (see the module's introduction).
    fn needs_finer(&self, tile: &LoadedTile, p: &RefineParams) -> bool {
        if tile.key.level == 0 {
            return false;
        }
        let ([c0, r0, c1, r1], _) = self.layout.vertices(tile.key);
        let side = self.layout.side;
        let lo = self.height_range_m[0].min(tile.height_range_m[0]) as f64;
        let hi = self.height_range_m[1].max(tile.height_range_m[1]) as f64;
        let a = terrain_position(c0, r1, side, self.cell_size_m, lo);
        let b = terrain_position(c1, r0, side, self.cell_size_m, hi);
        let [error, radius] = tile.finer_bound_m;
        let radius = radius.max(0.0);
        let nearest: f64 = (0..3)
            .map(|k| (a[k] - p.eye[k]).max(0.0).max(p.eye[k] - b[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        if nearest > p.lambda / p.tau_px * error + radius {
            return false;
        }
        p.planes.is_none_or(|planes| {
            planes.iter().all(|q| {
                let far = [0, 1, 2].map(|k| if q[k] >= 0.0 { b[k] } else { a[k] });
                q[0] * far[0] + q[1] * far[1] + q[2] * far[2] + q[3] >= -radius
            })
        })
    }

    fn children(key: TileKey) -> [TileKey; 4] {
        [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(dx, dy)| TileKey {
            level: key.level - 1,
            x: 2 * key.x + dx,
            y: 2 * key.y + dy,
        })
    }
}

/// The resident tiles a frame refines through: a leaf over every part of
/// the grid, neighbours at most one level apart, and the leaves'
/// ancestors. As a [`VertexSource`] it holds the vertices on the lattice
/// of every leaf touching them; strip indices are row-major over the
/// level-0 grid.
#[derive(Debug, Clone)]
pub struct Cut {
    geometry: Geometry,
    /// The leaves and their ancestors.
    tiles: HashMap<TileKey, Arc<LoadedTile>>,
    /// The level of the leaf over each level-0 tile, row by row.
    leaf_level: Vec<u32>,
    /// The leaf over each level-0 tile, row by row (what a vertex is read
    /// from without a search).
    leaf_tile: Vec<Option<Arc<LoadedTile>>>,
    /// Level-0 tiles a side, and log2 of a tile's cells: what every vertex
    /// lookup needs, kept (shifts, no divisions).
    across: usize,
    tile_shift: u32,
}

/// A sample of the cut: what the mesh draws at a vertex.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CutSample {
    pub height_m: f32,
    pub mask: u8,
    /// Unit normal of the leaf's lattice there (terrain frame).
    pub normal: [f64; 3],
}

impl Cut {
    /// The leaf over level-0 tile (tx, ty).
    fn leaf_key(&self, tx: usize, ty: usize) -> TileKey {
        let level = self.leaf_level[ty * self.across + tx];
        TileKey {
            level,
            x: tx >> level,
            y: ty >> level,
        }
    }

    /// The leaves, coarsest first.
    pub fn leaves(&self) -> Vec<TileKey> {
        let n = self.across;
        let mut keys: Vec<TileKey> = (0..n * n).map(|i| self.leaf_key(i % n, i / n)).collect();
        keys.sort_by_key(|k| (std::cmp::Reverse(k.level), k.y, k.x));
        keys.dedup();
        keys
    }

    /// A tile of the cut (a leaf or one of their ancestors).
    pub fn tile(&self, key: TileKey) -> Option<&Arc<LoadedTile>> {
        self.tiles.get(&key)
    }

    /// The leaf that holds vertex (c, r) on its lattice, and the sample's
    /// index in it; `None` when no leaf over it holds it.
    fn held(&self, c: usize, r: usize) -> Option<(&LoadedTile, usize)> {
        let (n, shift) = (self.across, self.tile_shift);
        let (tx, ty) = ((c >> shift).min(n - 1), (r >> shift).min(n - 1));
        let on_lattice = |x: usize, y: usize| {
            let s = self.leaf_level[y * n + x];
            (c >> s) << s == c && (r >> s) << s == r
        };
        if !on_lattice(tx, ty) {
            return None;
        }
        // On a level-0 tile's left or top border, the leaves across it
        // must hold the vertex too.
        let left = c > 0 && tx << shift == c;
        let up = r > 0 && ty << shift == r;
        let across = [
            (left, tx.wrapping_sub(1), ty),
            (up, tx, ty.wrapping_sub(1)),
            (left && up, tx.wrapping_sub(1), ty.wrapping_sub(1)),
        ];
        if across
            .iter()
            .any(|&(border, x, y)| border && !on_lattice(x, y))
        {
            return None;
        }
        let tile = self.leaf_tile.get(ty * n + tx)?.as_ref()?;
        // The leaf's first vertex: its key times its span, 2^(level + shift).
        let s = tile.key.level;
        let (c0, r0) = (tile.key.x << (s + shift), tile.key.y << (s + shift));
        let samples = (1 << shift) + 1;
        Some((tile, ((r - r0) >> s) * samples + ((c - c0) >> s)))
    }

    /// What the mesh draws at held vertex (c, r): height, mask and the
    /// normal of the leaf's lattice (central differences at its spacing,
    /// one-sided on its border).
    pub fn sample(&self, c: usize, r: usize) -> Option<CutSample> {
        let (tile, k) = self.held(c, r)?;
        let samples = self.geometry.layout.samples();
        let spacing = self.geometry.cell_size_m * (1u64 << tile.key.level) as f64;
        let normal = vertex_normal(&tile.heights, samples, spacing, k % samples, k / samples);
        Some(CutSample {
            height_m: tile.heights[k],
            mask: tile.mask[k],
            normal,
        })
    }

    /// The smallest tile of the cut whose extent holds every one of
    /// `vertices` (grid columns and rows): the tile whose drape a triangle
    /// over them is textured from.
    pub fn tile_holding(&self, vertices: &[(usize, usize)]) -> TileKey {
        let layout = &self.geometry.layout;
        let last = self.across - 1;
        let t = layout.tile_cells;
        let (c, r) = vertices[0];
        let mut key = self.leaf_key((c / t).min(last), (r / t).min(last));
        let top = self.geometry.top().level;
        loop {
            let ([c0, r0, c1, r1], _) = layout.vertices(key);
            let inside = vertices
                .iter()
                .all(|&(c, r)| (c0..=c1).contains(&c) && (r0..=r1).contains(&r));
            if inside || key.level == top {
                return key;
            }
            key = TileKey {
                level: key.level + 1,
                x: key.x / 2,
                y: key.y / 2,
            };
        }
    }
}

impl VertexSource for Cut {
    fn side(&self) -> usize {
        self.geometry.layout.side
    }

    fn cell_size_m(&self) -> f64 {
        self.geometry.cell_size_m
    }

    fn vertex(&self, c: usize, r: usize) -> Option<(f32, [f32; 2])> {
        self.held(c, r)
            .map(|(tile, k)| (tile.heights[k], tile.lp[k]))
    }

    fn index(&self, c: usize, r: usize) -> u32 {
        (r * self.geometry.layout.side + c) as u32
    }
}

/// Choose the cut for `p` among `resident` tiles (which must hold the top
/// tile and every ancestor of a tile they hold): the tiles the camera
/// needs where their children are resident, balanced. Also returns the
/// tiles wanted and missing, coarsest first.
#[allow(clippy::too_many_lines)] // one pass each: split, restrict, gather
fn choose(
    geometry: Geometry,
    resident: &HashMap<TileKey, Arc<LoadedTile>>,
    p: &RefineParams,
) -> (Cut, Vec<TileKey>) {
    let layout = geometry.layout;
    let n = layout.across(0);
    let mut leaf_level = vec![geometry.top().level; n * n];
    let mut wanted = Vec::new();
    let set = |leaf_level: &mut Vec<u32>, key: TileKey, level: u32| {
        let span = 1usize << key.level;
        for ty in key.y * span..(key.y + 1) * span {
            for tx in key.x * span..(key.x + 1) * span {
                leaf_level[ty * n + tx] = level;
            }
        }
    };
    // Split from the top while the camera needs it and the children have arrived.
    let mut stack = vec![geometry.top()];
    while let Some(key) = stack.pop() {
        let Some(tile) = resident.get(&key) else {
            continue;
        };
        if !geometry.needs_finer(tile, p) {
            continue;
        }
        let children = Geometry::children(key);
        let missing: Vec<TileKey> = children
            .into_iter()
            .filter(|c| !resident.contains_key(c))
            .collect();
        if missing.is_empty() {
            set(&mut leaf_level, key, key.level - 1);
            stack.extend(children);
        } else {
            wanted.extend(missing);
        }
    }
    // Restrict: leaves touching each other at most one level apart.
    let mut frozen = HashSet::new();
    loop {
        let mut changed = false;
        for ty in 0..n {
            for tx in 0..n {
                let fine = leaf_level[ty * n + tx];
                for (dx, dy) in EIGHT_NEIGHBOURS {
                    let (ux, uy) = (tx as i64 + dx, ty as i64 + dy);
                    if ux < 0 || uy < 0 || ux >= n as i64 || uy >= n as i64 {
                        continue;
                    }
                    let (ux, uy) = (ux as usize, uy as usize);
                    let coarse = leaf_level[uy * n + ux];
                    if coarse < fine + 2 {
                        continue;
                    }
                    let key = TileKey {
                        level: coarse,
                        x: ux >> coarse,
                        y: uy >> coarse,
                    };
                    let children = Geometry::children(key);
                    if !frozen.contains(&key) && children.iter().all(|c| resident.contains_key(c)) {
                        set(&mut leaf_level, key, coarse - 1);
                    } else {
                        wanted.extend(children.into_iter().filter(|c| !resident.contains_key(c)));
                        let merged = TileKey {
                            level: coarse - 1,
                            x: tx >> (coarse - 1),
                            y: ty >> (coarse - 1),
                        };
                        set(&mut leaf_level, merged, coarse - 1);
                        frozen.insert(merged);
                    }
                    changed = true;
                    break;
                }
            }
        }
        if !changed {
            break;
        }
    }
    let mut tiles = HashMap::new();
    for (i, &level) in leaf_level.iter().enumerate() {
        let mut key = TileKey {
            level,
            x: (i % n) >> level,
            y: (i / n) >> level,
        };
        loop {
            if tiles.contains_key(&key) {
                break;
            }
            if let Some(tile) = resident.get(&key) {
                tiles.insert(key, tile.clone());
            }
            if key.level == geometry.top().level {
                break;
            }
            key = TileKey {
                level: key.level + 1,
                x: key.x / 2,
                y: key.y / 2,
            };
        }
    }
    let leaf_tile = leaf_level
        .iter()
        .enumerate()
        .map(|(i, &level)| {
            let key = TileKey {
                level,
                x: (i % n) >> level,
                y: (i / n) >> level,
            };
            tiles.get(&key).cloned()
        })
        .collect();
    wanted.sort_by_key(|k| (std::cmp::Reverse(k.level), k.y, k.x));
    wanted.dedup();
    (
        Cut {
            geometry,
            tiles,
            leaf_level,
            leaf_tile,
            across: n,
            tile_shift: layout.tile_cells.trailing_zeros(),
        },
        wanted,
    )
}

/// What the paging did, for the HUD and the benchmark.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct PagingStats {
    /// Tiles in memory, and their bytes.
    pub resident: usize,
    pub resident_bytes: usize,
    /// Tiles asked for and not yet arrived.
    pub loading: usize,
    /// Leaves of the last cut, and the finest level among them.
    pub leaves: usize,
    pub finest_level: u32,
    /// Tiles read and dropped since the pyramid was opened.
    pub loaded_total: u64,
    pub evicted_total: u64,
    /// Frames drawn while a tile they wanted was missing.
    pub stalled_frames: u64,
}

/// Requests the loader takes, newest frame's only.
#[derive(Default)]
struct Queue {
    keys: Vec<TileKey>,
    closed: bool,
}

/// A pyramid paged for a camera: the cache, its budget and the loader
/// thread.
pub struct PagedPyramid {
    pub pyramid: Arc<Pyramid>,
    geometry: Geometry,
    budget_bytes: usize,
    resident: HashMap<TileKey, (Arc<LoadedTile>, u64)>,
    loading: HashSet<TileKey>,
    queue: Arc<(Mutex<Queue>, Condvar)>,
    arrived: Receiver<(TileKey, Result<LoadedTile>)>,
    frame: u64,
    stats: PagingStats,
    /// The level of the last cut's leaf over each level-0 tile.
    last_leaf_level: Vec<u32>,
    /// The first tile that could not be read, if any.
    pub error: Option<String>,
}

impl PagedPyramid {
    /// Page `pyramid` within `budget_bytes` of tiles (the cut a camera
    /// needs is kept even above it): the top tile is read now, the rest on
    /// a background thread as frames ask for them.
    pub fn new(pyramid: Pyramid, budget_bytes: usize) -> Result<PagedPyramid> {
        let pyramid = Arc::new(pyramid);
        let geometry = Geometry::of(&pyramid);
        let top = LoadedTile::read(&pyramid, geometry.top())?;
        let queue: Arc<(Mutex<Queue>, Condvar)> = Arc::default();
        let (send, arrived) = channel();
        let (reader, requests) = (pyramid.clone(), queue.clone());
        std::thread::Builder::new()
            .name("relevo tile loader".into())
            .spawn(move || loop {
                let key = {
                    let (lock, wake) = &*requests;
                    let Ok(mut q) = lock.lock() else { return };
                    loop {
                        if q.closed {
                            return;
                        }
                        if !q.keys.is_empty() {
                            break q.keys.remove(0);
                        }
                        q = match wake.wait(q) {
                            Ok(q) => q,
                            Err(_) => return,
                        };
                    }
                };
                if send.send((key, LoadedTile::read(&reader, key))).is_err() {
                    return;
                }
            })
            .map_err(|e| Error::io(&pyramid.dir, e))?;
        let mut resident = HashMap::new();
        let bytes = top.bytes();
        resident.insert(top.key, (Arc::new(top), 0));
        Ok(PagedPyramid {
            pyramid,
            geometry,
            budget_bytes,
            resident,
            loading: HashSet::new(),
            queue,
            arrived,
            frame: 0,
            stats: PagingStats {
                resident: 1,
                resident_bytes: bytes,
                loaded_total: 1,
                ..PagingStats::default()
            },
            last_leaf_level: Vec::new(),
            error: None,
        })
    }

    /// The cut for `p` with what has arrived so far; asks the loader for
    /// the tiles missing (dropping older requests) and evicts the least
    /// recently used tiles above the budget. Never waits.
    pub fn frame(&mut self, p: &RefineParams) -> Cut {
        self.receive();
        self.frame += 1;
        let (cut, wanted) = self.cut(p);
        self.request(&wanted);
        if !wanted.is_empty() {
            self.stats.stalled_frames += 1;
        }
        self.evict(&cut);
        cut
    }

    /// The cut for `p` once every tile it needs has arrived, waiting for
    /// them (a headless render, a test): the same mesh a single grid gives.
    pub fn settled(&mut self, p: &RefineParams) -> Result<Cut> {
        loop {
            self.receive();
            let (cut, wanted) = self.cut(p);
            if let Some(e) = &self.error {
                return Err(Error::Input(e.clone()));
            }
            let wanted: Vec<TileKey> = wanted
                .into_iter()
                .filter(|k| !self.resident.contains_key(k))
                .collect();
            if wanted.is_empty() {
                self.frame += 1;
                self.evict(&cut);
                return Ok(cut);
            }
            self.request(&wanted);
            // Wait for one to arrive.
            match self.arrived.recv() {
                Ok(arrival) => self.accept(arrival),
                Err(_) => {
                    return Err(Error::Input(format!(
                        "{}: the tile loader stopped",
                        self.pyramid.dir.display()
                    )))
                }
            }
        }
    }

    /// Hold at most `bytes` of tiles from the next frame on (beyond those
    /// the view needs).
    pub fn set_budget(&mut self, bytes: usize) {
        self.budget_bytes = bytes;
    }

    /// The paging's figures after the last frame.
    pub fn stats(&self) -> PagingStats {
        self.stats
    }

    /// The level of the last cut's tile over grid vertex (c, r) (columns
    /// and rows of level 0): what the mesh there was refined from.
    pub fn level_at(&self, c: f64, r: f64) -> Option<u32> {
        let last = (self.geometry.layout.side - 1) as f64;
        if !(0.0..=last).contains(&c) || !(0.0..=last).contains(&r) {
            return None;
        }
        let t = self.geometry.layout.tile_cells as f64;
        let n = self.geometry.layout.across(0);
        let (tx, ty) = (((c / t) as usize).min(n - 1), ((r / t) as usize).min(n - 1));
        self.last_leaf_level.get(ty * n + tx).copied()
    }

    fn cut(&mut self, p: &RefineParams) -> (Cut, Vec<TileKey>) {
        let resident: HashMap<TileKey, Arc<LoadedTile>> = self
            .resident
            .iter()
            .map(|(k, (t, _))| (*k, t.clone()))
            .collect();
        let (cut, wanted) = choose(self.geometry, &resident, p);
        for key in cut.tiles.keys() {
            if let Some(entry) = self.resident.get_mut(key) {
                entry.1 = self.frame;
            }
        }
        self.stats.leaves = cut.leaves().len();
        self.last_leaf_level.clone_from(&cut.leaf_level);
        self.stats.finest_level = cut.leaf_level.iter().copied().min().unwrap_or(0);
        (cut, wanted)
    }

    fn receive(&mut self) {
        while let Ok(arrival) = self.arrived.try_recv() {
            self.accept(arrival);
        }
    }

    fn accept(&mut self, (key, tile): (TileKey, Result<LoadedTile>)) {
        self.loading.remove(&key);
        match tile {
            Ok(tile) => {
                self.stats.loaded_total += 1;
                self.resident.insert(key, (Arc::new(tile), self.frame));
            }
            Err(e) => {
                self.error.get_or_insert_with(|| e.to_string());
            }
        }
        self.count();
    }

    fn request(&mut self, wanted: &[TileKey]) {
        if let Ok(mut q) = self.queue.0.lock() {
            // Those asked for earlier and not yet taken are dropped; those
            // being read are not asked for again.
            for key in q.keys.drain(..) {
                self.loading.remove(&key);
            }
            let keys: Vec<TileKey> = wanted
                .iter()
                .copied()
                .filter(|k| !self.resident.contains_key(k) && !self.loading.contains(k))
                .collect();
            self.loading.extend(keys.iter().copied());
            q.keys = keys;
        }
        self.queue.1.notify_one();
        self.count();
    }

    /// Drop the least recently used tiles above the budget: never one of
    /// `cut`, the top, or a tile whose children are resident.
    fn evict(&mut self, cut: &Cut) {
        let top = self.geometry.top();
        let mut bytes: usize = self.resident.values().map(|(t, _)| t.bytes()).sum();
        if bytes > self.budget_bytes {
            let mut candidates: Vec<(u64, TileKey)> = self
                .resident
                .iter()
                .filter(|(k, _)| **k != top && !cut.tiles.contains_key(k))
                .map(|(k, (_, used))| (*used, *k))
                .collect();
            // Finer first among equals, so that children go before parents.
            candidates.sort_by_key(|&(used, k)| (used, k.level));
            for (_, key) in candidates {
                if bytes <= self.budget_bytes {
                    break;
                }
                let has_children = key.level > 0
                    && Geometry::children(key)
                        .iter()
                        .any(|c| self.resident.contains_key(c));
                if has_children {
                    continue;
                }
                if let Some((tile, _)) = self.resident.remove(&key) {
                    bytes -= tile.bytes();
                    self.stats.evicted_total += 1;
                }
            }
        }
        self.count();
    }

    fn count(&mut self) {
        self.stats.resident = self.resident.len();
        self.stats.resident_bytes = self.resident.values().map(|(t, _)| t.bytes()).sum();
        self.stats.loading = self.loading.len();
    }
}

impl Drop for PagedPyramid {
    fn drop(&mut self) {
        if let Ok(mut q) = self.queue.0.lock() {
            q.closed = true;
        }
        self.queue.1.notify_all();
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::bundle::{Crs, GridInfo};
    use crate::grid::HeightGrid;
    use crate::lp::refine::tests::{assert_watertight, cameras, terrains, Terrain};
    use crate::lp::refine::Refiner;
    use crate::pyramid::{write_pyramid, BuildOptions, PyramidDescription, WriteOptions};
    use crate::testdata::Lcg;

    /// `t` as a pyramid of `tile_cells`-cell tiles, written and opened.
    pub(crate) fn pyramid_of(t: &Terrain, tile_cells: usize) -> (tempfile::TempDir, Pyramid) {
        let cell = t.h.cell_size_m;
        let grid = HeightGrid {
            side: t.h.side,
            heights: t.heights.clone(),
            mask: vec![1; t.heights.len()],
            geotransform: crate::geo::GeoTransform::north_up(0.0, 0.0, cell, cell),
        };
        let description = PyramidDescription {
            region: t.name.to_string(),
            crs: Crs {
                wkt: String::new(),
                epsg: None,
            },
            grid: GridInfo::of(&grid, cell, 1.0).unwrap(),
            inputs: Vec::new(),
            parameters: Default::default(),
        };
        let options = WriteOptions {
            tile_cells,
            build: BuildOptions {
                metric: crate::lp::ErrorMetric::default(),
                cell_size_m: cell,
                drape: true,
            },
            force: false,
            resume: false,
        };
        let dir = tempfile::tempdir().unwrap();
        let path = write_pyramid(
            &dir.path().join("p.relevo"),
            &grid,
            description,
            options,
            &|_| {},
        )
        .unwrap();
        let pyramid = Pyramid::open(&path).unwrap();
        (dir, pyramid)
    }

    /// With every tile it needs resident, the cut refines to the single
    /// grid's strip, index for index and height for height: on the four
    /// real crops in tiles of 32 cells (four levels, 85 tiles), for
    /// cameras anywhere, with and without culling and geomorphing.
    #[test]
    fn once_settled_the_cut_refines_to_the_single_grids_strip() {
        let mut refiner = Refiner::new();
        for t in terrains() {
            let (_dir, pyramid) = pyramid_of(&t, 32);
            let mut paged = PagedPyramid::new(pyramid, usize::MAX).unwrap();
            for (k, camera) in cameras(&t, 12, 11).iter().enumerate() {
                for (tau, morph, cull) in [
                    (1.0, None, true),
                    (4.0, Some(8.0), true),
                    (2.0, None, false),
                ] {
                    let p = RefineParams::for_camera(camera, tau, morph, cull);
                    let single = refiner.refine(&t.h, &t.heights, &p).clone();
                    let cut = paged.settled(&p).unwrap();
                    let through_tiles = refiner.refine_source(&cut, &p);
                    assert!(
                        *through_tiles == single,
                        "{} camera {k} τ={tau}: {} entries through the tiles, {} on the grid",
                        t.name,
                        through_tiles.indices.len(),
                        single.indices.len()
                    );
                }
            }
        }
    }

    /// Whatever subset of the tiles has arrived (the top and, below it,
    /// each tile with probability 0.3, 0.6 or 0.9 when its parent has),
    /// the cut's mesh is watertight: no edge used once inside the grid.
    #[test]
    fn cuts_of_whatever_has_arrived_are_crack_free() {
        let mut refiner = Refiner::new();
        let mut rng = Lcg(3);
        for t in terrains().into_iter().take(2) {
            let (_dir, pyramid) = pyramid_of(&t, 16);
            let geometry = Geometry::of(&pyramid);
            let layout = pyramid.layout;
            let mut partial = 0;
            for (k, camera) in cameras(&t, 60, 5).iter().enumerate() {
                let keep = [0.3, 0.6, 0.9][k % 3];
                let mut resident = HashMap::new();
                for level in (0..layout.levels()).rev() {
                    for key in layout.tiles(level) {
                        let parent_here = level + 1 == layout.levels()
                            || resident.contains_key(&TileKey {
                                level: level + 1,
                                x: key.x / 2,
                                y: key.y / 2,
                            });
                        if parent_here && (level + 1 == layout.levels() || rng.next() < keep) {
                            resident
                                .insert(key, Arc::new(LoadedTile::read(&pyramid, key).unwrap()));
                        }
                    }
                }
                let p = RefineParams::for_camera(camera, [0.5, 1.0][k % 2], None, k % 4 < 2);
                let (cut, wanted) = choose(geometry, &resident, &p);
                partial += usize::from(!wanted.is_empty());
                let strip = refiner.refine_source(&cut, &p);
                assert_watertight(strip, layout.side, &format!("{} camera {k}", t.name));
            }
            assert!(
                partial >= 10,
                "{}: only {partial} cuts lacked a tile",
                t.name
            );
        }
    }

    /// A budget of a few tiles: frames never wait, every frame's mesh is
    /// watertight, tiles are evicted and read again, and what stays
    /// resident besides the cut keeps under the budget.
    #[test]
    fn a_small_budget_evicts_and_every_frame_is_drawn() {
        let t = terrains().remove(1);
        let (_dir, pyramid) = pyramid_of(&t, 16);
        let tile_bytes = LoadedTile::read(
            &pyramid,
            TileKey {
                level: 0,
                x: 0,
                y: 0,
            },
        )
        .unwrap()
        .bytes();
        let mut paged = PagedPyramid::new(pyramid, 12 * tile_bytes).unwrap();
        let mut refiner = Refiner::new();
        for (k, camera) in cameras(&t, 40, 9).iter().enumerate() {
            let p = RefineParams::for_camera(camera, 1.0, None, true);
            for _ in 0..3 {
                let cut = paged.frame(&p);
                let strip = refiner.refine_source(&cut, &p);
                assert_watertight(strip, t.h.side, &format!("camera {k}"));
                let cut_bytes: usize = cut.tiles.values().map(|t| t.bytes()).sum();
                assert!(
                    paged.stats().resident_bytes <= (12 * tile_bytes).max(cut_bytes) + cut_bytes
                );
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
        }
        let stats = paged.stats();
        assert!(
            stats.evicted_total > 0 && stats.loaded_total > stats.resident as u64,
            "{stats:?}"
        );
        assert!(stats.stalled_frames > 0, "{stats:?}");
    }
}
