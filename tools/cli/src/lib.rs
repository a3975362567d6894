//! The `relevo` command-line tools: GDAL ingest and the bundle pipeline.
//! `main.rs` only parses arguments and calls [`cli::run`].

pub mod bench;
pub mod cli;
pub mod crs;
pub mod gdalio;
pub mod mesh;
pub mod prep;
pub mod progress;
pub mod region;
pub mod render;
pub mod stitch;
pub mod veg;
