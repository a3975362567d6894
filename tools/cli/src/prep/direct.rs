//! The out-of-core source of a tiled `prep`: a single DEM already on a
//! projected, north-up grid of square cells, whose voids (if any) are all
//! holes the fill stage fills, read window by window through GDAL —
//! nothing the size of the region is ever held. The windows are exactly
//! what the in-memory stages (stitch, fill, square) would give: the file's
//! values scaled, each hole filled from its ring at the raster's positions
//! (the window grown to hold the holes it meets), the square padded right
//! and down with the nearest edge value under a mask of 0.
//!
//! The scan that checks the file finds its voids' connected parts a strip
//! of rows at a time (union–find over labels of one row), keeping each
//! part's size and box. Any other input (several tiles, another CRS or
//! cell size, a void the fill leaves — too large, or open to the edge —
//! an encoding) goes through the in-memory stages.

use super::region::RegionSpec;
use crate::ingest::gdalio::{self, GridSpec};
use anyhow::{bail, Result};
use relevo_core::bundle::{Crs, GridInfo};
use relevo_core::grid::{pow2_plus_1_at_least, Squaring};
use relevo_core::lp::window::Rect;
use relevo_core::pyramid::HeightSource;
use relevo_core::raster::encoding::Encoding;
use relevo_core::raster::fill::fill_holes_at;
use std::path::PathBuf;

/// Rows read at a time when the file is scanned for voids.
const SCAN_ROWS: usize = 256;

/// GDAL's block cache, MB: its default (5 % of the machine's memory) would
/// grow with the machine, not with the work.
const GDAL_CACHE_MB: &str = "64";

/// A DEM read window by window. Each window opens the file anew (GDAL's
/// handles are not shared between threads; an open costs far less than a
/// tile's read), so tiles are read in parallel.
pub struct DirectSource {
    path: PathBuf,
    nodata: Option<f64>,
    z_scale: f64,
    width: usize,
    height: usize,
    max_hole_cells: usize,
    /// The file's holes, each `[c0, r0, c1, r1]` inclusive (set by
    /// [`DirectSource::scan`]); every one is filled.
    holes: Vec<[usize; 4]>,
    pub grid: GridInfo,
    pub crs: Crs,
}

impl DirectSource {
    /// The DEM's own grid (the level-0 grid before it was padded).
    pub fn dem_grid(&self) -> GridSpec {
        GridSpec {
            crs_wkt: self.crs.wkt.clone(),
            geotransform: self.grid.geotransform,
            width: self.width,
            height: self.height,
        }
    }

    /// The region's DEM as a direct source, when it qualifies by its
    /// header (see the module); `None` when the in-memory stages must run.
    /// [`DirectSource::scan`] then reads it once for voids.
    pub fn open(region: &RegionSpec) -> Result<Option<DirectSource>> {
        let r = region;
        if r.dem.files.len() != 1
            || r.dem.encoding != Encoding::Plain
            || r.cell_size_m.is_some()
            || r.grid.squaring != Squaring::Pad
        {
            return Ok(None);
        }
        gdal::config::set_config_option("GDAL_CACHEMAX", GDAL_CACHE_MB)?;
        let source = gdalio::open(&r.dem.files[0])?;
        let (Some(geo), Some(srs)) = (source.geotransform, source.srs.clone()) else {
            return Ok(None);
        };
        let square = geo.is_north_up() && geo.cell_size().0 == geo.cell_size().1;
        let same_crs = match &r.crs {
            Some(def) => crate::ingest::crs::parse(def)? == srs,
            None => true,
        };
        if srs.is_geographic() || !square || !same_crs {
            return Ok(None);
        }
        let nodata = r.dem.src_nodata.map(|n| n.value()).or(source.nodata);
        let (width, height) = (source.width, source.height);
        if width < 2 || height < 2 {
            return Ok(None);
        }
        let side = pow2_plus_1_at_least(width.max(height));
        if side > relevo_core::bundle::MAX_SIDE {
            bail!(
                "the {side}×{side} grid exceeds the largest a bundle holds ({}²)",
                relevo_core::bundle::MAX_SIDE
            );
        }
        let cell = geo.cell_size().0 * srs.linear_units();
        let [x0, y0, x1, y1] = geo.bounds(width, height);
        let grid = GridInfo {
            side,
            geotransform: geo,
            cell_size_m: cell,
            z_scale: r.z_scale,
            valid_extent: [x0, y0, x1, y1],
            // Filled in by the build.
            height_range_m: [0.0, 0.0],
            valid_vertices: 0,
        };
        let crs = Crs {
            wkt: crate::ingest::crs::to_wkt(&srs)?,
            epsg: crate::ingest::crs::epsg(&srs),
        };
        Ok(Some(DirectSource {
            path: source.path.clone(),
            nodata,
            z_scale: r.z_scale,
            width,
            height,
            max_hole_cells: r.fill.max_hole_cells,
            holes: Vec::new(),
            grid,
            crs,
        }))
    }

    /// Read the file once, a strip of rows at a time, finding its voids:
    /// `false` when one is a void the fill stage leaves (the in-memory
    /// stages handle it), an error for absurd heights.
    pub fn scan(&mut self) -> Result<bool> {
        let source = gdalio::open(&self.path)?;
        let name = self.path.display().to_string();
        let mut voids = Voids::new(self.width);
        for row in (0..self.height).step_by(SCAN_ROWS) {
            let rows = SCAN_ROWS.min(self.height - row);
            let mut strip =
                source.read_window(0, row, self.width, rows, Some(&[1]), self.nodata)?;
            strip.data.iter_mut().for_each(|v| *v *= self.z_scale);
            gdalio::check_heights(&strip, &format!("{name} (rows from {row})"))?;
            for (r, values) in strip.data.chunks_exact(self.width).enumerate() {
                voids.row(row + r, self.height, values);
            }
        }
        let holes = voids.parts();
        let left = holes
            .iter()
            .find(|h| h.touches_edge || h.cells > self.max_hole_cells as u64);
        if let Some(h) = left {
            tracing::info!(
                "{name}: a void of {} cells at columns {}–{}, rows {}–{} is not filled \
                 (larger than {} cells, or open to the edge); the grid is built in memory",
                h.cells,
                h.bounds[0],
                h.bounds[2],
                h.bounds[1],
                h.bounds[3],
                self.max_hole_cells
            );
            return Ok(false);
        }
        self.holes = holes.into_iter().map(|h| h.bounds).collect();
        if !self.holes.is_empty() {
            tracing::info!(
                "{name}: {} holes, filled window by window",
                self.holes.len()
            );
        }
        Ok(true)
    }

    /// The holes [`DirectSource::scan`] found, each `[c0, r0, c1, r1]`
    /// inclusive.
    pub fn holes(&self) -> &[[usize; 4]] {
        &self.holes
    }

    /// The source with the holes an earlier scan of the same file found
    /// (a plan's jobs read the file without scanning it again).
    pub fn with_holes(mut self, holes: Vec<[usize; 4]>) -> DirectSource {
        self.holes = holes;
        self
    }

    /// The file's cells a window of `[c0, r0, c1, r1]` (inclusive, inside
    /// the file) must read so that every hole meeting it lies inside with
    /// its ring.
    fn grown(&self, [c0, r0, c1, r1]: [usize; 4]) -> [usize; 4] {
        let mut out = [c0, r0, c1, r1];
        for &[hc0, hr0, hc1, hr1] in &self.holes {
            if hc0 <= c1 && hc1 >= c0 && hr0 <= r1 && hr1 >= r0 {
                out = [
                    out[0].min(hc0.saturating_sub(1)),
                    out[1].min(hr0.saturating_sub(1)),
                    out[2].max((hc1 + 1).min(self.width - 1)),
                    out[3].max((hr1 + 1).min(self.height - 1)),
                ];
            }
        }
        out
    }
}

/// A void part as the scan finds it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Part {
    cells: u64,
    /// `[c0, r0, c1, r1]`, inclusive.
    bounds: [usize; 4],
    touches_edge: bool,
}

/// The 4-connected parts of a raster's voids, found a row at a time: each
/// void cell takes its left or upper neighbour's label, labels that meet
/// are joined (union–find), and each label's root keeps its part's size,
/// box and whether it touches the raster's edge.
struct Voids {
    width: usize,
    /// Per column, the label of the row above (`NONE` where it has data).
    above: Vec<u32>,
    parent: Vec<u32>,
    parts: Vec<Part>,
}

const NONE: u32 = u32::MAX;

impl Voids {
    fn new(width: usize) -> Voids {
        Voids {
            width,
            above: vec![NONE; width],
            parent: Vec::new(),
            parts: Vec::new(),
        }
    }

    fn root(&mut self, mut l: u32) -> u32 {
        while self.parent[l as usize] != l {
            let up = self.parent[self.parent[l as usize] as usize];
            self.parent[l as usize] = up;
            l = up;
        }
        l
    }

    fn join(&mut self, a: u32, b: u32) -> u32 {
        let (a, b) = (self.root(a), self.root(b));
        if a == b {
            return a;
        }
        let (keep, gone) = if a < b { (a, b) } else { (b, a) };
        self.parent[gone as usize] = keep;
        let (k, g) = (self.parts[keep as usize], self.parts[gone as usize]);
        self.parts[keep as usize] = Part {
            cells: k.cells + g.cells,
            bounds: [
                k.bounds[0].min(g.bounds[0]),
                k.bounds[1].min(g.bounds[1]),
                k.bounds[2].max(g.bounds[2]),
                k.bounds[3].max(g.bounds[3]),
            ],
            touches_edge: k.touches_edge || g.touches_edge,
        };
        keep
    }

    /// Row `r` (of `height`) with its values (NaN: void).
    fn row(&mut self, r: usize, height: usize, values: &[f64]) {
        let mut left = NONE;
        for (c, v) in values.iter().enumerate() {
            if !v.is_nan() {
                self.above[c] = NONE;
                left = NONE;
                continue;
            }
            let label = match (left, self.above[c]) {
                (NONE, NONE) => {
                    let l = self.parent.len() as u32;
                    self.parent.push(l);
                    self.parts.push(Part {
                        cells: 0,
                        bounds: [c, r, c, r],
                        touches_edge: false,
                    });
                    l
                }
                (NONE, up) => self.root(up),
                (l, NONE) => l,
                (l, up) => self.join(l, up),
            };
            let p = &mut self.parts[label as usize];
            p.cells += 1;
            p.bounds = [
                p.bounds[0].min(c),
                p.bounds[1].min(r),
                p.bounds[2].max(c),
                p.bounds[3].max(r),
            ];
            p.touches_edge |= c == 0 || r == 0 || c + 1 == self.width || r + 1 == height;
            self.above[c] = label;
            left = label;
        }
    }

    /// Every part, in the order its first cell comes.
    fn parts(mut self) -> Vec<Part> {
        let mut out = Vec::new();
        for l in 0..self.parent.len() as u32 {
            if self.root(l) == l {
                out.push(self.parts[l as usize]);
            }
        }
        out
    }
}

impl HeightSource for DirectSource {
    fn window(&self, rect: Rect) -> relevo_core::Result<(Vec<f32>, Vec<u8>)> {
        // The file's cells the window reads, edges repeated beyond it,
        // grown to hold the holes it meets with their rings.
        let clamp_c = |c: usize| c.min(self.width - 1);
        let clamp_r = |r: usize| r.min(self.height - 1);
        let inside = [
            clamp_c(rect.c0),
            clamp_r(rect.r0),
            clamp_c(rect.c0 + rect.width - 1),
            clamp_r(rect.r0 + rect.height - 1),
        ];
        let [c0, r0, c1, r1] = self.grown(inside);
        let (w, h) = (c1 - c0 + 1, r1 - r0 + 1);
        relevo_core::memory::check(
            &format!("a {w}×{h} window of {}", self.path.display()),
            (w * h) as u64,
            8,
            "prepare the region with a smaller [fill] max_hole_cells",
        )?;
        let mut raster = gdalio::open(&self.path)
            .and_then(|source| source.read_window(c0, r0, w, h, Some(&[1]), self.nodata))
            .map_err(|e| relevo_core::Error::Input(format!("{e:#}")))?;
        raster.data.iter_mut().for_each(|v| *v *= self.z_scale);
        if !self.holes.is_empty() {
            fill_holes_at(&mut raster.data, w, h, self.max_hole_cells, [c0, r0]);
        }
        let mut heights = Vec::with_capacity(rect.len());
        let mut mask = Vec::with_capacity(rect.len());
        for r in rect.r0..rect.r0 + rect.height {
            for c in rect.c0..rect.c0 + rect.width {
                let v = raster.data[(clamp_r(r) - r0) * w + (clamp_c(c) - c0)];
                heights.push(v as f32);
                mask.push(u8::from(r < self.height && c < self.width));
            }
        }
        Ok((heights, mask))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scan's parts on a small raster: sizes, boxes and edges, parts
    /// that meet only further down (a U), and a diagonal that does not
    /// join (4-connected).
    #[test]
    fn voids_are_found_a_row_at_a_time() {
        let rows = [
            "..........",
            ".X...X.X..",
            ".X...X.X..",
            ".....XXX..",
            "........X.",
            "X........X",
        ];
        let mut voids = Voids::new(10);
        for (r, row) in rows.iter().enumerate() {
            let values: Vec<f64> = row
                .chars()
                .map(|ch| if ch == 'X' { f64::NAN } else { 1.0 })
                .collect();
            voids.row(r, rows.len(), &values);
        }
        let parts = voids.parts();
        let summary: Vec<(u64, [usize; 4], bool)> = parts
            .iter()
            .map(|p| (p.cells, p.bounds, p.touches_edge))
            .collect();
        assert_eq!(
            summary,
            vec![
                (2, [1, 1, 1, 2], false),
                (7, [5, 1, 7, 3], false),
                (1, [8, 4, 8, 4], false),
                (1, [0, 5, 0, 5], true),
                (1, [9, 5, 9, 5], true),
            ]
        );
    }
}
