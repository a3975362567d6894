//! `relevo prep --plan`: the pyramid's build cut into jobs run as separate
//! processes gives the bytes of `relevo prep --tiled` on one machine — for
//! 1, 4 and 16 jobs a step, the DEM read window by window (holes filled)
//! or through the in-memory stages; a job killed mid-tile and run again
//! changes nothing; the finish refuses an incomplete plan naming the jobs
//! left and the commands that run them.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{grenoble_dem, projected_dem_named, pyramid_contents, relevo, relevo_ok, set_cells};
use std::path::{Path, PathBuf};
use std::process::Command;

/// `relevo prep --dem DEM --tiled --tile-size T EXTRA… --out OUT -q`.
fn prep_tiled(dem: &Path, out: &Path, tile: usize, extra: &[&str]) {
    let mut args: Vec<String> = ["prep", "--dem", dem.to_str().unwrap(), "--tiled"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    args.extend(["--tile-size".into(), tile.to_string(), "-q".into()]);
    args.extend(extra.iter().map(|s| s.to_string()));
    args.extend(["--out".into(), out.display().to_string()]);
    relevo_ok(&args);
}

/// The plan's steps: (name, first job, last job).
fn steps(plan: &Path) -> Vec<(String, usize, usize)> {
    let plan: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(plan.join("plan.json")).unwrap()).unwrap();
    plan["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["name"].as_str().unwrap().to_string(),
                s["jobs"][0].as_u64().unwrap() as usize,
                s["jobs"][1].as_u64().unwrap() as usize,
            )
        })
        .collect()
}

fn job(plan: &Path, k: usize) -> std::process::Output {
    relevo([
        "prep".as_ref(),
        "--plan".as_ref(),
        plan.as_os_str(),
        "--job".as_ref(),
        k.to_string().as_ref(),
        "-q".as_ref(),
    ])
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

/// The DEM warped to UTM with four holes the fill stage fills: the plan's
/// scan finds them and the jobs fill them window by window.
fn dem_with_holes(dir: &Path) -> PathBuf {
    let dem = projected_dem_named(dir, "holes.tif", &["-dstnodata", "-32768"]);
    for cells in [[100, 120, 6, 4], [250, 250, 10, 10], [497, 300, 30, 2]] {
        set_cells(&dem, 32631, cells, -32768.0);
    }
    dem
}

#[test]
fn a_plan_run_as_jobs_gives_the_single_machine_pyramid_for_any_job_count() {
    let d = tempfile::tempdir().unwrap();
    let windows = dem_with_holes(d.path());
    for (label, dem) in [("windows", windows), ("in memory", grenoble_dem())] {
        let local = d.path().join(format!("local-{}", label.len()));
        std::fs::create_dir(&local).unwrap();
        prep_tiled(&dem, &local.join("g.relevo"), 128, &[]);
        let expected = pyramid_contents(&local.join("g.relevo"));
        for jobs in [1, 4, 16] {
            let here = d.path().join(format!("{}-{jobs}", label.len()));
            std::fs::create_dir(&here).unwrap();
            let (plan, out) = (here.join("plan"), here.join("g.relevo"));
            let jobs_arg = jobs.to_string();
            prep_tiled(
                &dem,
                &out,
                128,
                &["--plan", plan.to_str().unwrap(), "--jobs", &jobs_arg],
            );
            let steps = steps(&plan);
            assert_eq!(steps.len(), 11, "{label}: {steps:?}");
            assert!(steps.iter().all(|&(_, a, b)| b - a < jobs), "{steps:?}");
            // A job of the second step before the first is done: refused.
            if label == "windows" {
                let o = job(&plan, steps[1].1);
                assert_eq!(o.status.code(), Some(1));
                assert!(
                    stderr(&o).contains("needs the steps before it complete"),
                    "{}",
                    stderr(&o)
                );
            }
            // Step after step; within a step, the jobs from last to first.
            for (i, &(ref name, first, last)) in steps.iter().enumerate() {
                if i == 3 {
                    let o = relevo(["prep", "--plan", plan.to_str().unwrap(), "--finish"]);
                    let e = stderr(&o);
                    assert_eq!(o.status.code(), Some(1), "{e}");
                    assert!(
                        e.contains("jobs are not done")
                            && e.contains(&format!("{first} (lattice, 1 tile)"))
                            && e.contains("--submit slurm")
                            && !out.exists(),
                        "{e}"
                    );
                    let status = relevo_ok(["prep", "--plan", plan.to_str().unwrap(), "--status"]);
                    let own = format!(
                        "own errors: {} of {} jobs done",
                        steps[1].2 - steps[1].1 + 1,
                        steps[1].2 - steps[1].1 + 1
                    );
                    assert!(
                        status.contains(&own) && status.contains("lattice: 0 of 1 jobs done"),
                        "{status}"
                    );
                }
                for k in (first..=last).rev() {
                    let o = job(&plan, k);
                    assert!(
                        o.status.success(),
                        "{label} {jobs} {name} {k}: {}",
                        stderr(&o)
                    );
                }
            }
            relevo_ok(["prep", "--plan", plan.to_str().unwrap(), "--finish", "-q"]);
            assert_eq!(
                pyramid_contents(&out),
                expected,
                "{label}, {jobs} jobs a step: not the single machine's pyramid"
            );
            // Each job recorded what it did.
            let total: u64 = (0..=steps[10].2)
                .map(|k| {
                    let r: serde_json::Value = serde_json::from_str(
                        &std::fs::read_to_string(plan.join(format!("jobs/{k}.json"))).unwrap(),
                    )
                    .unwrap();
                    assert!(r["memory_budget_bytes"].as_u64().unwrap() > 0);
                    r["computed"].as_u64().unwrap()
                })
                .sum();
            let heights = if label == "windows" { 64 } else { 0 };
            // Heights (written by the plan when in memory), own errors,
            // errors and radii, lattice, drape; 21 coarser tiles twice.
            assert_eq!(total, heights + 64 * 3 + 1 + 2 * 21, "{label} {jobs}");
            let o = relevo(["prep", "--plan", plan.to_str().unwrap(), "--finish"]);
            assert!(stderr(&o).contains("already finished"), "{}", stderr(&o));
            let status = relevo_ok(["prep", "--plan", plan.to_str().unwrap(), "--status"]);
            assert!(status.contains("jobs done; finished: "), "{status}");
        }
    }
}

#[test]
fn a_job_killed_mid_tile_runs_again_to_the_same_bytes() {
    let d = tempfile::tempdir().unwrap();
    // 41 m cells: a 4097² grid in tiles of 32 cells, a few seconds a step.
    let dem = grenoble_dem();
    let whole = d.path().join("whole");
    std::fs::create_dir(&whole).unwrap();
    prep_tiled(&dem, &whole.join("g.relevo"), 32, &["--cell-size", "41"]);
    let here = d.path().join("killed");
    std::fs::create_dir(&here).unwrap();
    let (plan, out) = (here.join("plan"), here.join("g.relevo"));
    let args = ["--cell-size", "41", "--plan", plan.to_str().unwrap()];
    prep_tiled(&dem, &out, 32, &[&args[..], &["--jobs", "2"]].concat());
    let steps = steps(&plan);
    let mut killed = 0;
    for (name, first, last) in &steps {
        for k in *first..=*last {
            if name == "errors and radii" || name == "own errors" {
                // Killed part-way, after a delay, then run to the end.
                let mut child = Command::new(env!("CARGO_BIN_EXE_relevo"))
                    .args(["prep", "--plan", plan.to_str().unwrap(), "-q"])
                    .args(["--job", &k.to_string()])
                    .spawn()
                    .unwrap();
                std::thread::sleep(std::time::Duration::from_millis(300));
                if child.try_wait().unwrap().is_none() {
                    killed += 1;
                }
                let _ = child.kill();
                let _ = child.wait();
            }
            let o = job(&plan, k);
            assert!(o.status.success(), "{name} {k}: {}", stderr(&o));
        }
    }
    assert!(killed > 0, "no job was still running when killed");
    relevo_ok(["prep", "--plan", plan.to_str().unwrap(), "--finish", "-q"]);
    assert_eq!(
        pyramid_contents(&out),
        pyramid_contents(&whole.join("g.relevo"))
    );
}

#[test]
fn plans_in_the_wrong_place_and_jobs_that_do_not_exist_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let dem = grenoble_dem();
    let out = d.path().join("g.relevo");
    let user = d.path().join("mine");
    std::fs::create_dir(&user).unwrap();
    std::fs::write(user.join("notes.txt"), "mine").unwrap();
    let plan_args = |plan: &Path| -> Vec<String> {
        [
            "prep",
            "--dem",
            dem.to_str().unwrap(),
            "--tiled",
            "--tile-size",
            "256",
            "--jobs",
            "2",
            "--plan",
            plan.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let o = relevo(plan_args(&user));
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("not empty and not a plan"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read_to_string(user.join("notes.txt")).unwrap(),
        "mine"
    );
    let plan = d.path().join("plan");
    relevo_ok(plan_args(&plan));
    let o = relevo(plan_args(&plan));
    assert!(
        stderr(&o).contains("already holds a plan"),
        "{}",
        stderr(&o)
    );
    let o = job(&plan, 9999);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("no job 9999"), "{}", stderr(&o));
    // Another writer of the same bundle does not clear the plan's build.
    let o = relevo([
        "prep",
        "--dem",
        dem.to_str().unwrap(),
        "--tiled",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("holds the build of the plan in") && plan.join("plan.json").exists(),
        "{}",
        stderr(&o)
    );
    for (name, first, last) in steps(&plan) {
        for k in first..=last {
            assert!(job(&plan, k).status.success(), "{name} {k}");
        }
    }
    relevo_ok(["prep", "--plan", plan.to_str().unwrap(), "--finish", "-q"]);
    assert!(!out.join(".relevo-plan").exists() && out.join("manifest.json").exists());
    let o = relevo([
        "prep",
        "--plan",
        d.path().join("none").to_str().unwrap(),
        "--finish",
    ]);
    assert!(stderr(&o).contains("no plan here"), "{}", stderr(&o));
}
