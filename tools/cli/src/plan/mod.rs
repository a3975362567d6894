//! What every plan shares — a pyramid's (`prep::plan`) and a vegetation
//! detection's (`veg_plan`): its folder (`plan.json`, `jobs/K.json` records,
//! `logs/`, `slurm/`), read and written atomically, and `slurm`, which
//! submits any plan's jobs as Slurm array jobs.

pub mod slurm;

use anyhow::{bail, Context, Result};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// A plan whose numbered jobs run in steps, each step's jobs side by side
/// once the step before has succeeded.
pub trait Jobs {
    /// The `relevo` subcommand that runs a job with `--plan DIR --job K`
    /// and finishes with `--plan DIR --finish`.
    fn subcommand(&self) -> &'static [&'static str];
    /// The steps, in order: name, first and last job.
    fn steps(&self) -> Result<Vec<(String, usize, usize)>>;
    /// The jobs of the plan in `dir` not done, in order.
    fn unfinished(&self, dir: &Path) -> Result<Vec<usize>>;
    /// Whether the plan in `dir` is finished: its result written.
    fn finished(&self, dir: &Path) -> bool;
    /// What the plan writes, for the scripts' comments.
    fn target(&self) -> &Path;
    /// Bytes a job on `threads` threads holds at once, by the estimate
    /// it checks against its memory budget before it starts.
    fn working_bytes(&self, threads: usize) -> Result<u64>;
}

/// How far a plan has come.
#[derive(Debug, Clone, Serialize)]
pub struct Status {
    pub steps: Vec<StepStatus>,
    /// Whether its result is written.
    pub finished: bool,
}

/// How far one step of a plan has come.
#[derive(Debug, Clone, Serialize)]
pub struct StepStatus {
    pub step: String,
    pub jobs: usize,
    pub done: usize,
}

/// Each step of `plan` (in `dir`) with its jobs done of all, and whether
/// it is finished.
pub fn status(dir: &Path, plan: &dyn Jobs) -> Result<Status> {
    let finished = plan.finished(dir);
    let left = if finished {
        Vec::new()
    } else {
        plan.unfinished(dir)?
    };
    let steps = plan
        .steps()?
        .into_iter()
        .map(|(step, first, last)| StepStatus {
            step,
            jobs: last + 1 - first,
            done: (first..=last).filter(|j| !left.contains(j)).count(),
        })
        .collect();
    Ok(Status { steps, finished })
}

/// The plan's own file in its folder.
const PLAN_FILE: &str = "plan.json";

/// Make `dir` ready for a new plan: created with its `jobs/` and `logs/`,
/// or emptied of an earlier plan's files with `force`; a folder holding
/// anything else is refused.
pub fn prepare(dir: &Path, force: bool) -> Result<()> {
    if dir.join(PLAN_FILE).is_file() {
        if !force {
            bail!(
                "{}: already holds a plan (pass --force to replace it)",
                dir.display()
            );
        }
        for sub in ["jobs", "logs", "slurm"] {
            let p = dir.join(sub);
            if p.exists() {
                std::fs::remove_dir_all(&p).with_context(|| p.display().to_string())?;
            }
        }
        std::fs::remove_file(dir.join(PLAN_FILE))?;
    } else if dir.read_dir().is_ok_and(|mut d| d.next().is_some()) {
        bail!(
            "{}: not empty and not a plan; give --plan a new or empty folder",
            dir.display()
        );
    }
    for sub in ["jobs", "logs"] {
        let p = dir.join(sub);
        std::fs::create_dir_all(&p).with_context(|| p.display().to_string())?;
    }
    Ok(())
}

/// Read `dir/plan.json`, refused unless its `format` and `format_version`
/// are `format` and `version`.
pub fn load<T: DeserializeOwned>(dir: &Path, format: &str, version: u32) -> Result<T> {
    let path = dir.join(PLAN_FILE);
    let text = relevo_core::files::read_to_string(&path)
        .with_context(|| format!("{}: no plan here (make one with --jobs)", dir.display()))?;
    let value: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a Relevo plan", path.display()))?;
    let found = (
        value["format"].as_str().unwrap_or("none").to_string(),
        value["format_version"].as_u64().unwrap_or(0),
    );
    if found != (format.to_string(), u64::from(version)) {
        bail!(
            "{}: a plan of format {} version {}; this command reads {format} version {version}",
            path.display(),
            found.0,
            found.1
        );
    }
    serde_json::from_value(value).with_context(|| format!("{}: not a Relevo plan", path.display()))
}

/// Write the plan `value` as `dir/plan.json`.
pub fn save<T: Serialize>(dir: &Path, value: &T) -> Result<()> {
    write_json(&dir.join(PLAN_FILE), value)
}

/// `dir/jobs/K.json`, job K's record.
pub fn job_record(dir: &Path, k: usize) -> PathBuf {
    dir.join("jobs").join(format!("{k}.json"))
}

/// Write `value` as JSON at `path` atomically (a reader sees the old file
/// or the whole new one).
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let mut text = serde_json::to_string_pretty(value)?;
    text.push('\n');
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, text).with_context(|| tmp.display().to_string())?;
    std::fs::rename(&tmp, path).with_context(|| path.display().to_string())
}

/// `p` made absolute against the current folder: jobs may run elsewhere.
pub fn absolute(p: &Path) -> Result<PathBuf> {
    Ok(if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir()?.join(p)
    })
}

/// This machine's name, for the jobs' records.
pub fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_default()
}
