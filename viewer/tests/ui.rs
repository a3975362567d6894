//! The window's UI driven by egui_kittest with the wgpu renderer (Mesa's
//! lavapipe): keys switch modes and toggles, arrows fly, the HUD shows the
//! frame's numbers, the help lists the keys, and the rendered window shows
//! terrain under the HUD.
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use eframe::egui::Key;
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use relevo_core::bundle::BundleFiles;
use relevo_view::app::ViewerApp;
use relevo_view::settings::TerrainMode;

/// The viewer's window on `bundle`, 1000×640, drawn by the wgpu renderer
/// on lavapipe unless a driver is pinned.
fn window(bundle: &std::path::Path) -> Harness<'static, ViewerApp> {
    if std::env::var_os("VK_ICD_FILENAMES").is_none() {
        std::env::set_var("VK_ICD_FILENAMES", relevo_view::LAVAPIPE_ICD);
    }
    let bundle = bundle.to_path_buf();
    Harness::builder()
        .with_size([1000.0, 640.0])
        .wgpu()
        .build_eframe(move |_| ViewerApp::new(Some(&bundle)))
}

#[test]
fn keys_switch_modes_and_the_hud_shows_the_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = common::grenoble_bundle(dir.path());
    let mut harness = window(&bundle);
    harness.run_steps(3);
    let app = harness.state();
    assert_eq!(app.error(), None);
    assert_eq!(app.settings.mode, TerrainMode::Mesh);
    assert!(
        app.stats.triangles > 100,
        "{} triangles",
        app.stats.triangles
    );
    let hud = app.hud_lines().join("\n");
    assert!(
        hud.contains(&format!("{} triangles", app.stats.triangles)),
        "{hud}"
    );
    assert!(
        hud.contains("above ground") && hud.contains("km/h") && hud.contains("camera E"),
        "{hud}"
    );

    // Toggles, one key each.
    for (key, check) in [
        (
            Key::M,
            &(|a: &ViewerApp| a.settings.mode == TerrainMode::Raycast)
                as &dyn Fn(&ViewerApp) -> bool,
        ),
        (Key::W, &|a: &ViewerApp| a.settings.wireframe),
        (Key::T, &|a: &ViewerApp| !a.settings.texture),
        (Key::G, &|a: &ViewerApp| !a.settings.morph),
        (Key::F1, &|a: &ViewerApp| !a.settings.objects),
    ] {
        harness.key_press(key);
        harness.run_steps(2);
        assert!(check(harness.state()), "{key:?} did not switch");
    }
    let hud = harness.state().hud_lines().join("\n");
    assert!(hud.contains("raycast (floating horizon)"), "{hud}");
    assert_eq!(
        harness.state().stats.triangles,
        0,
        "the raycast draws no triangles"
    );

    // Flying forward moves the eye along the heading.
    let before = harness.state().flight().unwrap().position;
    harness.key_down(Key::ArrowUp);
    harness.run_steps(5);
    harness.key_up(Key::ArrowUp);
    harness.run_steps(1);
    let after = harness.state().flight().unwrap().position;
    assert!(
        (after - before).truncate().length() > 1.0,
        "{before} → {after}"
    );

    // The help lists the keys.
    harness.key_press(Key::H);
    harness.run_steps(2);
    assert!(harness.state().show_help);
    harness.get_by_label("fly forward / back");

    // The window as rendered: terrain below the HUD's dark panel.
    let image = harness.render().unwrap();
    let (w, h) = image.dimensions();
    let sky = [135u8, 170, 215];
    let lower: Vec<[u8; 3]> = (h * 3 / 4..h - 10)
        .flat_map(|y| (20..w / 2).map(move |x| (x, y)))
        .map(|(x, y)| {
            let p = image.get_pixel(x, y).0;
            [p[0], p[1], p[2]]
        })
        .collect();
    let terrain = lower.iter().filter(|p| **p != sky).count();
    assert!(
        terrain * 10 > lower.len() * 9,
        "{terrain} of {} pixels",
        lower.len()
    );
    let hud_pixel = image.get_pixel(20, 30).0;
    assert!(
        hud_pixel[..3].iter().all(|&c| c < 120),
        "HUD panel at (20, 30): {hud_pixel:?}"
    );
}

#[test]
fn problems_are_shown_in_the_window() {
    if std::env::var_os("VK_ICD_FILENAMES").is_none() {
        std::env::set_var("VK_ICD_FILENAMES", relevo_view::LAVAPIPE_ICD);
    }
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nowhere.relevo");
    let mut harness = Harness::builder()
        .with_size([800.0, 500.0])
        .wgpu()
        .build_eframe(|_| ViewerApp::new(Some(&missing)));
    harness.run_steps(2);
    let error = harness.state().error().unwrap().to_string();
    assert!(error.contains("nowhere.relevo"), "{error}");
    harness.get_by_label(&error);
    // A broken placement on a good bundle: the message, and the view goes on.
    let bundle = common::grenoble_bundle(dir.path());
    let broken = dir.path().join("broken.geojson");
    std::fs::write(&broken, "{").unwrap();
    let mut harness = Harness::builder()
        .with_size([800.0, 500.0])
        .wgpu()
        .build_eframe(|_| {
            let mut app = ViewerApp::new(Some(&bundle));
            app.load_objects(&broken);
            app
        });
    harness.run_steps(2);
    let error = harness.state().error().unwrap();
    assert!(
        error.contains("broken.geojson") && error.contains("not JSON"),
        "{error}"
    );
    assert!(
        harness.state().stats.triangles > 0,
        "the terrain is still drawn"
    );
}

/// The samples tab opens from the tab bar and says plainly when the bundle
/// has no drape to mark samples on; the 3D view comes back as it was.
#[test]
fn the_samples_tab_opens_and_explains_a_bundle_without_a_drape() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = common::grenoble_bundle(dir.path());
    let mut harness = samples_tab_of(&bundle);
    assert_eq!(harness.state().tab, relevo_view::app::Tab::Samples);
    harness.get_by_label("This bundle has no drape image to mark samples on.");
    harness.get_by_label("3D view").click();
    harness.run_steps(2);
    assert_eq!(harness.state().tab, relevo_view::app::Tab::View);
    assert!(harness.state().stats.triangles > 100);
}

/// The samples tab driven with simulated input: two rectangles dragged on
/// the drape (the second after switching class), detection run from its
/// button on the real Grenoble crop, the overlay shown, and accepting
/// writes a database and clusters that `validate` accepts and the 3D view
/// draws.
#[test]
fn samples_are_dragged_detected_and_accepted_in_the_window() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = common::grenoble_bundle_with_drape(dir.path());
    let mut harness = samples_tab_of(&bundle);
    let drag = |harness: &mut Harness<ViewerApp>, from: [f32; 2], to: [f32; 2]| {
        harness.hover_at(from.into());
        harness.run_steps(1);
        harness.drag_at(from.into());
        harness.run_steps(1);
        for k in 1..=4 {
            let t = k as f32 / 4.0;
            harness.hover_at(
                [
                    from[0] + t * (to[0] - from[0]),
                    from[1] + t * (to[1] - from[1]),
                ]
                .into(),
            );
            harness.run_steps(1);
        }
        harness.drop_at(to.into());
        harness.run_steps(2);
    };
    // Low ground (valley) as vegetation, high rock as the counter-example.
    drag(&mut harness, [560.0, 380.0], [640.0, 450.0]);
    harness.state_mut().samples_tab().unwrap().class = "other".into();
    drag(&mut harness, [700.0, 200.0], [780.0, 260.0]);
    let samples = harness.state_mut().samples_tab().unwrap().samples.clone();
    assert_eq!(samples.len(), 2, "{samples:?}");
    assert_eq!(
        (samples[0].0.as_str(), samples[1].0.as_str()),
        ("forest", "other")
    );
    for (_, r) in &samples {
        assert!(
            r[2] - r[0] > 5.0 && r[3] - r[1] > 5.0 && r[2] <= 257.0 && r[3] <= 257.0,
            "{r:?}"
        );
    }
    // Coarse pixels (150 m): fill mode, one object per 45 ha keeps it small.
    harness
        .state_mut()
        .samples_tab()
        .unwrap()
        .options
        .density_per_ha = 1.0 / 45.0;
    detect(&mut harness);
    let tab = harness.state_mut().samples_tab().unwrap();
    assert!(tab.fresh, "{}", tab.status);
    let found = tab.detections.len();
    assert!(found > 0, "{}", tab.status);
    harness.get_by_label("accept").click();
    harness.run_steps(3);
    assert_eq!(harness.state().error(), None);
    let reopened = relevo_core::bundle::Bundle::open(&bundle).unwrap();
    assert_eq!(
        relevo_core::validation::validate(&reopened),
        Vec::<String>::new()
    );
    assert_eq!(reopened.vegetation().unwrap().unwrap().len(), found);
    harness.get_by_label("3D view").click();
    harness.run_steps(3);
    assert!(harness
        .state()
        .hud_lines()
        .join("\n")
        .contains("vegetation (quadtree)"));
}

/// A broken samples file and a bundle that cannot be rewritten, in the
/// samples tab: each is a message in the window naming the file, the
/// marks stay as they were, and the bundle is left exactly as it was (its
/// staging path is taken by a plain file here, which the rewrite must not
/// remove; permissions would not stop a test run as root).
#[test]
fn broken_samples_and_an_unwritable_bundle_are_reported_in_the_window() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = common::grenoble_bundle_with_drape(dir.path());
    let mut harness = samples_tab_of(&bundle);

    let broken = dir.path().join("broken.csv");
    std::fs::write(
        &broken,
        "class;xmin;ymin;xmax;ymax\nforest;10;10;forty;40\n",
    )
    .unwrap();
    let tab = harness.state_mut().samples_tab().unwrap();
    assert!(tab.samples.is_empty() && tab.problem.is_none());
    tab.samples_path = broken.display().to_string();
    harness.get_by_label("load").click();
    harness.run_steps(2);
    let problem = problem_shown(&mut harness);
    assert!(
        problem.contains("broken.csv") && problem.contains("line 2"),
        "{problem}"
    );
    assert!(harness
        .state_mut()
        .samples_tab()
        .unwrap()
        .samples
        .is_empty());

    // Good samples load; detection runs; the rewrite cannot stage.
    let good = dir.path().join("good.csv");
    std::fs::write(&good, "forest;100;116;140;150\nother;140;60;180;90\n").unwrap();
    let tab = harness.state_mut().samples_tab().unwrap();
    tab.samples_path = good.display().to_string();
    tab.options.density_per_ha = 1.0 / 45.0;
    harness.get_by_label("load").click();
    harness.run_steps(2);
    let tab = harness.state_mut().samples_tab().unwrap();
    assert_eq!(tab.samples.len(), 2, "{:?}", tab.problem);
    assert!(tab.problem.is_none());
    detect(&mut harness);
    assert!(harness.state_mut().samples_tab().unwrap().fresh);
    let before: Vec<(std::path::PathBuf, Vec<u8>)> = files(&bundle);
    let mut staging = bundle.clone().into_os_string();
    staging.push(".tmp");
    std::fs::write(&staging, "not a directory").unwrap();
    harness.get_by_label("accept").click();
    harness.run_steps(2);
    let problem = problem_shown(&mut harness);
    assert!(problem.contains(".relevo.tmp"), "{problem}");
    assert!(
        harness.state_mut().samples_tab().unwrap().fresh,
        "still to accept"
    );
    assert_eq!(files(&bundle), before, "the bundle changed");
    assert_eq!(std::fs::read(&staging).unwrap(), b"not a directory");
}

/// With truth boxes loaded, each detection is a round: its figures are
/// shown, with the marks it ran with and how many were new.
#[test]
fn the_samples_tab_scores_each_round_against_truth_boxes() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = common::grenoble_bundle_with_drape(dir.path());
    let mut harness = samples_tab_of(&bundle);
    let marks = dir.path().join("marks.csv");
    std::fs::write(&marks, "forest;100;116;140;150\nother;140;60;180;90\n").unwrap();
    let tab = harness.state_mut().samples_tab().unwrap();
    tab.samples_path = marks.display().to_string();
    tab.options.density_per_ha = 1.0 / 45.0;
    harness.get_by_label("load").click();
    harness.run_steps(2);
    // Truth: the first detection's own objects as boxes of their size (in
    // drape pixels), so the first round scores 1; a broken file is named.
    detect(&mut harness);
    let bad = dir.path().join("truth.txt");
    std::fs::write(&bad, "1,2,3\n").unwrap();
    let tab = harness.state_mut().samples_tab().unwrap();
    tab.truth_path = bad.display().to_string();
    harness.get_by_label("load truth").click();
    harness.run_steps(2);
    assert!(problem_shown(&mut harness).contains("truth.txt"));
    let opened = relevo_core::bundle::Bundle::open(&bundle).unwrap();
    let g = opened.manifest.color.as_ref().unwrap().geotransform;
    let pixel_m = g.smallest_cell_side();
    let tab = harness.state_mut().samples_tab().unwrap();
    let boxes: Vec<String> = tab
        .detections
        .iter()
        .map(|o| {
            let (x, y) = g.invert(o.x, o.y).unwrap();
            let r = o.size / pixel_m / 2.0;
            format!("{},{},{},{}", x - r, y - r, x + r, y + r)
        })
        .collect();
    assert!(!boxes.is_empty());
    let truth = dir.path().join("truth.csv");
    std::fs::write(&truth, boxes.join("\n")).unwrap();
    tab.truth_path = truth.display().to_string();
    harness.get_by_label("load truth").click();
    harness.run_steps(2);
    detect(&mut harness);
    harness.run_steps(2);
    let tab = harness.state_mut().samples_tab().unwrap();
    assert_eq!(tab.rounds.len(), 1, "{:?}", tab.problem);
    assert_eq!((tab.rounds[0].marks, tab.rounds[0].added), (2, 0));
    assert!((tab.rounds[0].scores.iou_0_4.f1 - 1.0).abs() < 1e-9);
    // A counter-example over some of the truth: the next round counts it
    // as new and scores lower.
    tab.samples.push(("other".into(), [0.0, 0.0, 90.0, 90.0]));
    // (Laid out again first: the new rectangle's row moves the buttons.)
    harness.run_steps(2);
    detect(&mut harness);
    harness.run_steps(2);
    let tab = harness.state_mut().samples_tab().unwrap();
    assert_eq!(tab.rounds.len(), 2, "{} {:?}", tab.status, tab.problem);
    assert_eq!((tab.rounds[1].marks, tab.rounds[1].added), (3, 1));
    assert!(tab.rounds[1].scores.iou_0_4.recall < 1.0);
    harness.get_by_label_contains("round 1: 3 marks (+1)");
}

/// On a drape of 0.1 m pixels (SOAP_061 with its committed marks) crowns
/// are placed: the status shown names the mark that kept the learnt crown
/// spacing from being closer, as `veg detect` does, and the tab keeps that
/// mark's rectangle to draw it in red.
#[test]
fn the_samples_tab_names_the_mark_that_kept_crowns_apart() {
    let dir = tempfile::tempdir().unwrap();
    let (mut harness, _) = soap_061_marked(dir.path());
    detect(&mut harness);
    harness.run_steps(2);
    let tab = harness.state_mut().samples_tab().unwrap();
    assert!(
        tab.status
            .contains("the dead marked as sample 2 (x 90–138, y 147–196 px)"),
        "{}",
        tab.status
    );
    assert_eq!(tab.spacing_mark, Some([90.0, 147.0, 138.0, 196.0]));
    assert_eq!(tab.samples[1].1, [90.0, 147.0, 138.0, 196.0]);
    harness.get_by_label_contains("marked as sample 2");
}

/// Each detection shows the crown spacing and size it placed crowns at.
/// Kept, they hold when crown marks on large crowns are added (the
/// simulated user's two rounds on SOAP_061, which move the learnt
/// spacing and size); let go, those marks move them again.
#[test]
fn the_samples_tab_keeps_a_rounds_crown_scale() {
    let dir = tempfile::tempdir().unwrap();
    let (mut harness, marks) = soap_061_marked(dir.path());
    detect(&mut harness);
    harness.run_steps(2);
    let tab = harness.state_mut().samples_tab().unwrap();
    let first = tab.scale.unwrap();
    assert!(
        tab.status
            .contains("crowns ≥ 3.0 m apart, sized toward 3.4 m"),
        "{}",
        tab.status
    );
    // Crowns are placed, so the thresholds follow the marks' contrast.
    assert!(
        tab.status
            .contains("segmentation thresholds scaled by 0.97 to the samples' contrast"),
        "{}",
        tab.status
    );
    harness
        .get_by_label_contains("keep crowns ≥ 3.0 m apart")
        .click();
    harness.run_steps(2);
    let tab = harness.state_mut().samples_tab().unwrap();
    assert_eq!(tab.kept_scale, Some(first));
    assert_eq!(tab.samples.len(), marks);
    tab.samples.extend(
        [
            ("alive", [48.0, 226.0, 120.0, 306.0]),
            ("alive", [179.0, 184.0, 225.0, 234.0]),
            ("dead", [20.0, 148.0, 59.0, 203.0]),
            ("dead", [95.0, 91.0, 131.0, 140.0]),
            ("dead", [2.0, 75.0, 39.0, 119.0]),
            ("dead", [1.0, 172.0, 26.0, 236.0]),
            ("dead", [53.0, 79.0, 81.0, 117.0]),
        ]
        .map(|(class, r)| (class.to_string(), r)),
    );
    let close = |a: f64, b: f64| (a - b).abs() < 1e-4;
    // (Laid out again first: the new rectangles' rows move the buttons.)
    harness.run_steps(2);
    detect(&mut harness);
    let kept = harness.state_mut().samples_tab().unwrap().scale.unwrap();
    assert!(close(kept.spacing_m, first.spacing_m), "{kept:?} {first:?}");
    assert!(
        close(kept.size_m.unwrap(), first.size_m.unwrap()),
        "{kept:?} {first:?}"
    );
    harness.run_steps(2);
    harness
        .get_by_label_contains("keep crowns ≥ 3.0 m apart")
        .click();
    harness.run_steps(2);
    assert_eq!(harness.state_mut().samples_tab().unwrap().kept_scale, None);
    detect(&mut harness);
    let learnt = harness.state_mut().samples_tab().unwrap().scale.unwrap();
    assert!(
        !close(learnt.spacing_m, first.spacing_m)
            || !close(learnt.size_m.unwrap(), first.size_m.unwrap()),
        "{learnt:?} {first:?}"
    );
}

/// The window on a bundle whose drape is SOAP_061 at 0.1 m, in `dir`, its
/// samples tab open with the committed marks loaded; and how many marks.
fn soap_061_marked(dir: &std::path::Path) -> (Harness<'static, ViewerApp>, usize) {
    use relevo_core::bundle::{Bundle, BundleLock, BundleWriter, ColorInfo};
    let path = common::grenoble_bundle(dir);
    let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let png = std::fs::read(repo.join("data/crops/SOAP_061.png")).unwrap();
    let (rgba, w, h) = relevo_core::raster::png::decode_rgba(&png).unwrap();
    let bundle = Bundle::open(&path).unwrap();
    let [x0, _, _, y0, _, _] = bundle.manifest.grid.geotransform.0;
    let info = ColorInfo {
        width: w,
        height: h,
        geotransform: relevo_core::geo::GeoTransform::north_up(x0, y0, 0.1, 0.1),
        bands: [0, 0, 0],
    };
    let mut writer =
        BundleWriter::rewrite(BundleLock::acquire(&bundle.dir).unwrap(), &bundle, |_| true)
            .unwrap();
    writer.write_drape(&rgba, info).unwrap();
    drop(bundle);
    let bundle = writer.commit().unwrap();
    let mut harness = samples_tab_of(&bundle);
    let marks = repo.join("data/trees/soap_061_samples.csv");
    harness.state_mut().samples_tab().unwrap().samples_path = marks.display().to_string();
    harness.get_by_label("load").click();
    harness.run_steps(2);
    let marks = harness.state_mut().samples_tab().unwrap().samples.len();
    (harness, marks)
}

/// The window on `bundle` with its samples tab open.
fn samples_tab_of(bundle: &std::path::Path) -> Harness<'static, ViewerApp> {
    let mut harness = window(bundle);
    harness.run_steps(2);
    harness.get_by_label("samples").click();
    harness.run_steps(3);
    harness
}

/// Click *detect* in the samples tab and wait for the detection to end.
fn detect(harness: &mut Harness<ViewerApp>) {
    harness.get_by_label("detect").click();
    for _ in 0..600 {
        harness.run_steps(1);
        if !harness.state_mut().samples_tab().unwrap().running() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The samples tab's problem line, which must be shown in the window.
fn problem_shown(harness: &mut Harness<ViewerApp>) -> String {
    let problem = harness
        .state_mut()
        .samples_tab()
        .unwrap()
        .problem
        .clone()
        .unwrap();
    harness.get_by_label(&problem);
    problem
}

/// Every file under `dir` with its bytes, sorted by path.
fn files(dir: &std::path::Path) -> Vec<(std::path::PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(files(&path));
        } else {
            out.push((path.clone(), std::fs::read(&path).unwrap()));
        }
    }
    out.sort();
    out
}
