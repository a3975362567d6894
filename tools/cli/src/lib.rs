//! The `relevo` command-line tools: GDAL ingest, the `prep` pipeline and one
//! module per subcommand. `main.rs` only parses arguments and calls
//! [`commands::run`]. Every algorithm these call is in `relevo_core`; this
//! crate turns files into its inputs and its results into files.
//!
//! - [`commands`]: the argument tree, the dispatch, one file per subcommand.
//! - [`ingest`]: GDAL reading, warping and writing; CRSs; stitching tiles.
//! - [`prep`]: the stage list that builds a bundle, and REGION.toml.
//! - [`clusters`]: baking clusters with progress, and their report.
//! - [`veg_io`]: vegetation inputs and exports through GDAL.
//! - [`output`]: the existing-output check and atomic writes every writer uses.
//! - [`progress`]: progress bars.

pub mod clusters;
pub mod commands;
pub mod ingest;
pub mod output;
pub mod plan;
pub mod prep;
pub mod progress;
pub mod terrain_export;
pub mod veg_io;
pub mod veg_plan;
