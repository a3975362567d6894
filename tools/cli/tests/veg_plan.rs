//! `relevo veg detect --plan`: detection split into jobs that each read
//! only their tiles' windows gives the database `relevo veg detect` writes
//! on one machine, byte for byte — crowns on the NEON Yellowstone crop
//! (its thresholds absolute and scaled to the samples' contrast) and
//! forest fill on the Olinda Landsat scene, in tiles of 256 pixels so
//! objects on tile borders are many; the finish refuses a plan with jobs
//! left, naming them; a plan whose jobs were edited out of the tiles is
//! refused.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{relevo, relevo_ok, repo, shared};
use std::path::Path;

/// `relevo veg detect IMAGE --samples SAMPLES OPTIONS… EXTRA…`.
fn detect(image: &Path, samples: &Path, options: &[&str], extra: &[&str]) -> String {
    let mut args = vec![
        "veg".to_string(),
        "detect".into(),
        image.display().to_string(),
        "--samples".into(),
        samples.display().to_string(),
        "--tile".into(),
        "256".into(),
    ];
    args.extend(options.iter().chain(extra).map(|s| s.to_string()));
    relevo_ok(&args)
}

fn plan_command(plan: &Path, what: &[&str]) -> std::process::Output {
    let mut args = vec!["veg", "detect", "--plan", plan.to_str().unwrap()];
    args.extend(what);
    relevo(&args)
}

#[test]
fn a_detection_run_as_jobs_writes_the_single_machine_database() {
    let d = tempfile::tempdir().unwrap();
    let yellowstone = shared("trees/2019_YELL_2_541000_4977000_image_crop.png");
    let yellowstone_samples = repo("data/trees/yellowstone_samples.csv");
    let olinda = repo("data/olinda/L7_ETMs.tif");
    let olinda_samples = repo("data/olinda/samples.csv");
    let cases: [(&str, &Path, &Path, &[&str]); 3] = [
        (
            "crowns",
            &yellowstone,
            &yellowstone_samples,
            &["--pixel-size", "0.1"],
        ),
        (
            "crowns, contrast",
            &yellowstone,
            &yellowstone_samples,
            &["--pixel-size", "0.1", "--contrast", "samples"],
        ),
        (
            "fill",
            &olinda,
            &olinda_samples,
            &["--bands", "3,2,1", "--stretch", "1,99", "--density", "4"],
        ),
    ];
    for (k, (label, image, samples, options)) in cases.into_iter().enumerate() {
        let single = d.path().join(format!("single{k}.csv"));
        detect(
            image,
            samples,
            options,
            &["--out", single.to_str().unwrap()],
        );
        let expected = std::fs::read_to_string(&single).unwrap();
        assert!(expected.lines().count() > 50, "{label}: {expected}");
        for jobs in [1, 3] {
            let plan = d.path().join(format!("plan{k}-{jobs}"));
            let out = d.path().join(format!("planned{k}-{jobs}.csv"));
            detect(
                image,
                samples,
                options,
                &[
                    "--plan",
                    plan.to_str().unwrap(),
                    "--jobs",
                    &jobs.to_string(),
                    "--out",
                    out.to_str().unwrap(),
                ],
            );
            if jobs == 3 {
                let o = plan_command(&plan, &["--job", "2"]);
                assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
                let o = plan_command(&plan, &["--finish"]);
                let e = String::from_utf8_lossy(&o.stderr);
                assert_eq!(o.status.code(), Some(1), "{e}");
                assert!(
                    e.contains("2 jobs are not done: 0, 1") && !out.exists(),
                    "{e}"
                );
                let o = plan_command(&plan, &["--status"]);
                let status = String::from_utf8_lossy(&o.stdout);
                assert!(status.contains("vegetation: 1 of 3 jobs done"), "{status}");
            }
            for job in (0..jobs).rev() {
                let o = plan_command(&plan, &["--job", &job.to_string()]);
                assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            }
            let o = plan_command(&plan, &["--finish"]);
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            assert!(
                std::fs::read_to_string(&out).unwrap() == expected,
                "{label}, {jobs} jobs: not the single machine's database"
            );
            let status =
                String::from_utf8_lossy(&plan_command(&plan, &["--status"]).stdout).to_string();
            assert!(status.contains("jobs done; finished: "), "{status}");
            if jobs == 3 && k == 0 {
                let path = plan.join("plan.json");
                let mut edited: serde_json::Value =
                    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
                // Each edit is refused by name, before any tile is read.
                let refused = |edited: &serde_json::Value, message: &str| {
                    std::fs::write(&path, edited.to_string()).unwrap();
                    let o = plan_command(&plan, &["--job", "0"]);
                    let e = String::from_utf8_lossy(&o.stderr);
                    assert_eq!(o.status.code(), Some(1), "{e}");
                    assert!(e.contains(message), "{e}");
                };
                let jobs_cut = edited["jobs"].clone();
                edited["jobs"] = serde_json::json!([[0, 9999]]);
                refused(&edited, "do not cut the 25 tiles");
                // A crown template that does not hold together.
                edited["jobs"] = jobs_cut;
                edited["model"]["placement"]["template"]["weights"] = serde_json::json!([1.0]);
                refused(&edited, "plan.json: crown template with 1 weights");
                // A marked crown size that is not positive (crown sizes are
                // kept within a range of it).
                edited["model"]["placement"]["template"] = serde_json::Value::Null;
                edited["model"]["placement"]["marked_size_px"] = serde_json::json!(-5.0);
                refused(
                    &edited,
                    "plan.json: marked crown size of -5 px: not positive",
                );
            }
        }
    }
}
