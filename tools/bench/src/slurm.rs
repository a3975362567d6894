//! A pyramid built as Slurm array jobs on a single-node cluster this
//! benchmark starts (2 CPUs), beside `relevo prep --tiled` on the same
//! machine: the wall time from submission to the pyramid in place with
//! one task of 2 threads at a time and with two tasks of 1 thread; the
//! seconds a tile each step takes (the jobs' own records); and Slurm's
//! own cost — an array of empty tasks, and the time between chained steps.

use crate::measure::{emit, run_measured, tempfile_dir};
use crate::pyramid::{grenoble_utm, relevo_exe};
use anyhow::{anyhow, bail, Result};
use serde_json::json;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

#[path = "../../../tests/src/slurm_cluster.rs"]
mod slurm_cluster;
use slurm_cluster::Cluster;

/// Longest a measured submission may take.
const LIMIT: Duration = Duration::from_secs(1800);

pub fn run(repo: &Path, jobs: usize, json_lines: bool) -> Result<()> {
    let relevo = relevo_exe()?;
    let scratch = tempfile_dir()?;
    let dem = grenoble_utm(
        repo,
        &scratch,
        20.0,
        [660000.0, 4990000.0, 730000.0, 5090000.0],
    )?;
    let local = scratch.join("local.relevo");
    let (local_ms, local_mb) = run_measured(
        Command::new(&relevo)
            .args(["prep", "--tiled", "-q", "--dem"])
            .arg(&dem)
            .arg("--out")
            .arg(&local),
    )?;
    std::fs::remove_dir_all(&local)?;
    let cluster = Cluster::start(&scratch.join("slurm")).map_err(|e| anyhow!(e))?;

    // Slurm alone: an array of 16 empty tasks.
    let start = Instant::now();
    slurm_cluster::run(
        cluster
            .command("sbatch")
            .args([
                "--array=0-15",
                "--cpus-per-task=1",
                "--mem=10M",
                "-o",
                "/dev/null",
            ])
            .args(["--wrap", "true"]),
    )
    .map_err(|e| anyhow!(e))?;
    cluster.drain(LIMIT).map_err(|e| anyhow!(e))?;
    let empty_ms = start.elapsed().as_secs_f64() * 1e3;
    emit(
        json_lines,
        json!({"bench": "slurm", "what": "16 empty array tasks on 2 CPUs", "wall_ms": empty_ms,
               "ms_per_task": empty_ms / 16.0}),
        format!(
            "slurm: 16 empty array tasks in {:.1} s ({:.0} ms a task)",
            empty_ms / 1e3,
            empty_ms / 16.0
        ),
    );

    for cpus in [2usize, 1] {
        let here = scratch.join(format!("cpus{cpus}"));
        std::fs::create_dir_all(&here)?;
        let (plan, out) = (here.join("plan"), here.join("g.relevo"));
        let start = Instant::now();
        let status = cluster
            .command(&relevo)
            .args(["prep", "--tiled", "-q", "--dem"])
            .arg(&dem)
            .arg("--plan")
            .arg(&plan)
            .args(["--jobs", &jobs.to_string(), "--submit", "slurm", "--json"])
            .args(["--cpus-per-task", &cpus.to_string()])
            .arg("--out")
            .arg(&out)
            .stdout(std::process::Stdio::null())
            .status()?;
        if !status.success() {
            bail!("the plan's submission failed");
        }
        cluster.drain(LIMIT).map_err(|e| anyhow!(e))?;
        let wall_ms = start.elapsed().as_secs_f64() * 1e3;
        if !out.is_dir() {
            bail!(
                "{}: the finish did not run (see {}/logs)",
                out.display(),
                plan.display()
            );
        }
        let (per_step, tasks, jobs_ms) = step_times(&plan)?;
        let concurrent = 2 / cpus;
        emit(
            json_lines,
            json!({"bench": "slurm", "what": "grenoble 8193² pyramid as Slurm array jobs",
                   "jobs_per_step": jobs, "tasks": tasks, "cpus_per_task": cpus,
                   "concurrent_tasks": concurrent, "slurm_wall_ms": wall_ms,
                   "jobs_ms": jobs_ms, "local_prep_tiled_ms": local_ms,
                   "local_peak_rss_mb": local_mb, "steps": per_step}),
            format!(
                "slurm: grenoble 8193², {tasks} tasks, {concurrent} at a time of {cpus} thread(s): \
                 {:.1} s from submission to the pyramid (the jobs' own time {:.1} s); \
                 prep --tiled on 2 threads {:.1} s",
                wall_ms / 1e3,
                jobs_ms / 1e3,
                local_ms / 1e3
            ),
        );
        if cpus == 1 && !json_lines {
            for s in &per_step {
                println!("  {s}");
            }
        }
    }
    drop(cluster);
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// Each step of the plan in `plan`: the jobs' summed and longest times and
/// the seconds a tile, from the jobs' records; the tasks, the jobs' time.
fn step_times(plan: &Path) -> Result<(Vec<serde_json::Value>, usize, f64)> {
    let plan_json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(plan.join("plan.json"))?)?;
    let (mut per_step, mut tasks, mut jobs_ms) = (Vec::new(), 0, 0.0);
    for s in plan_json["steps"].as_array().cloned().unwrap_or_default() {
        let (first, last) = (
            s["jobs"][0].as_u64().unwrap_or(0),
            s["jobs"][1].as_u64().unwrap_or(0),
        );
        let tiles = s["tiles"].as_u64().unwrap_or(0).max(1);
        let (mut sum, mut longest) = (0.0f64, 0.0f64);
        for k in first..=last {
            let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(
                plan.join(format!("jobs/{k}.json")),
            )?)?;
            let ms = r["ms"].as_f64().unwrap_or(0.0);
            sum += ms;
            longest = longest.max(ms);
            tasks += 1;
        }
        jobs_ms += sum;
        per_step.push(
            json!({"step": s["name"], "jobs_ms": sum, "longest_job_ms": longest,
                             "tiles": tiles, "s_per_tile": sum / 1e3 / tiles as f64}),
        );
    }
    Ok((per_step, tasks, jobs_ms))
}
