//! Real bundles rendered by the raycaster in process: depth against the
//! exact surface, and snapshots against reviewed references.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use relevo_core::bundle::Bundle;
use relevo_core::horizon::{distance_of_depth, pick, DistanceBand, RenderOptions, Terrain};
use relevo_core::scene::{self, camera, View};
use relevo_tests::{compare_with_reference, prep_dem, prep_region, repo, shared};
use std::path::{Path, PathBuf};

/// A bundle of a shared DEM or of a region file of this repository.
fn bundle_of(input: &str, dir: &Path) -> PathBuf {
    if input.ends_with(".toml") {
        prep_region(&repo(input), &dir.join("b.relevo"))
    } else {
        prep_dem(&shared(input), dir)
    }
}

#[test]
fn depth_of_a_real_bundle_matches_the_exact_surface() {
    let d = tempfile::tempdir().unwrap();
    let b = Bundle::open(&bundle_of("dem/srtm_ref.tif", d.path())).unwrap();
    let view = View::home(&b.manifest.grid, [240, 135]);
    let options = RenderOptions {
        bands: vec![DistanceBand {
            until_m: f64::INFINITY,
            slices_per_cell: 8.0,
            subvoxel: true,
        }],
        ..RenderOptions::default()
    };
    let frame = scene::render_bundle(&b, &view, &options, None)
        .unwrap()
        .to_rows();
    let heights = b.heights().unwrap();
    let mask = b.mask().unwrap();
    let tf = b.frame();
    let color = b.drape().unwrap().and_then(|d| d.color_source(&tf));
    let terrain = Terrain::new(tf.side, tf.cell_size_m, &heights, &mask, color);
    let cam = camera(&tf, &view).unwrap();
    let spacing = tf.cell_size_m / 8.0;
    let (mut errors, mut disagree) = (Vec::new(), 0);
    for py in 0..135 {
        for px in 0..240 {
            let dv = frame.depth[py * 240 + px];
            match (dv < 1.0, pick(&terrain, &cam, px as f64, py as f64)) {
                (true, Some(s)) => {
                    errors.push((distance_of_depth(&cam, dv as f64) - s).abs() / spacing);
                }
                (false, None) => {}
                _ => disagree += 1,
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    let (median, p95) = (errors[errors.len() / 2], errors[errors.len() * 95 / 100]);
    eprintln!("srtm_ref: depth vs exact surface median {median:.3}, p95 {p95:.3} slice spacings; {disagree} of {} pixels disagree on terrain/sky", 240 * 135);
    assert!(errors.len() > 20_000, "{} terrain pixels", errors.len());
    assert!(median <= 1.0 && p95 <= 2.0, "median {median}, p95 {p95}");
    assert!(disagree * 100 < 240 * 135, "{disagree} pixels disagree");
}

/// Snapshots: at most 0.5 % of pixels off by more than 16 levels in any
/// channel, and a mean difference under 1 level.
#[test]
fn renders_of_real_bundles_match_their_references() {
    let d = tempfile::tempdir().unwrap();
    let bands = "3000:4:sub,inf:1";
    for (name, input, bands, prefilter, hillshade) in [
        ("olinda", "data/olinda/REGION.toml", None, false, None),
        (
            "olinda_bands",
            "data/olinda/REGION.toml",
            Some(bands),
            true,
            Some([315.0, 40.0]),
        ),
        (
            "srtm_ref",
            "dem/srtm_ref.tif",
            None,
            false,
            Some([315.0, 40.0]),
        ),
    ] {
        let dir = d.path().join(name);
        std::fs::create_dir_all(&dir).unwrap();
        let b = Bundle::open(&bundle_of(input, &dir)).unwrap();
        let view = View::home(&b.manifest.grid, [320, 180]);
        let bands = bands.map(|t| scene::parse_bands(t).unwrap());
        let options = scene::with_bands(
            RenderOptions {
                prefilter,
                ..RenderOptions::default()
            },
            bands,
        )
        .unwrap();
        let frame = scene::render_bundle(&b, &view, &options, hillshade)
            .unwrap()
            .to_rows();
        let rgba = frame.rgba_bytes();
        let reference = repo(&format!("data/golden/renders/{name}.png"));
        compare_with_reference(rgba, [320, 180], &reference, 16, |d| {
            d.pixels_off * 200 <= 320 * 180 && d.mean < 1.0
        });
        // Terrain and sky are both in view.
        let sky = rgba
            .chunks(4)
            .filter(|p| p == &[135, 170, 215, 255])
            .count();
        assert!(sky > 0 && sky < 320 * 180, "{name}: {sky} sky pixels");
    }
}
