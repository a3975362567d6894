//! Split-and-merge segmentation (Horowitz & Pavlidis; as presented by Pitas,
//! "Digital Image Processing Algorithms", and used by Savelli & Seixas): split
//! the image as a quadtree while a block is not homogeneous, then merge
//! adjacent regions while their union stays homogeneous.
//!
//! The homogeneity predicate is per channel of the opponent colour space of
//! [`super::opponent`]: a region is homogeneous when the standard deviation of
//! its brightness is at most `brightness_std` and that of every chroma channel
//! at most `chroma_std` (both in 8-bit band units).
//!
//! Implementation: the quadtree is rooted on the image padded to a power of
//! two; blocks are clipped to the image and empty ones dropped, so any size
//! works. The image is split in 64×64 tiles in parallel, each with its own
//! bottom-up pyramid of moments, then a pyramid over tile moments decides the
//! blocks above tile size. Merging visits the region adjacency graph's edges
//! in order of increasing mean difference and joins with union–find; ties are
//! broken by leaf index, so the result is the same on any number of threads.

use super::{Image, MAX_BANDS};
use crate::{Error, Result};
use rayon::prelude::*;

/// Side of the tiles split in parallel (a power of two).
pub(crate) const TILE: usize = 64;
const TILE_LEVELS: usize = TILE.trailing_zeros() as usize + 1;

/// How many edges ahead the joins ask for the leaves they will read.
const PREFETCH_EDGES: usize = 16;

/// Thresholds of the homogeneity predicate and of the final clean-up.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SegmentParams {
    /// Largest standard deviation of brightness in a region (band units).
    pub brightness_std: f32,
    /// Largest standard deviation of each chroma channel (band units).
    pub chroma_std: f32,
    /// Regions of fewer pixels join their most similar neighbour.
    pub min_region_px: u32,
    /// Side of the smallest block the split makes (a power of two, ≤ 64):
    /// blocks this small are leaves whatever their content.
    pub min_block_px: u32,
}

impl Default for SegmentParams {
    fn default() -> Self {
        SegmentParams {
            brightness_std: 28.0,
            chroma_std: 6.0,
            min_region_px: 16,
            min_block_px: 2,
        }
    }
}

impl SegmentParams {
    pub fn check(&self) -> Result<()> {
        let ok = |v: f32| v.is_finite() && v >= 0.0;
        if !ok(self.brightness_std) || !ok(self.chroma_std) {
            return Err(Error::Input(format!(
                "segmentation thresholds must be finite and ≥ 0 (brightness {}, chroma {})",
                self.brightness_std, self.chroma_std
            )));
        }
        if !(self.min_block_px.is_power_of_two() && self.min_block_px as usize <= TILE) {
            return Err(Error::Input(format!(
                "the smallest block must be a power of two up to {TILE} pixels, got {}",
                self.min_block_px
            )));
        }
        Ok(())
    }
}

/// One region of a segmentation.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Area in pixels.
    pub pixels: u32,
    /// Bounding box `[x0, y0, x1, y1)` in pixels.
    pub bbox: [u32; 4],
    /// Centre of mass in pixel coordinates (pixel `i` spans `[i, i+1)`).
    pub centroid: [f32; 2],
    /// Mean and standard deviation per opponent channel.
    pub mean: [f32; MAX_BANDS],
    pub std: [f32; MAX_BANDS],
}

/// Regions partitioning an image.
#[derive(Debug, Clone)]
pub struct Segmentation {
    pub width: usize,
    pub height: usize,
    /// Region index of every pixel, row-major.
    pub labels: Vec<u32>,
    pub regions: Vec<Segment>,
    /// Quadtree leaves before merging.
    pub leaves: usize,
    /// Where the time went.
    pub steps: SegmentSteps,
}

/// Wall time of each phase of [`segment`], in milliseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct SegmentSteps {
    /// Splitting the tiles, the levels above them, gathering and painting leaves.
    pub split_ms: f64,
    /// Finding adjacent leaves, weighting and sorting the edges.
    pub adjacency_ms: f64,
    /// Joining regions whose union stays homogeneous (union–find).
    pub merge_ms: f64,
    /// Joining regions smaller than the minimum to a neighbour.
    pub small_regions_ms: f64,
    /// Numbering and describing the regions.
    pub describe_ms: f64,
}

impl SegmentSteps {
    /// Add another segmentation's times (tiles of one image).
    pub fn add(&mut self, other: &SegmentSteps) {
        self.split_ms += other.split_ms;
        self.adjacency_ms += other.adjacency_ms;
        self.merge_ms += other.merge_ms;
        self.small_regions_ms += other.small_regions_ms;
        self.describe_ms += other.describe_ms;
    }
}

/// Count, sums and sums of squares of the `N` opponent channels of some
/// pixels: as many channels as the image has bands, so that the arrays of
/// them (a leaf's, a region's) hold nothing unused — 56 bytes for RGB.
#[derive(Debug, Clone, Copy)]
#[repr(C)]
struct Moments<const N: usize> {
    n: f64,
    sum: [f64; N],
    sumsq: [f64; N],
}

impl<const N: usize> Default for Moments<N> {
    fn default() -> Self {
        Moments {
            n: 0.0,
            sum: [0.0; N],
            sumsq: [0.0; N],
        }
    }
}

// SAFETY: `Moments` is `repr(C)` and all `f64`: no padding, and any bits
// are some value (zeros are the empty moments).
unsafe impl<const N: usize> bytemuck::Zeroable for Moments<N> {}
// SAFETY: as above; `Copy` and `'static`.
unsafe impl<const N: usize> bytemuck::Pod for Moments<N> {}

impl<const N: usize> Moments<N> {
    fn pixel(colour: [f32; MAX_BANDS]) -> Moments<N> {
        let mut m = Moments {
            n: 1.0,
            ..Default::default()
        };
        for (c, &v) in colour[..N].iter().enumerate() {
            let v = v as f64;
            m.sum[c] = v;
            m.sumsq[c] = v * v;
        }
        m
    }

    fn add(&mut self, other: &Moments<N>) {
        self.n += other.n;
        for c in 0..N {
            self.sum[c] += other.sum[c];
            self.sumsq[c] += other.sumsq[c];
        }
    }

    fn joined(mut self, other: &Moments<N>) -> Moments<N> {
        self.add(other);
        self
    }

    fn mean(&self, c: usize) -> f64 {
        self.sum[c] / self.n
    }

    fn variance(&self, c: usize) -> f64 {
        (self.sumsq[c] / self.n - self.mean(c).powi(2)).max(0.0)
    }
}

/// The homogeneity predicate: variance per channel within its limit
/// (brightness, then chroma for every other channel).
struct Predicate {
    /// Pyramid level of the smallest block (log2 of its side).
    min_level: usize,
    limit_variance: [f64; MAX_BANDS],
    /// 1 / limit std per channel: weights of the mean difference between regions.
    inverse_std: [f64; MAX_BANDS],
}

impl Predicate {
    fn new(params: &SegmentParams) -> Predicate {
        let mut limit_variance = [0.0; MAX_BANDS];
        let mut inverse_std = [0.0; MAX_BANDS];
        for c in 0..MAX_BANDS {
            let limit = if c == 0 {
                params.brightness_std
            } else {
                params.chroma_std
            } as f64;
            limit_variance[c] = limit * limit;
            inverse_std[c] = 1.0 / limit.max(0.5);
        }
        Predicate {
            min_level: params.min_block_px.trailing_zeros() as usize,
            limit_variance,
            inverse_std,
        }
    }

    fn homogeneous<const N: usize>(&self, m: &Moments<N>) -> bool {
        (0..N).all(|c| m.variance(c) <= self.limit_variance[c] + 1e-9)
    }

    /// Squared distance between region means in units of the thresholds.
    fn difference<const N: usize>(&self, a: &Moments<N>, b: &Moments<N>) -> f32 {
        (0..N)
            .map(|c| ((a.mean(c) - b.mean(c)) * self.inverse_std[c]).powi(2))
            .sum::<f64>() as f32
    }
}

/// A quadtree leaf: a homogeneous block clipped to the image.
#[derive(Debug, Clone, Copy)]
struct Leaf {
    x: u32,
    y: u32,
    w: u32,
    h: u32,
}

/// What splitting one tile gives.
struct TileSplit<const N: usize> {
    moments: Moments<N>,
    leaves: Vec<Leaf>,
    leaf_moments: Vec<Moments<N>>,
}

/// Which leaves cover a tile after the coarse levels are decided.
#[derive(Clone, Copy)]
enum TileCover {
    /// The tile's own leaves, `start..end` in the global list.
    Own(u32, u32),
    /// One leaf larger than a tile covers it.
    Coarse(u32),
}

/// Working arrays one segmentation after another reuses: the leaves, their
/// moments, the sorted edges (together about 20 bytes a pixel) and, when
/// handed back, an earlier segmentation's labels. A worker that segments
/// tile after tile keeps one, so their memory is mapped once rather than
/// for every tile.
#[derive(Default)]
pub struct SegmentBuffers {
    leaves: Vec<Leaf>,
    /// The leaves' moments as their `f64` values (their channel count is
    /// the image's).
    moments: Vec<f64>,
    edges: Vec<Edge>,
    labels: Vec<u32>,
}

impl SegmentBuffers {
    /// Hand back a segmentation's labels once read: the next segmentation
    /// numbers its pixels in them.
    pub fn reuse_labels(&mut self, labels: Vec<u32>) {
        self.labels = labels;
    }

    /// The moments' array, emptied, for `N` channels (a new one when it
    /// last held another count, whose size may not divide it).
    fn take_moments<const N: usize>(&mut self) -> Vec<Moments<N>> {
        let mut values = std::mem::take(&mut self.moments);
        values.clear();
        bytemuck::allocation::try_cast_vec(values).unwrap_or_default()
    }

    /// Keep the moments' array for the next segmentation.
    fn keep_moments<const N: usize>(&mut self, moments: Vec<Moments<N>>) {
        self.moments = bytemuck::allocation::try_cast_vec(moments).unwrap_or_default();
    }
}

/// Split-and-merge `image` into homogeneous 4-connected regions. `buffers`
/// may hold an earlier segmentation's working arrays, to be reused.
pub fn segment(
    image: &Image,
    params: &SegmentParams,
    buffers: &mut SegmentBuffers,
) -> Result<Segmentation> {
    params.check()?;
    // One body per channel count, so the moments hold no unused channel.
    with_band_count!(image.bands, N => segment_channels::<N>(image, params, buffers))
}

/// [`segment`] of an image of `N` channels.
fn segment_channels<const N: usize>(
    image: &Image,
    params: &SegmentParams,
    buffers: &mut SegmentBuffers,
) -> Result<Segmentation> {
    let predicate = Predicate::new(params);
    let (w, h) = (image.width, image.height);
    let mut clock = std::time::Instant::now();
    let mut lap = || {
        let ms = clock.elapsed().as_secs_f64() * 1e3;
        clock = std::time::Instant::now();
        ms
    };

    let mut leaves = std::mem::take(&mut buffers.leaves);
    let mut leaf_moments = buffers.take_moments::<N>();
    let mut labels = split(
        image,
        &predicate,
        &mut leaves,
        &mut leaf_moments,
        std::mem::take(&mut buffers.labels),
    );
    let split_ms = lap();

    // Merge along the region adjacency graph.
    // The edges come in (a, b) order, so a stable sort by difference
    // alone orders them by (difference, a, b).
    let edges = sort_by_difference(
        adjacency(&leaves, &leaf_moments, &labels, w, h, &predicate),
        std::mem::take(&mut buffers.edges),
    );
    let adjacency_ms = lap();
    let mut sets = DisjointSets::new(leaf_moments);
    sets.join_along(
        &edges,
        |_, _| true,
        |x, y| predicate.homogeneous(&x.joined(y)),
    );
    let merge_ms = lap();
    // Regions still too small join their most similar neighbour. This needs
    // only pixel counts: a compact forest over the merged regions keeps the
    // joins cache-friendly. Sets only grow, so an edge between two regions
    // that were both large at the start is passed over before its leaves'
    // sets are looked up; a byte a leaf says which, so that test stays in
    // cache.
    let min = params.min_region_px;
    let merged = sets.roots();
    let moments = sets.data;
    let mut small = DisjointSets {
        parent: merged.clone(),
        data: moments.iter().map(|m| m.n as u32).collect(),
    };
    let in_small: Vec<bool> = merged
        .par_iter()
        .map(|&r| small.data[r as usize] < min)
        .collect();
    small.join_along(
        &edges,
        |a, b| in_small[a as usize] || in_small[b as usize],
        |x, y| *x < min || *y < min,
    );
    let small_regions_ms = lap();

    // Number regions in leaf order and describe them; their moments are the
    // sums of the merged regions they hold, in index order.
    let mut region_of_root = vec![u32::MAX; leaves.len()];
    let mut region_of_leaf = Vec::with_capacity(leaves.len());
    let mut region_count = 0;
    for leaf in 0..leaves.len() as u32 {
        let root = small.find(leaf) as usize;
        if region_of_root[root] == u32::MAX {
            region_of_root[root] = region_count;
            region_count += 1;
        }
        region_of_leaf.push(region_of_root[root]);
    }
    let mut region_moments = vec![Moments::<N>::default(); region_count as usize];
    for (k, m) in moments.iter().enumerate() {
        if merged[k] == k as u32 {
            region_moments[region_of_leaf[k] as usize].add(m);
        }
    }
    labels
        .par_iter_mut()
        .for_each(|l| *l = region_of_leaf[*l as usize]);
    let mut regions: Vec<Segment> = region_moments
        .iter()
        .map(|m| {
            let mut mean = [0.0; MAX_BANDS];
            let mut std = [0.0; MAX_BANDS];
            for c in 0..image.bands {
                mean[c] = m.mean(c) as f32;
                std[c] = m.variance(c).sqrt() as f32;
            }
            Segment {
                pixels: 0,
                bbox: [u32::MAX, u32::MAX, 0, 0],
                centroid: [0.0; 2],
                mean,
                std,
            }
        })
        .collect();
    let mut centre_sums = vec![[0.0f64; 2]; regions.len()];
    for (leaf, &r) in leaves.iter().zip(&region_of_leaf) {
        let region = &mut regions[r as usize];
        let area = (leaf.w * leaf.h) as f64;
        region.pixels += leaf.w * leaf.h;
        region.bbox[0] = region.bbox[0].min(leaf.x);
        region.bbox[1] = region.bbox[1].min(leaf.y);
        region.bbox[2] = region.bbox[2].max(leaf.x + leaf.w);
        region.bbox[3] = region.bbox[3].max(leaf.y + leaf.h);
        let sums = &mut centre_sums[r as usize];
        sums[0] += area * (leaf.x as f64 + leaf.w as f64 / 2.0);
        sums[1] += area * (leaf.y as f64 + leaf.h as f64 / 2.0);
    }
    for (region, sums) in regions.iter_mut().zip(&centre_sums) {
        let n = region.pixels as f64;
        region.centroid = [(sums[0] / n) as f32, (sums[1] / n) as f32];
    }
    buffers.leaves = leaves;
    buffers.keep_moments(moments);
    buffers.edges = edges;
    let steps = SegmentSteps {
        split_ms,
        adjacency_ms,
        merge_ms,
        small_regions_ms,
        describe_ms: lap(),
    };
    Ok(Segmentation {
        width: w,
        height: h,
        labels,
        regions,
        leaves: buffers.leaves.len(),
        steps,
    })
}

/// Split `image` into quadtree leaves: every tile in parallel, then the
/// levels above tile size. Fills `leaves` (in depth-first order) and their
/// `moments`; returns the leaf index of every pixel, in `labels` (whatever
/// it held).
fn split<const N: usize>(
    image: &Image,
    predicate: &Predicate,
    leaves: &mut Vec<Leaf>,
    moments: &mut Vec<Moments<N>>,
    labels: Vec<u32>,
) -> Vec<u32> {
    let (w, h) = (image.width, image.height);
    let tiles_x = w.div_ceil(TILE);
    let tiles_y = h.div_ceil(TILE);
    let tiles: Vec<TileSplit<N>> = (0..tiles_x * tiles_y)
        .into_par_iter()
        .map_init(TileScratch::new, |scratch, t| {
            scratch.split(image, predicate, (t % tiles_x) * TILE, (t / tiles_x) * TILE)
        })
        .collect();
    let cover = split_coarse(&tiles, tiles_x, tiles_y, w, h, predicate, leaves, moments);
    drop(tiles);
    paint(leaves, &cover, tiles_x, w, h, labels)
}

/// Per-thread buffers for splitting one tile: the moments pyramid.
struct TileScratch<const N: usize> {
    levels: Vec<Vec<Moments<N>>>,
}

impl<const N: usize> TileScratch<N> {
    fn new() -> TileScratch<N> {
        TileScratch {
            levels: (0..TILE_LEVELS)
                .map(|k| vec![Moments::default(); (TILE >> k) * (TILE >> k)])
                .collect(),
        }
    }

    /// Split the tile whose top-left pixel is `(x0, y0)`.
    fn split(
        &mut self,
        image: &Image,
        predicate: &Predicate,
        x0: usize,
        y0: usize,
    ) -> TileSplit<N> {
        let (tw, th) = (TILE.min(image.width - x0), TILE.min(image.height - y0));
        let pixel = |x: usize, y: usize| {
            if x < tw && y < th {
                Moments::pixel(image.colour(x0 + x, y0 + y))
            } else {
                Moments::default()
            }
        };
        // Blocks of one pixel are never leaves when the smallest block is
        // larger: then the 2×2 level is summed straight from the pixels, in
        // the order the levels above sum their children.
        let first = if predicate.min_level >= 1 {
            let side = TILE / 2;
            for y in 0..side {
                for x in 0..side {
                    let at = |dx: usize, dy: usize| pixel(2 * x + dx, 2 * y + dy);
                    self.levels[1][y * side + x] = at(0, 0)
                        .joined(&at(1, 0))
                        .joined(&at(0, 1))
                        .joined(&at(1, 1));
                }
            }
            2
        } else {
            for y in 0..TILE {
                for x in 0..TILE {
                    self.levels[0][y * TILE + x] = pixel(x, y);
                }
            }
            1
        };
        for k in first..TILE_LEVELS {
            let (lower, upper) = self.levels.split_at_mut(k);
            let (child, parent) = (&lower[k - 1], &mut upper[0]);
            let side = TILE >> k;
            for y in 0..side {
                for x in 0..side {
                    let at = |dx: usize, dy: usize| &child[(2 * y + dy) * 2 * side + 2 * x + dx];
                    parent[y * side + x] =
                        at(0, 0).joined(at(1, 0)).joined(at(0, 1)).joined(at(1, 1));
                }
            }
        }
        let mut out = TileSplit {
            moments: self.levels[TILE_LEVELS - 1][0],
            leaves: Vec::new(),
            leaf_moments: Vec::new(),
        };
        self.emit(predicate, TILE_LEVELS - 1, 0, 0, (x0, y0, tw, th), &mut out);
        out
    }

    /// Top-down: a block is a leaf when homogeneous (or a single pixel).
    fn emit(
        &self,
        predicate: &Predicate,
        level: usize,
        bx: usize,
        by: usize,
        tile: (usize, usize, usize, usize),
        out: &mut TileSplit<N>,
    ) {
        let m = &self.levels[level][by * (TILE >> level) + bx];
        if m.n == 0.0 {
            return;
        }
        if level <= predicate.min_level || predicate.homogeneous(m) {
            let size = 1 << level;
            let (x, y) = (bx * size, by * size);
            out.leaves.push(Leaf {
                x: (tile.0 + x) as u32,
                y: (tile.1 + y) as u32,
                w: size.min(tile.2 - x) as u32,
                h: size.min(tile.3 - y) as u32,
            });
            out.leaf_moments.push(*m);
            return;
        }
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            self.emit(predicate, level - 1, 2 * bx + dx, 2 * by + dy, tile, out);
        }
    }
}

/// Decide the quadtree levels above tile size and gather every leaf in
/// traversal order into `leaves` and `moments` (emptied first); returns the
/// leaves covering each tile.
#[allow(clippy::too_many_arguments)]
fn split_coarse<const N: usize>(
    tiles: &[TileSplit<N>],
    tiles_x: usize,
    tiles_y: usize,
    width: usize,
    height: usize,
    predicate: &Predicate,
    leaves: &mut Vec<Leaf>,
    moments: &mut Vec<Moments<N>>,
) -> Vec<TileCover> {
    let side = tiles_x.max(tiles_y).next_power_of_two();
    let mut levels = vec![vec![Moments::default(); side * side]];
    for ty in 0..tiles_y {
        for tx in 0..tiles_x {
            levels[0][ty * side + tx] = tiles[ty * tiles_x + tx].moments;
        }
    }
    while let Some(child) = levels.last().filter(|level| level.len() > 1) {
        let s = (child.len() as f64).sqrt() as usize / 2;
        let parent: Vec<Moments<N>> = (0..s * s)
            .map(|i| {
                let (x, y) = (i % s, i / s);
                let at = |dx: usize, dy: usize| &child[(2 * y + dy) * 2 * s + 2 * x + dx];
                at(0, 0).joined(at(1, 0)).joined(at(0, 1)).joined(at(1, 1))
            })
            .collect();
        levels.push(parent);
    }
    let most: usize = tiles.iter().map(|t| t.leaves.len()).sum();
    leaves.clear();
    leaves.reserve(most);
    moments.clear();
    moments.reserve(most);
    let mut cover = vec![TileCover::Own(0, 0); tiles_x * tiles_y];
    let mut stack = vec![(levels.len() - 1, 0usize, 0usize)];
    while let Some((level, bx, by)) = stack.pop() {
        let m = &levels[level][by * (side >> level) + bx];
        if m.n == 0.0 {
            continue;
        }
        if level == 0 {
            let t = by * tiles_x + bx;
            let start = leaves.len() as u32;
            leaves.extend_from_slice(&tiles[t].leaves);
            moments.extend_from_slice(&tiles[t].leaf_moments);
            cover[t] = TileCover::Own(start, leaves.len() as u32);
        } else if predicate.homogeneous(m) {
            let id = leaves.len() as u32;
            let size = TILE << level;
            let (x, y) = (bx * size, by * size);
            leaves.push(Leaf {
                x: x as u32,
                y: y as u32,
                w: size.min(width - x) as u32,
                h: size.min(height - y) as u32,
            });
            moments.push(*m);
            let tiles_per = 1 << level;
            for ty in by * tiles_per..((by + 1) * tiles_per).min(tiles_y) {
                for tx in bx * tiles_per..((bx + 1) * tiles_per).min(tiles_x) {
                    cover[ty * tiles_x + tx] = TileCover::Coarse(id);
                }
            }
        } else {
            // Reverse Z order on the stack so blocks pop in Z order.
            for (dx, dy) in [(1, 1), (0, 1), (1, 0), (0, 0)] {
                stack.push((level - 1, 2 * bx + dx, 2 * by + dy));
            }
        }
    }
    cover
}

/// The leaf index of every pixel, in `labels` (whatever it held).
fn paint(
    leaves: &[Leaf],
    cover: &[TileCover],
    tiles_x: usize,
    w: usize,
    h: usize,
    mut labels: Vec<u32>,
) -> Vec<u32> {
    labels.clear();
    labels.resize(w * h, 0);
    labels
        .par_chunks_mut(TILE * w)
        .enumerate()
        .for_each(|(ty, band)| {
            let y0 = ty * TILE;
            let rows = band.len() / w;
            let mut fill = |leaf: &Leaf, id: u32| {
                let ys =
                    (leaf.y as usize).max(y0)..(leaf.y as usize + leaf.h as usize).min(y0 + rows);
                for y in ys {
                    let row = &mut band[(y - y0) * w..(y - y0 + 1) * w];
                    row[leaf.x as usize..(leaf.x + leaf.w) as usize].fill(id);
                }
            };
            for tx in 0..tiles_x {
                match cover[ty * tiles_x + tx] {
                    TileCover::Own(start, end) => {
                        for id in start..end {
                            fill(&leaves[id as usize], id);
                        }
                    }
                    TileCover::Coarse(id) => {
                        let leaf = &leaves[id as usize];
                        let x0 = tx * TILE;
                        let part = Leaf {
                            x: x0 as u32,
                            y: leaf.y,
                            w: TILE.min(w - x0) as u32,
                            h: leaf.h,
                        };
                        fill(&part, id);
                    }
                }
            }
        });
    labels
}

/// An adjacency edge: the bits of the two leaves' [`Predicate::difference`]
/// (a non-negative f32, so ordered as the value), and the leaves `a < b`.
type Edge = (u32, u32, u32);

/// Leaves in a part of the adjacency search, found in parallel.
const ADJACENCY_PART: usize = 4096;

/// The edges between 4-adjacent leaves, found along each leaf's right and
/// bottom borders (runs of one neighbour along a border give one edge), in
/// parts of [`ADJACENCY_PART`] leaves. In part order they come sorted by
/// `(a, b)`: leaves are numbered in the quadtree's depth-first (Z) order,
/// and a leaf's right or bottom neighbour always comes later in it (the two
/// lie in the left and right, or top and bottom, children of their smallest
/// common block), so `a` is the leaf whose border was walked; each leaf's
/// own edges are sorted by `b`.
fn adjacency<const N: usize>(
    leaves: &[Leaf],
    moments: &[Moments<N>],
    labels: &[u32],
    w: usize,
    h: usize,
    predicate: &Predicate,
) -> Vec<Vec<Edge>> {
    leaves
        .par_chunks(ADJACENCY_PART)
        .enumerate()
        .map(|(part, part_leaves)| {
            // About two and a half edges a leaf: room for three, so the part
            // rarely grows.
            let mut edges = Vec::with_capacity(3 * part_leaves.len());
            for (k, leaf) in part_leaves.iter().enumerate() {
                let id = part * ADJACENCY_PART + k;
                let first = edges.len();
                let mut push = |other: u32, last: &mut u32| {
                    if other != *last {
                        *last = other;
                        let difference =
                            predicate.difference(&moments[id], &moments[other as usize]);
                        edges.push((difference.to_bits(), id as u32, other));
                    }
                };
                let (x1, y1) = ((leaf.x + leaf.w) as usize, (leaf.y + leaf.h) as usize);
                if x1 < w {
                    let mut last = u32::MAX;
                    for y in leaf.y as usize..y1 {
                        push(labels[y * w + x1], &mut last);
                    }
                }
                if y1 < h {
                    let mut last = u32::MAX;
                    for x in leaf.x as usize..x1 {
                        push(labels[y1 * w + x], &mut last);
                    }
                }
                edges[first..].sort_unstable_by_key(|e| e.2);
            }
            edges
        })
        .collect()
}

/// Top bits of a difference's key that [`sort_by_difference`] first
/// buckets by: 4096 buckets, whose write positions stay in cache.
const BUCKET_BITS: u32 = 12;

/// The edges of all `parts`, in part order, sorted stably by difference.
/// One counting pass scatters them to buckets of their key's top
/// [`BUCKET_BITS`] bits (keeping their order), then each bucket is sorted
/// stably by the whole key, in L2 cache (on real imagery the differences
/// fill about 170 buckets of some 40 000 edges each: the top bits are the
/// float's exponent and three mantissa bits): the same order as a stable
/// sort of the parts joined, with two passes over them all in memory
/// where one radix sort of the whole array makes four, and no copy to join
/// them first. The result goes in `sorted`, whatever it held.
fn sort_by_difference(parts: Vec<Vec<Edge>>, mut sorted: Vec<Edge>) -> Vec<Edge> {
    let bucket = |e: &Edge| (e.0 >> (32 - BUCKET_BITS)) as usize;
    let edges = || parts.iter().flatten();
    let mut next = vec![0usize; 1 << BUCKET_BITS];
    for e in edges() {
        next[bucket(e)] += 1;
    }
    let mut start = 0;
    for slot in next.iter_mut() {
        let size = *slot;
        *slot = start;
        start += size;
    }
    sorted.clear();
    sorted.resize(start, (0, 0, 0));
    for e in edges() {
        let at = &mut next[bucket(e)];
        sorted[*at] = *e;
        *at += 1;
    }
    drop(parts);
    // `next` now holds each bucket's end.
    let mut start = 0;
    for &end in &next {
        let part = &mut sorted[start..end];
        if part.len() > 1024 {
            radsort::sort_by_key(part, |e| e.0);
        } else {
            part.sort_by_key(|e| e.0);
        }
        start = end;
    }
    sorted
}

/// What a set carries at its root: its size in pixels and how two combine.
trait SetData: Copy + Send + Sync {
    fn pixels(&self) -> f64;
    fn joined(&self, other: &Self) -> Self;
}

impl<const N: usize> SetData for Moments<N> {
    fn pixels(&self) -> f64 {
        self.n
    }
    fn joined(&self, other: &Self) -> Self {
        Moments::joined(*self, other)
    }
}

/// A bare pixel count, for joins that need no statistics.
impl SetData for u32 {
    fn pixels(&self) -> f64 {
        *self as f64
    }
    fn joined(&self, other: &Self) -> Self {
        self + other
    }
}

/// Union–find over leaves, keeping each set's data at its root.
struct DisjointSets<T> {
    parent: Vec<u32>,
    data: Vec<T>,
}

impl<T: SetData> DisjointSets<T> {
    fn new(data: Vec<T>) -> DisjointSets<T> {
        DisjointSets {
            parent: (0..data.len() as u32).collect(),
            data,
        }
    }

    /// The root of every element (in parallel, without path compression).
    fn roots(&self) -> Vec<u32> {
        (0..self.parent.len() as u32)
            .into_par_iter()
            .map(|mut x| {
                while self.parent[x as usize] != x {
                    x = self.parent[x as usize];
                }
                x
            })
            .collect()
    }

    /// Join along the `edges` `(_, a, b)` that `take` keeps, in order, where
    /// `accept` takes the two sets' data. The edges are sorted by
    /// difference, so their leaves lie all over the sets: each join asks the
    /// cache early for the leaves of the edge [`PREFETCH_EDGES`] ahead.
    fn join_along(
        &mut self,
        edges: &[Edge],
        take: impl Fn(u32, u32) -> bool,
        accept: impl Fn(&T, &T) -> bool,
    ) {
        for (k, &(_, a, b)) in edges.iter().enumerate() {
            if let Some(&(_, next_a, next_b)) = edges.get(k + PREFETCH_EDGES) {
                self.prefetch(next_a);
                self.prefetch(next_b);
            }
            if take(a, b) {
                self.union_if(a, b, &accept);
            }
        }
    }

    /// Ask the cache for `x`'s parent and data (both ends of it: moments
    /// mostly straddle two cache lines).
    fn prefetch(&self, x: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let x = x as usize;
            if x < self.parent.len() {
                // SAFETY: SSE is part of x86_64, and a prefetch only hints
                // (it never faults); the pointers are in bounds anyway.
                unsafe {
                    _mm_prefetch::<_MM_HINT_T0>(self.parent[x..].as_ptr().cast());
                    let data: *const i8 = self.data[x..].as_ptr().cast();
                    _mm_prefetch::<_MM_HINT_T0>(data);
                    _mm_prefetch::<_MM_HINT_T0>(data.wrapping_add(size_of::<T>() - 1));
                }
            }
        }
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grand = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grand;
            x = grand;
        }
        x
    }

    /// Join the sets of `a` and `b` when `accept` takes their data.
    fn union_if(&mut self, a: u32, b: u32, accept: impl Fn(&T, &T) -> bool) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return;
        }
        let (da, db) = (&self.data[ra as usize], &self.data[rb as usize]);
        if !accept(da, db) {
            return;
        }
        let joined = da.joined(db);
        // The larger set keeps its root; ties keep the lower index.
        let (na, nb) = (
            self.data[ra as usize].pixels(),
            self.data[rb as usize].pixels(),
        );
        let (root, child) = if na > nb || (na == nb && ra < rb) {
            (ra, rb)
        } else {
            (rb, ra)
        };
        self.parent[child as usize] = root;
        self.data[root as usize] = joined;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pseudo-random noise of amplitude `noise` over blocks of given colours.
    fn blocks(width: usize, height: usize, noise: u8) -> Image {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut pixels = Vec::with_capacity(width * height * 3);
        for y in 0..height {
            for x in 0..width {
                let base: [u8; 3] = match (x * 3 / width, y * 2 / height) {
                    (0, _) => [40, 120, 40],
                    (1, 0) => [200, 200, 200],
                    _ => [90, 60, 30],
                };
                for b in base {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    let jitter = if noise == 0 {
                        0
                    } else {
                        (state % noise as u64) as u8
                    };
                    pixels.push(b.saturating_add(jitter));
                }
            }
        }
        Image::new(width, height, 3, pixels).unwrap()
    }

    /// Every region is 4-connected, its stored area and bounding box match
    /// its pixels, and labels cover the image.
    pub(crate) fn assert_partition(s: &Segmentation) {
        let (w, h) = (s.width, s.height);
        assert_eq!(s.labels.len(), w * h);
        let mut area = vec![0u32; s.regions.len()];
        let mut first = vec![usize::MAX; s.regions.len()];
        for (i, &l) in s.labels.iter().enumerate() {
            area[l as usize] += 1;
            first[l as usize] = first[l as usize].min(i);
            let r = &s.regions[l as usize];
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            assert!(r.bbox[0] <= x && x < r.bbox[2] && r.bbox[1] <= y && y < r.bbox[3]);
        }
        for (k, r) in s.regions.iter().enumerate() {
            assert_eq!(r.pixels, area[k], "region {k} area");
            // Flood fill from its first pixel reaches all of it.
            let mut seen = vec![false; w * h];
            let mut stack = vec![first[k]];
            seen[first[k]] = true;
            let mut reached = 0;
            while let Some(i) = stack.pop() {
                reached += 1;
                for j in crate::grid::neighbours4(i, w, h) {
                    if !seen[j] && s.labels[j] == k as u32 {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
            assert_eq!(reached, r.pixels, "region {k} is not 4-connected");
        }
    }

    #[test]
    fn flat_blocks_become_one_region_each_on_odd_sizes() {
        for (w, h) in [(131, 77), (64, 64), (1, 1), (200, 3), (300, 260)] {
            let image = blocks(w, h, 0);
            let params = SegmentParams {
                min_region_px: 1,
                min_block_px: 1,
                ..Default::default()
            };
            let s = segment(&image, &params, &mut SegmentBuffers::default()).unwrap();
            assert_partition(&s);
            let distinct = if w >= 3 && h >= 2 { 3 } else { s.regions.len() };
            assert_eq!(s.regions.len(), distinct, "{w}×{h}");
        }
    }

    #[test]
    fn noisy_blocks_are_partitioned_and_homogeneous() {
        let image = blocks(257, 190, 10);
        let params = SegmentParams {
            min_region_px: 1,
            ..Default::default()
        };
        let s = segment(&image, &params, &mut SegmentBuffers::default()).unwrap();
        assert_partition(&s);
        // Uniform noise of 0..10 per band (chroma std ≈ 2.9) stays within the
        // thresholds: three regions.
        assert_eq!(s.regions.len(), 3);
        for r in &s.regions {
            assert!(r.std[0] <= params.brightness_std && r.std[1] <= params.chroma_std);
        }
        // A tight threshold makes many regions, still a partition.
        let tight = SegmentParams {
            brightness_std: 2.0,
            chroma_std: 1.0,
            min_region_px: 4,
            min_block_px: 1,
        };
        let s = segment(&image, &tight, &mut SegmentBuffers::default()).unwrap();
        assert!(s.regions.len() > 3);
        assert_partition(&s);
        assert!(s.regions.iter().all(|r| r.pixels >= 4));
    }

    #[test]
    fn same_result_on_any_number_of_threads() {
        let image = blocks(300, 200, 60);
        let params = SegmentParams::default();
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| segment(&image, &params, &mut SegmentBuffers::default()).unwrap())
        };
        let (a, b) = (run(1), run(3));
        assert_eq!(a.labels, b.labels);
        assert_eq!(a.regions, b.regions);
    }

    #[test]
    fn real_aerial_image_is_partitioned_into_connected_regions() {
        let image = crate::testdata::soap_061();
        for min_block_px in [1, 2, 8] {
            let params = SegmentParams {
                min_block_px,
                ..Default::default()
            };
            let s = segment(&image, &params, &mut SegmentBuffers::default()).unwrap();
            assert_partition(&s);
            assert!(s.regions.len() < s.leaves, "merging joined nothing");
            assert!(s.regions.iter().all(|r| r.pixels >= params.min_region_px));
        }
    }

    /// Buffers reused from other segmentations (larger and smaller images,
    /// of one to four bands), with their labels handed back, give what
    /// fresh ones give.
    #[test]
    fn reused_buffers_give_the_same_segmentation() {
        let params = SegmentParams::default();
        let mut buffers = SegmentBuffers::default();
        // The same image with its bands picked or repeated: the moments'
        // array passes between channel counts.
        let with_bands = |image: &Image, picked: &[usize]| {
            let pixels = image
                .pixels
                .chunks_exact(image.bands)
                .flat_map(|px| picked.iter().map(|&b| px[b]))
                .collect();
            Image::new(image.width, image.height, picked.len(), pixels).unwrap()
        };
        let soap = crate::testdata::soap_061();
        for image in [
            soap.clone(),
            blocks(300, 200, 60),
            with_bands(&soap, &[1]),
            with_bands(&soap, &[0, 1, 2, 1]),
            soap.clone(),
            with_bands(&soap, &[2, 0]),
        ] {
            let reused = segment(&image, &params, &mut buffers).unwrap();
            let fresh = segment(&image, &params, &mut SegmentBuffers::default()).unwrap();
            assert_eq!(reused.labels, fresh.labels);
            assert_eq!(reused.regions, fresh.regions);
            assert_eq!(reused.leaves, fresh.leaves);
            buffers.reuse_labels(reused.labels);
        }
    }

    /// The number of leaves `image` splits into and the adjacency parts of
    /// its leaves.
    fn leaves_and_edges(image: &Image, params: &SegmentParams) -> (usize, Vec<Vec<Edge>>) {
        let predicate = Predicate::new(params);
        let (mut leaves, mut moments) = (Vec::new(), Vec::<Moments<3>>::new());
        let labels = split(image, &predicate, &mut leaves, &mut moments, Vec::new());
        let (w, h) = (image.width, image.height);
        let parts = adjacency(&leaves, &moments, &labels, w, h, &predicate);
        (leaves.len(), parts)
    }

    /// The adjacency pairs of a real image's quadtree come in strictly
    /// increasing `(a, b)` order with `a` the earlier leaf, which the stable
    /// sort by difference relies on for its tie order.
    #[test]
    fn adjacent_pairs_come_in_leaf_order() {
        let image = crate::testdata::soap_061();
        for min_block_px in [1, 2, 8] {
            let params = SegmentParams {
                min_block_px,
                ..Default::default()
            };
            let (leaves, parts) = leaves_and_edges(&image, &params);
            let edges: Vec<Edge> = parts.concat();
            assert!(edges.len() > leaves, "{} edges", edges.len());
            assert!(edges.iter().all(|e| e.1 < e.2));
            assert!(edges
                .windows(2)
                .all(|p| (p[0].1, p[0].2) < (p[1].1, p[1].2)));
        }
    }

    /// The bucketed sort gives a stable sort's order: on a real image's
    /// edges with their differences, and on keys crowded into one bucket
    /// (past the size sorted by radix) with many ties.
    #[test]
    fn edges_sort_as_a_stable_sort_by_difference() {
        let image = crate::testdata::soap_061();
        let (_, real) = leaves_and_edges(&image, &SegmentParams::default());
        assert!(real.len() > 1, "one part only");
        let crowded: Vec<Edge> = (0..5000u32)
            .map(|i| (0x3f80_0000 | (i * 7919 % 61), i, i * 3))
            .collect();
        let crowded = crowded.chunks(1700).map(<[Edge]>::to_vec).collect();
        for parts in [real, crowded] {
            let mut want = parts.concat();
            want.sort_by_key(|e| e.0);
            // The output buffer's earlier content does not matter.
            assert_eq!(sort_by_difference(parts, vec![(1, 2, 3); 7]), want);
        }
    }

    #[test]
    fn bad_parameters_are_refused() {
        let image = blocks(8, 8, 0);
        for params in [
            SegmentParams {
                brightness_std: f32::NAN,
                ..Default::default()
            },
            SegmentParams {
                min_block_px: 3,
                ..Default::default()
            },
        ] {
            assert!(segment(&image, &params, &mut SegmentBuffers::default()).is_err());
        }
    }
}
