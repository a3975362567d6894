//! Relevo's algorithms and bundle format.
//!
//! This crate knows nothing of GDAL or the GPU: rasters arrive here already
//! decoded into memory, and everything that touches files outside a bundle
//! lives in the `relevo` command-line crate.
//!
//! - [`atomic`]: files written whole or not at all.
//! - [`geo`]: affine geotransforms between grid cells and world coordinates,
//!   and the terrain frame with its named conversions.
//! - [`raster`]: in-memory multiband rasters with no-data, mosaicking,
//!   hole filling and elevation tile encodings.
//! - [`grid`]: the square (2^n+1)² height grid with its data mask.
//! - [`lp`]: the Lindstrom–Pascucci hierarchy, extraction and refinement.
//! - [`objects`]: objects placed on the terrain (GeoJSON placement,
//!   buildings, cables, OBJ models) as triangles to composite.
//! - [`camera`]: the camera shared by the CPU and GPU renderers.
//! - [`horizon`]: the floating-horizon raycaster and its depth buffer.
//! - [`scene`]: cameras in world coordinates, the camera string, the
//!   raycast of a bundle.
//! - [`veg`]: vegetation from imagery: split-and-merge, Haar signatures,
//!   classification from samples, objects, the vegetation database.
//! - [`cluster`]: vegetation clusters — impostors from models, the
//!   quadtree with baked views, atlases, the cut chosen from a camera.
//! - [`tiles3d`]: 3D Tiles 1.1 — terrain and instanced vegetation tiles,
//!   `tileset.json`.
//! - [`gltf`]: binary glTF containers, for meshes and 3D Tiles content.
//! - [`zbuffer`]: the grid as geometry in the seven Z-buffer
//!   representations the floating horizon is compared with.
//! - [`bundle`]: the `NAME.relevo/` directory: manifest, artifacts, their checks.
//! - [`validation`]: a whole bundle checked, clusters included.
//! - [`golden`]: a bundle against a golden record, and two bundles
//!   compared (regression tests of a region's outputs).
//! - [`memory`]: the memory budget every large allocation is checked against.

pub mod atomic;
pub mod bundle;
pub mod camera;
pub mod cluster;
pub mod files;
pub mod geo;
pub mod gltf;
pub mod golden;
pub mod grid;
pub mod horizon;
pub mod lp;
pub mod memory;
pub mod objects;
pub mod pyramid;
pub mod raster;
pub mod scene;
pub mod terrain_tiles;
pub mod tiles3d;
pub mod validation;
pub mod veg;
pub mod zbuffer;

mod error;
#[cfg(test)]
mod testdata;
pub use error::{Error, Result};
