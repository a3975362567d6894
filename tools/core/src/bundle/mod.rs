//! The bundle: a directory `NAME.relevo/` holding `manifest.json` and the
//! artifacts it lists. See `docs/formats.md` for the specification.
//!
//! Writing goes through [`BundleWriter`], which builds everything in a
//! sibling staging directory and renames it into place only when complete,
//! so a reader never sees half a bundle, and holds the bundle's
//! [`BundleLock`] meanwhile, so that two writers never interleave. Reading maps arrays into memory
//! without copying.

mod files;
mod hash;
mod lock;
mod manifest;
pub mod names;
mod reader;
mod staging;
mod validate;
mod writer;

pub use files::{BundleFiles, StagedFiles};
pub use hash::{sha256_bytes, sha256_file};
pub use lock::{lock_path, BundleLock};
pub use manifest::{
    Artifact, ColorInfo, Crs, Dtype, GridInfo, InputFile, Manifest, StageTiming, FORMAT,
    FORMAT_VERSION,
};
pub use names::MANIFEST_FILE;
pub(crate) use reader::check_files_stay_inside;
pub use reader::{Array, Bundle, Drape, LpArray, MAX_IMAGE_SIDE, MAX_SIDE};
pub use staging::{
    format_of, is_bundle, staging_path, Leftover, Staging, PLAN_MARK, PYRAMID_FORMAT,
};
pub use validate::validate_artifacts;
pub use writer::{write_terrain_bundle, BundleWriter, Description};
