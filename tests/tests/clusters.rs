//! Vegetation clusters on the sample region's real detections: atlases
//! free of fringes at every mip level, quadtree cuts that represent every
//! visible object once for many cameras, blobs that keep their rule, the
//! composition close to rendering the members, and a class model read from
//! an OBJ file named in REGION.toml.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use relevo_core::bundle::Bundle;
use relevo_core::bundle::BundleFiles;
use relevo_core::camera::Camera;
use relevo_core::cluster::checks;
use relevo_core::cluster::cut::{
    box_distance, box_in_frustum, Blobs, CutOptions, DrawList, QuadtreeCut, Selection,
};
use relevo_core::cluster::model::TreeKind;
use relevo_core::cluster::{store, Clusters};
use relevo_tests::{prep_region, repo};
use std::collections::HashSet;

fn olinda() -> (tempfile::TempDir, Clusters) {
    let dir = tempfile::tempdir().unwrap();
    let out = prep_region(
        &repo("data/olinda/REGION.toml"),
        &dir.path().join("olinda.relevo"),
    );
    let (_, clusters) = store::read(&Bundle::open(&out).unwrap()).unwrap().unwrap();
    (dir, clusters)
}

/// Cameras over the 11.5 km region and around it, low and high.
fn cameras(count: usize) -> Vec<Camera> {
    checks::random_cameras(
        count,
        11,
        [-2_000.0, -2_000.0, 50.0],
        [14_000.0, 14_000.0, 3_050.0],
    )
}

#[test]
fn real_atlases_have_no_fringe_and_cuts_draw_each_visible_object_once() {
    let (_dir, clusters) = olinda();
    let (partial, problems) = checks::fringe_problems(&clusters);
    assert_eq!(problems, Vec::<String>::new());
    assert!(partial > 100_000, "{partial} partly covered texels");

    let options = CutOptions::default();
    let mut list = DrawList::default();
    let (mut draws, mut represented) = (0, 0);
    for camera in cameras(200) {
        QuadtreeCut(&clusters).select(&camera, &options, &mut list);
        assert_eq!(
            checks::cut_problems(&clusters, &list, &camera, &options),
            Vec::<String>::new()
        );
        draws += list.len();
        represented += list.represented;
    }
    // Clusters stand in for many objects on the whole.
    assert!(
        represented > 3 * draws,
        "{draws} draws for {represented} objects"
    );

    let blobs = Blobs::new(&clusters, 1_000.0);
    for camera in cameras(50) {
        blobs.select(&camera, &options, &mut list);
        let drawn: HashSet<u32> = checks::represented_objects(&clusters, &list)
            .into_iter()
            .map(|(o, _)| o)
            .collect();
        let planes = camera.frustum_planes();
        for blob in blobs.blobs() {
            let visible = box_in_frustum(&planes, blob.min, blob.max)
                && box_distance(camera.position, blob.min, blob.max) <= options.last_distance();
            assert!(
                blob.members.iter().all(|m| drawn.contains(m) == visible),
                "blob rule broken"
            );
        }
    }
}

/// The composition in painter's order against rendering the members'
/// models, on real clusters (the figure in docs/algorithms.md#clusters).
#[test]
fn composed_cluster_views_are_close_to_rendered_ones_on_real_data() {
    let (_dir, clusters) = olinda();
    let models = vec![TreeKind::Stand.model(1)];
    let (mean, texels) = checks::composition_difference(&clusters, &models, 20);
    println!("composition vs render: mean |Δα| = {mean:.4} over {texels} texels");
    assert!(
        texels > 100_000 && mean < 0.05,
        "mean |Δα| {mean} over {texels} texels"
    );
}

#[test]
fn a_region_names_an_obj_model_for_its_class() {
    let dir = tempfile::tempdir().unwrap();
    // A textured card: a leaf texture with a transparent half.
    let texture =
        relevo_core::raster::png::encode_rgba(&[40, 110, 30, 255, 0, 0, 0, 0], 2, 1).unwrap();
    std::fs::write(dir.path().join("leaf.png"), texture).unwrap();
    std::fs::write(
        dir.path().join("card.mtl"),
        "newmtl leaf\nKd 1 1 1\nmap_Kd leaf.png\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("card.obj"),
        "mtllib card.mtl\nv -1 0 0\nv 1 0 0\nv 1 2 0\nv -1 2 0\nv 0 0 -1\nv 0 0 1\nv 0 2 1\nv 0 2 -1\n\
         vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl leaf\nf 1/1 2/2 3/3 4/4\nf 5/1 6/2 7/3 8/4\n",
    )
    .unwrap();
    let region = std::fs::read_to_string(repo("data/olinda/REGION.toml")).unwrap();
    let olinda = repo("data/olinda").display().to_string();
    let region = region
        .replace(
            "\"olinda_dem_utm25s.tif\"",
            &format!("\"{olinda}/olinda_dem_utm25s.tif\""),
        )
        .replace("\"L7_ETMs.tif\"", &format!("\"{olinda}/L7_ETMs.tif\""))
        .replace("\"samples.csv\"", &format!("\"{olinda}/samples.csv\""))
        .replace("forest = \"stand\"", "forest = \"card.obj\"");
    std::fs::write(dir.path().join("REGION.toml"), region).unwrap();
    let out = prep_region(
        &dir.path().join("REGION.toml"),
        &dir.path().join("cards.relevo"),
    );
    let (index, clusters) = store::read(&Bundle::open(&out).unwrap()).unwrap().unwrap();
    assert!(
        matches!(&index.classes[0].model, relevo_core::cluster::model::ModelSource::Obj(path) if path.ends_with("card.obj")),
        "{}",
        index.classes[0].model
    );
    assert_eq!(index.classes[0].aspect, 1.0, "2 tall over 2 across");
    // The front view shows the card's leaf half and its cut-out half.
    let front = checks::frame_image(&clusters, &clusters.classes[0].frames[1]);
    let covered = front.texels.iter().filter(|t| t[3] == 255).count();
    assert!(
        covered > front.texels.len() / 5 && covered < front.texels.len() * 4 / 5,
        "{covered}"
    );
    assert!(
        front.texels.iter().any(|t| t[3] == 255 && t[1] > t[0]),
        "green leaves"
    );
}

/// `validate` checks the clusters against the database: a database object
/// moved after the bake is reported.
#[test]
fn validate_finds_clusters_that_disagree_with_the_database() {
    let dir = tempfile::tempdir().unwrap();
    let out = prep_region(
        &repo("data/olinda/REGION.toml"),
        &dir.path().join("olinda.relevo"),
    );
    let bundle = Bundle::open(&out).unwrap();
    let mut database = bundle.vegetation().unwrap().unwrap();
    database[10].x += 100.0;
    let mut writer = relevo_core::bundle::BundleWriter::rewrite(
        relevo_core::bundle::BundleLock::acquire(&out).unwrap(),
        &bundle,
        |key| key != "vegetation",
    )
    .unwrap();
    writer.staged().write_vegetation(&database).unwrap();
    drop(bundle);
    let out = writer.commit().unwrap();
    let problems = relevo_core::validation::validate(&Bundle::open(&out).unwrap());
    assert!(
        problems
            .iter()
            .any(|p| p.contains("row 10") && p.contains("differs from the database")),
        "{problems:?}"
    );
}
