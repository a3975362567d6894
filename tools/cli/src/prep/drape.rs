//! A pyramid's drape from imagery (`prep --tiled` with `[image]`): each
//! tile's samples warped from the image through GDAL, a pixel a vertex at
//! the tile's level — each sample the imagery over the square of its
//! level's cell, averaged where that cell holds several image pixels —
//! stretched to 8 bits with one set of per-band ranges for the whole
//! region, so tiles and levels agree where they meet. The image is read
//! tile by tile (GDAL picks its overviews for coarse levels when it has
//! them), never whole.

use super::region::ImageSection;
use crate::ingest::gdalio::{self, GridSpec, Resampling};
use anyhow::{bail, Result};
use gdal::raster::GdalDataType;
use relevo_core::geo::GeoTransform;
use relevo_core::pyramid::{DrapeSource, TileKey, TileLayout};
use relevo_core::raster::stretch::{stretch_or_default, stretch_ranges, to_rgba8_in};
use std::path::PathBuf;

/// Most pixels a side of the view the stretch's percentiles are taken
/// from.
const STRETCH_VIEW_PX: usize = 2048;

/// The imagery of a region, sampled tile by tile.
pub struct ImageryDrape {
    path: PathBuf,
    /// Source bands shown as red, green, blue (1-based).
    bands: [usize; 3],
    /// The values of each of `bands` mapped to 0 and 255.
    ranges: Vec<(f64, f64)>,
    src_nodata: Option<f64>,
    /// The image's own resampling (finer cells than its pixels).
    resampling: Resampling,
    /// The image's pixel, metres (0 when unknown: every level averages).
    pixel: f64,
    crs_wkt: String,
    /// Metres in a unit of the grid's CRS.
    metres_per_unit: f64,
    /// The level-0 grid's georeferencing, a pixel a vertex.
    grid: GeoTransform,
    layout: TileLayout,
}

impl ImageryDrape {
    /// The imagery of `image` (one file; a VRT for many) over the level-0
    /// grid `grid` (cells `cell_size_m`) of `layout`, which squares the DEM
    /// whose own grid is `dem`: its stretch taken from a view of the DEM's
    /// extent at most [`STRETCH_VIEW_PX`] a side.
    pub fn open(
        image: &ImageSection,
        dem: &GridSpec,
        grid: GeoTransform,
        cell_size_m: f64,
        layout: TileLayout,
    ) -> Result<ImageryDrape> {
        let [path] = image.files.as_slice() else {
            bail!(
                "a tiled bundle reads its imagery as one file, tile by tile; [image] names {} \
                 files: make one VRT of them (gdalbuildvrt imagery.vrt FILES…) and name it",
                image.files.len()
            );
        };
        let source = gdalio::open(path)?;
        let bands = match image.bands {
            Some(b) => b,
            None if source.bands < 3 => [1, 1, 1],
            None => [1, 2, 3],
        };
        if let Some(b) = bands.iter().find(|&&b| b == 0 || b > source.bands) {
            bail!(
                "{}: has no band {b} (bands are 1..={})",
                path.display(),
                source.bands
            );
        }
        let Some(own) = source.geotransform else {
            bail!("{}: not georeferenced", path.display());
        };
        let src_nodata = image.src_nodata.map(|n| n.value());
        // The image's pixel in metres (a projected image's own; a
        // geographic one's unknown here, so every level averages).
        let pixel = match &source.srs {
            Some(srs) if !srs.is_geographic() => {
                let (w, h) = own.cell_size();
                w.abs().min(h.abs()) * srs.linear_units()
            }
            _ => 0.0,
        };
        // The stretch of the whole region, from one view of it at the
        // image's own pixel (as a single grid's drape is stretched), or
        // sampled more coarsely when that is more than STRETCH_VIEW_PX a
        // side: sampled, not averaged, so that the values keep their spread.
        let metres_per_unit = cell_size_m / grid.cell_size().0.abs();
        let [x0, y0, x1, y1] = dem.geotransform.bounds(dem.width, dem.height);
        let longest = (x1 - x0).max(y1 - y0);
        let view_pixel = (pixel / metres_per_unit).max(longest / STRETCH_VIEW_PX as f64);
        let size = |span: f64| (span / view_pixel).ceil().max(1.0) as usize;
        let spec = GridSpec {
            crs_wkt: dem.crs_wkt.clone(),
            geotransform: GeoTransform([x0, view_pixel, 0.0, y1, 0.0, -view_pixel]),
            width: size(x1 - x0),
            height: size(y1 - y0),
        };
        let raster = gdalio::warp(&source.dataset, path, &spec, image.resampling, src_nodata)?;
        let chosen = raster.select_bands(&bands);
        let eight_bit = source.band_type == GdalDataType::UInt8;
        let ranges = stretch_ranges(&chosen, stretch_or_default(image.stretch, eight_bit));
        Ok(ImageryDrape {
            path: path.clone(),
            bands,
            ranges,
            src_nodata,
            resampling: image.resampling,
            pixel,
            crs_wkt: dem.crs_wkt.clone(),
            metres_per_unit,
            grid,
            layout,
        })
    }
}

impl DrapeSource for ImageryDrape {
    fn tile_drape(&self, key: TileKey) -> relevo_core::Result<Vec<u8>> {
        let failed = |e: anyhow::Error| relevo_core::Error::Input(format!("{e:#}"));
        let samples = self.layout.samples();
        let geotransform = self.layout.tile_geotransform(&self.grid, key);
        let spec = GridSpec {
            crs_wkt: self.crs_wkt.clone(),
            geotransform,
            width: samples,
            height: samples,
        };
        // Cells larger than the image's pixels average them.
        let cell = geotransform.cell_size().0.abs() * self.metres_per_unit;
        let resampling = if cell > self.pixel {
            Resampling::Average
        } else {
            self.resampling
        };
        // GDAL datasets are not shared between threads: one a tile.
        let source = gdalio::open(&self.path).map_err(failed)?;
        let raster = gdalio::warp(
            &source.dataset,
            &self.path,
            &spec,
            resampling,
            self.src_nodata,
        )
        .map_err(failed)?;
        let chosen = raster.select_bands(&self.bands);
        Ok(to_rgba8_in(&chosen, &self.ranges))
    }
}
