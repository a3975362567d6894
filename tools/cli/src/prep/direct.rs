//! The out-of-core source of a tiled `prep`: a single DEM already on a
//! projected, north-up grid of square cells, without voids, read window by
//! window through GDAL — nothing the size of the region is ever held. The
//! windows are exactly what the in-memory stages (stitch, fill, square)
//! would give: the file's values scaled, the square padded right and down
//! with the nearest edge value under a mask of 0.
//!
//! Any other input (several tiles, another CRS or cell size, voids to fill,
//! an encoding) goes through the in-memory stages.

use super::region::RegionSpec;
use crate::ingest::gdalio;
use anyhow::{bail, Result};
use relevo_core::bundle::{Crs, GridInfo};
use relevo_core::grid::{pow2_plus_1_at_least, Squaring};
use relevo_core::lp::window::Rect;
use relevo_core::pyramid::HeightSource;
use relevo_core::raster::encoding::Encoding;
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
    pub grid: GridInfo,
    pub crs: Crs,
}

impl DirectSource {
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
            grid,
            crs,
        }))
    }

    /// Read the file once, a strip of rows at a time: `false` when it has
    /// voids (the in-memory stages fill them), an error for absurd heights.
    pub fn scan(&self) -> Result<bool> {
        let source = gdalio::open(&self.path)?;
        let name = self.path.display().to_string();
        for row in (0..self.height).step_by(SCAN_ROWS) {
            let rows = SCAN_ROWS.min(self.height - row);
            let mut strip =
                source.read_window(0, row, self.width, rows, Some(&[1]), self.nodata)?;
            if strip.data.iter().any(|v| v.is_nan()) {
                tracing::info!("{name}: has voids; the grid is built in memory");
                return Ok(false);
            }
            strip.data.iter_mut().for_each(|v| *v *= self.z_scale);
            gdalio::check_heights(&strip, &format!("{name} (rows from {row})"))?;
        }
        Ok(true)
    }
}

impl HeightSource for DirectSource {
    fn window(&self, rect: Rect) -> relevo_core::Result<(Vec<f32>, Vec<u8>)> {
        // The file's cells the window reads, edges repeated beyond it.
        let clamp_c = |c: usize| c.min(self.width - 1);
        let clamp_r = |r: usize| r.min(self.height - 1);
        let (c0, c1) = (clamp_c(rect.c0), clamp_c(rect.c0 + rect.width - 1));
        let (r0, r1) = (clamp_r(rect.r0), clamp_r(rect.r0 + rect.height - 1));
        let (w, h) = (c1 - c0 + 1, r1 - r0 + 1);
        let raster = gdalio::open(&self.path)
            .and_then(|source| source.read_window(c0, r0, w, h, Some(&[1]), self.nodata))
            .map_err(|e| relevo_core::Error::Input(format!("{e:#}")))?;
        let mut heights = Vec::with_capacity(rect.len());
        let mut mask = Vec::with_capacity(rect.len());
        for r in rect.r0..rect.r0 + rect.height {
            for c in rect.c0..rect.c0 + rect.width {
                let v = raster.data[(clamp_r(r) - r0) * w + (clamp_c(c) - c0)] * self.z_scale;
                heights.push(v as f32);
                mask.push(u8::from(r < self.height && c < self.width));
            }
        }
        Ok((heights, mask))
    }
}
