//! Ingest through GDAL: opening, reading, warping and writing rasters
//! ([`gdalio`]), coordinate reference systems ([`crs`]) and stitching tiles
//! onto one grid ([`stitch`]). The only part of Relevo that links GDAL,
//! together with the vegetation exports in `veg_io`.

pub mod crs;
pub mod gdalio;
pub mod stitch;
