//! Helpers for Relevo's end-to-end tests (`tests/tests/`): where the real
//! inputs are, building bundles through the library in process, and image
//! comparison against reviewed references that leaves `-actual` and
//! `-difference` PNGs beside a failing reference for people to look at.
// Test support: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

pub mod forge;
mod paths;

pub use paths::{repo, repo_root, shared};
use relevo::prep::region::RegionSpec;
use std::path::{Path, PathBuf};

/// Whether the run asked to rewrite golden outputs (`RELEVO_BLESS=1`).
pub fn blessing() -> bool {
    std::env::var_os("RELEVO_BLESS").is_some()
}

/// `relevo prep` in process: the region file at `region` into `out`.
pub fn prep_region(region: &Path, out: &Path) -> PathBuf {
    relevo::ingest::gdalio::init();
    let region = RegionSpec::load(region).unwrap();
    relevo::prep::prep(&region, out, true).unwrap().bundle
}

/// `relevo prep --dem FILE` in process, through a one-line REGION.toml.
pub fn prep_dem(dem: &Path, dir: &Path) -> PathBuf {
    let toml = dir.join("REGION.toml");
    std::fs::write(
        &toml,
        format!("[dem]\nfiles = [{:?}]\n", dem.display().to_string()),
    )
    .unwrap();
    prep_region(&toml, &dir.join("dem.relevo"))
}

/// Decode an RGBA8 PNG.
pub fn decode_png(path: &Path) -> (Vec<u8>, [u32; 2]) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let (rgba, w, h) = relevo_core::raster::png::decode_rgba(&bytes).unwrap();
    (rgba, [w as u32, h as u32])
}

pub use relevo_core::raster::compare::ImageDifference;

/// Compare RGBA8 `actual` (`size`) with the reference PNG `reference`
/// (rewritten when blessing). On a size change or when `accept` refuses the
/// difference, writes `NAME-actual.png` and `NAME-difference.png` beside the
/// reference and panics naming them.
pub fn compare_with_reference(
    actual: &[u8],
    size: [u32; 2],
    reference: &Path,
    threshold: u8,
    accept: impl Fn(&ImageDifference) -> bool,
) -> ImageDifference {
    let encode = |rgba: &[u8]| {
        relevo_core::raster::png::encode_rgba(rgba, size[0] as usize, size[1] as usize).unwrap()
    };
    if blessing() {
        std::fs::create_dir_all(reference.parent().unwrap()).unwrap();
        std::fs::write(reference, encode(actual)).unwrap();
    }
    let (want, want_size) = decode_png(reference);
    let beside = |suffix: &str| {
        let stem = reference.file_stem().unwrap().to_string_lossy();
        reference.with_file_name(format!("{stem}-{suffix}.png"))
    };
    let difference = if want_size == size {
        relevo_core::raster::compare::difference(actual, &want, threshold)
    } else {
        None
    };
    match difference {
        Some(d) if accept(&d) => d,
        _ => {
            std::fs::write(beside("actual"), encode(actual)).unwrap();
            if want_size == size {
                let diff = relevo_core::raster::compare::difference_image(actual, &want);
                std::fs::write(beside("difference"), encode(&diff)).unwrap();
            }
            panic!(
                "{} differs ({difference:?}, size {size:?} vs {want_size:?}); see {} (rerun with RELEVO_BLESS=1 if intended)",
                reference.display(),
                beside("actual").display()
            );
        }
    }
}
