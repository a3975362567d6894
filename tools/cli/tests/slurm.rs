//! `relevo prep --plan DIR --submit slurm` on a real Slurm (Debian's
//! slurm-wlm and munge, installed by scripts/setup-test): a single-node
//! cluster this test configures, starts and stops. The plan of the real
//! Grenoble DEM (warped to UTM, holes filled window by window) runs as
//! array jobs chained by `afterok` and gives the bytes of `relevo prep
//! --tiled` on one machine; each task runs inside the memory Slurm gives
//! it; a second submission while the first is queued is refused; a
//! cancelled task leaves the plan incomplete, `--finish` names what is
//! missing, and submitting again sends only that and completes the same
//! bytes. A vegetation detection on real imagery, split into array tasks,
//! writes the database one machine writes.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{projected_dem_named, pyramid_contents, relevo_ok, repo, set_cells, shared};
use std::path::Path;
use std::process::Output;
use std::time::Duration;

#[path = "../../../tests/src/slurm_cluster.rs"]
mod slurm_cluster;

use slurm_cluster::{run, Cluster};

/// `relevo ARGS…` talking to `cluster`.
fn relevo(cluster: &Cluster, args: &[&str]) -> Output {
    cluster
        .command(env!("CARGO_BIN_EXE_relevo"))
        .args(args)
        .output()
        .unwrap()
}

const LIMIT: Duration = Duration::from_secs(240);

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

/// What `--submit slurm --json` printed: (step, plan jobs, Slurm job id).
fn submitted(o: &Output) -> Vec<(String, Vec<u64>, String)> {
    assert!(o.status.success(), "{}", stderr(o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    v.as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["step"].as_str().unwrap().to_string(),
                s["jobs"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|j| j.as_u64().unwrap())
                    .collect(),
                s["slurm_job_id"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

#[test]
fn a_plan_runs_as_slurm_array_jobs_to_the_single_machine_pyramid_and_survives_a_cancelled_task() {
    let d = tempfile::tempdir().unwrap();
    let dem = projected_dem_named(d.path(), "holes.tif", &["-dstnodata", "-32768"]);
    for cells in [[100, 120, 6, 4], [497, 300, 30, 2]] {
        set_cells(&dem, 32631, cells, -32768.0);
    }
    let dem = dem.to_str().unwrap().to_string();
    let local = d.path().join("local");
    std::fs::create_dir(&local).unwrap();
    let prep = ["prep", "--dem", &dem, "--tiled", "--tile-size", "256", "-q"];
    let out = local.join("g.relevo");
    relevo_ok([&prep[..], &["--out", out.to_str().unwrap()]].concat());
    let expected = pyramid_contents(&out);

    let slurm_dir = tempfile::tempdir().unwrap();
    let cluster = Cluster::start(slurm_dir.path()).unwrap();
    // The whole plan, 4 jobs a step, 300 MB a task.
    // Plan `name` (4 jobs a step) and submit it with `extra`: the plan,
    // the pyramid's path, what was submitted.
    let plan_and_submit = |name: &str, extra: &[&str]| {
        let here = d.path().join(name);
        std::fs::create_dir(&here).unwrap();
        let (plan, out) = (here.join("plan"), here.join("g.relevo"));
        let o = relevo(
            &cluster,
            &[
                &prep[..],
                &["--plan", plan.to_str().unwrap(), "--jobs", "4"],
                &[
                    "--out",
                    out.to_str().unwrap(),
                    "--submit",
                    "slurm",
                    "--json",
                ],
                extra,
            ]
            .concat(),
        );
        let ids = submitted(&o);
        (plan, out, ids)
    };
    let (plan, out, ids) = plan_and_submit("whole", &["--mem", "300M"]);
    let plan_s = plan.to_str().unwrap();
    let steps: Vec<&str> = ids.iter().map(|(s, _, _)| s.as_str()).collect();
    assert_eq!(
        steps,
        [
            "heights",
            "own errors",
            "errors and radii",
            "lattice",
            "drape",
            "level 1",
            "level 1 drape",
            "level 2",
            "level 2 drape",
            "finish"
        ]
    );
    // Submitting again while these are queued is refused, naming them.
    let again = relevo(&cluster, &["prep", "--plan", plan_s, "--submit", "slurm"]);
    assert_eq!(again.status.code(), Some(1));
    assert!(
        stderr(&again).contains("still queued or running") && stderr(&again).contains("scancel"),
        "{}",
        stderr(&again)
    );
    cluster.drain(LIMIT).unwrap();
    assert!(
        out.exists(),
        "the finish job did not move the pyramid into place: {:?}",
        std::fs::read_to_string(plan.join("logs/10-finish.log"))
    );
    assert_eq!(pyramid_contents(&out), expected, "Slurm's pyramid differs");
    // Every task ran under Slurm with the memory it was given.
    for k in 0..=ids[8].1[0] {
        let record: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(plan.join(format!("jobs/{k}.json"))).unwrap(),
        )
        .unwrap();
        assert!(record["slurm"].is_string(), "{record}");
        assert_eq!(record["memory_budget_bytes"], 300u64 << 20, "{record}");
    }

    // A task cancelled: the steps after it never run.
    let (plan, out, ids) = plan_and_submit("cancelled", &[]);
    let plan_s = plan.to_str().unwrap();
    let (_, own_jobs, own_id) = &ids[1];
    run(cluster.command("scancel").arg(format!("{own_id}_2"))).unwrap();
    cluster.drain(LIMIT).unwrap();
    assert!(!out.exists());
    let finish = relevo(&cluster, &["prep", "--plan", plan_s, "--finish"]);
    let e = stderr(&finish);
    assert_eq!(finish.status.code(), Some(1), "{e}");
    let cancelled = own_jobs[2];
    assert!(
        e.contains(&format!("{cancelled} (own errors, 4 tiles)")) && e.contains("--submit slurm"),
        "{e}"
    );
    // Submitted again: only the cancelled job of its step, then the rest.
    let ids = submitted(&relevo(
        &cluster,
        &["prep", "--plan", plan_s, "--submit", "slurm", "--json"],
    ));
    assert_eq!(ids[0].0, "own errors");
    assert_eq!(ids[0].1, [cancelled]);
    cluster.drain(LIMIT).unwrap();
    assert_eq!(
        pyramid_contents(&out),
        expected,
        "the resubmitted plan's pyramid differs"
    );

    vegetation_as_array_jobs(&cluster, d.path());
}

/// Vegetation on real imagery (the NEON Yellowstone crop, tiles of 256
/// pixels) planned in `dir`: 3 array tasks, then the finish, write the
/// database one machine writes.
fn vegetation_as_array_jobs(cluster: &Cluster, dir: &Path) {
    let image = shared("trees/2019_YELL_2_541000_4977000_image_crop.png");
    let samples = repo("data/trees/yellowstone_samples.csv");
    let veg = [
        "veg",
        "detect",
        image.to_str().unwrap(),
        "--samples",
        samples.to_str().unwrap(),
        "--pixel-size",
        "0.1",
        "--tile",
        "256",
    ];
    let single = dir.join("single.csv");
    relevo_ok([&veg[..], &["--out", single.to_str().unwrap()]].concat());
    let (plan, out) = (dir.join("veg-plan"), dir.join("trees.csv"));
    let ids = submitted(&relevo(
        cluster,
        &[
            &veg[..],
            &["--plan", plan.to_str().unwrap(), "--jobs", "3"],
            &[
                "--out",
                out.to_str().unwrap(),
                "--submit",
                "slurm",
                "--json",
            ],
        ]
        .concat(),
    ));
    assert_eq!(ids.len(), 2, "{ids:?}");
    assert_eq!(ids[0].1, [0, 1, 2]);
    cluster.drain(LIMIT).unwrap();
    assert!(
        std::fs::read(&out).ok() == std::fs::read(&single).ok(),
        "Slurm's vegetation database differs: {:?}",
        std::fs::read_to_string(plan.join("logs/01-finish.log"))
    );
}
