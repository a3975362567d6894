//! The sample region from raw inputs to a bundle, in process: artifact
//! hashes against `data/golden/`, the grid and the drape as recorded.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use relevo_core::bundle::BundleFiles;
use relevo_core::bundle::{sha256_file, Bundle};
use relevo_core::validation::validate;
use relevo_tests::{blessing, prep_region, repo};
use std::collections::BTreeMap;

/// Artifact hashes recomputed from the files (not trusted from the
/// manifest), compared with the golden file `golden` (rewritten when
/// blessing, after a reviewed change).
fn assert_golden_hashes(bundle: &Bundle, golden: &str) {
    let hashes: BTreeMap<String, String> = bundle
        .manifest
        .artifacts
        .iter()
        .map(|(name, a)| {
            (
                name.clone(),
                sha256_file(&bundle.dir.join(&a.file)).unwrap().1,
            )
        })
        .collect();
    let golden_path = repo(golden);
    if blessing() {
        std::fs::write(
            &golden_path,
            serde_json::to_string_pretty(&hashes).unwrap() + "\n",
        )
        .unwrap();
    }
    let want: BTreeMap<String, String> =
        serde_json::from_str(&std::fs::read_to_string(&golden_path).unwrap()).unwrap();
    assert_eq!(
        hashes, want,
        "bundle differs from {golden}; if intended, rerun with RELEVO_BLESS=1"
    );
}

/// Rebuild the sample region and compare with `data/golden/`. Set
/// RELEVO_BLESS=1 to rewrite the golden file after a reviewed change.
#[test]
fn sample_bundle_matches_golden_hashes() {
    let d = tempfile::tempdir().unwrap();
    let out = prep_region(
        &repo("data/olinda/REGION.toml"),
        &d.path().join("olinda.relevo"),
    );
    let bundle = Bundle::open(&out).unwrap();
    assert_eq!(validate(&bundle), Vec::<String>::new());
    assert_golden_hashes(&bundle, "data/golden/olinda.json");

    let m = &bundle.manifest;
    assert_eq!(m.grid.side, 129);
    assert_eq!(m.grid.valid_vertices, 111 * 111);
    assert_eq!(m.color.as_ref().map(|c| c.bands), Some([3, 2, 1]));
    assert_eq!(m.inputs.len(), 2, "the DEM and the image");
    let heights = bundle.heights().unwrap();
    // The DEM is already on the bundle grid: its heights are copied exactly.
    let source = relevo::ingest::gdalio::open(&repo("data/olinda/olinda_dem_utm25s.tif"))
        .unwrap()
        .read(None)
        .unwrap();
    for r in 0..111 {
        for c in 0..111 {
            assert_eq!(
                heights[r * 129 + c] as f64,
                source.band(0)[r * 111 + c],
                "({c}, {r})"
            );
        }
    }
    // Padding replicates the last real row and column.
    for r in 0..129 {
        for c in 111..129 {
            assert_eq!(heights[r * 129 + c], heights[r.min(110) * 129 + 110]);
        }
    }
    // The vegetation database lies on the drape (validate checks the rest).
    let objects = bundle.vegetation().unwrap().unwrap();
    assert!(objects.len() > 10_000, "{} objects", objects.len());
}

/// The second sample region: the Copernicus DEM of Grenoble reprojected to
/// UTM, draped with the tint and hillshade derived from its heights.
#[test]
fn grenoble_bundle_with_a_terrain_drape_matches_golden_hashes() {
    let d = tempfile::tempdir().unwrap();
    let out = prep_region(
        &repo("data/grenoble/REGION.toml"),
        &d.path().join("grenoble.relevo"),
    );
    let bundle = Bundle::open(&out).unwrap();
    assert_eq!(validate(&bundle), Vec::<String>::new());
    assert_golden_hashes(&bundle, "data/golden/grenoble.json");
    let m = &bundle.manifest;
    assert_eq!(m.crs.epsg, Some(32631), "UTM 31N");
    let color = m.color.as_ref().unwrap();
    assert_eq!(
        (color.width, color.height, color.bands),
        (m.grid.side, m.grid.side, [0, 0, 0])
    );
    // Snow on the summits, green in the valleys, nothing on the padding.
    let (rgba, mask, heights) = (
        bundle.drape().unwrap().unwrap().rgba,
        bundle.mask().unwrap(),
        bundle.heights().unwrap(),
    );
    let highest = (0..heights.len())
        .filter(|&i| mask[i] == 1)
        .max_by(|&a, &b| heights[a].total_cmp(&heights[b]))
        .unwrap();
    let lowest = (0..heights.len())
        .filter(|&i| mask[i] == 1)
        .min_by(|&a, &b| heights[a].total_cmp(&heights[b]))
        .unwrap();
    let px = |i: usize| {
        [
            rgba[i * 4],
            rgba[i * 4 + 1],
            rgba[i * 4 + 2],
            rgba[i * 4 + 3],
        ]
    };
    assert!(
        px(highest)[2] > px(lowest)[2] && px(lowest)[1] > px(lowest)[2],
        "{:?} {:?}",
        px(highest),
        px(lowest)
    );
    assert!(mask
        .iter()
        .zip(rgba.chunks_exact(4))
        .all(|(&k, p)| (k == 1) == (p[3] == 255)));
}
