//! `--plan DIR --submit slurm`: a plan's jobs (a pyramid's, `relevo prep`;
//! a vegetation detection's, `relevo veg detect`) as Slurm array jobs,
//! through Slurm's own commands (`sbatch`, `squeue`) and nothing else.
//!
//! Each step is one batch script in `DIR/slurm/` whose array task i runs
//! the step's i-th job; the scripts are plain files a person can read,
//! edit and `sbatch` by hand. A submission sends, step by step, the array
//! tasks whose jobs are not done, each step held (`--dependency=afterok`)
//! until the one before it has succeeded, then the finish. So after a
//! task is killed or a node fails, submitting again sends only what is
//! left.

use super::Jobs;
use anyhow::{bail, Context, Result};
use relevo_core::bundle::sha256_bytes;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// What the batch scripts ask Slurm for (`#SBATCH` lines).
#[derive(Debug, Clone, Default)]
pub struct SlurmOptions {
    pub partition: Option<String>,
    /// Memory a task, as `sbatch --mem` takes it (e.g. `2G`); by default
    /// twice the job's working estimate and 256 MiB.
    pub mem: Option<String>,
    /// CPUs a task; the job's threads.
    pub cpus_per_task: usize,
    /// Time limit a task, as `sbatch --time` takes it.
    pub time: Option<String>,
}

/// One `sbatch` this submission made.
#[derive(Debug, Clone, Serialize)]
pub struct Submitted {
    pub script: PathBuf,
    pub step: String,
    /// The plan's jobs it runs (`--job`), none for the finish.
    pub jobs: Vec<usize>,
    pub slurm_job_id: String,
}

/// The batch script of each step, and the finish's, in the order they run.
struct Script {
    path: PathBuf,
    /// The step's name, first and last job; none for the finish. Array
    /// task i runs job `first + i`.
    step: Option<(String, usize, usize)>,
}

/// The prefix of every Slurm job name of the plan in `dir`: one plan's
/// jobs are told from another's in `squeue`.
fn job_name_prefix(dir: &Path) -> Result<String> {
    let absolute = std::fs::canonicalize(dir).with_context(|| dir.display().to_string())?;
    let hash = sha256_bytes(absolute.as_os_str().as_encoded_bytes());
    Ok(format!("relevo-{}", &hash[..8]))
}

/// `s` quoted for a POSIX shell.
fn quoted(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// The scripts of `plan` in `dir/slurm/`, in the order they run.
fn scripts(dir: &Path, plan: &dyn Jobs) -> Result<Vec<Script>> {
    let slurm = dir.join("slurm");
    let steps = plan.steps()?;
    let mut out: Vec<Script> = steps
        .iter()
        .enumerate()
        .map(|(i, s)| Script {
            path: slurm.join(format!("{i:02}-{}.sbatch", s.0.replace(' ', "-"))),
            step: Some(s.clone()),
        })
        .collect();
    out.push(Script {
        path: slurm.join(format!("{:02}-finish.sbatch", steps.len())),
        step: None,
    });
    Ok(out)
}

/// Write the plan's batch scripts with `options`, replacing earlier ones.
pub fn write_scripts(dir: &Path, plan: &dyn Jobs, options: &SlurmOptions) -> Result<()> {
    let dir_abs = std::fs::canonicalize(dir).with_context(|| dir.display().to_string())?;
    let slurm = dir_abs.join("slurm");
    std::fs::create_dir_all(&slurm).with_context(|| slurm.display().to_string())?;
    let exe = std::env::current_exe().context("cannot find the relevo executable")?;
    let prefix = job_name_prefix(dir)?;
    let cpus = options.cpus_per_task.max(1);
    let mem = match &options.mem {
        Some(m) => m.clone(),
        None => format!("{}M", ((2 * plan.working_bytes(cpus)?) >> 20) + 256),
    };
    let subcommand = plan.subcommand().join(" ");
    let relevo = format!("{} {subcommand}", quoted(&exe.display().to_string()));
    let plan_dir = quoted(&dir_abs.display().to_string());
    for (i, script) in scripts(&dir_abs, plan)?.iter().enumerate() {
        let stem = script
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        let (what, array, command) = match &script.step {
            Some((name, first, last)) => (
                format!(
                    "step \"{name}\": jobs {first}–{last} of the plan, array task i runs job \
                     {first} + i"
                ),
                Some(format!("0-{}", last - first)),
                format!("{relevo} --plan {plan_dir} --job $(( {first} + SLURM_ARRAY_TASK_ID ))"),
            ),
            None => (
                "the finish: checks every job is done and writes the result".to_string(),
                None,
                format!("{relevo} --plan {plan_dir} --finish"),
            ),
        };
        let log = match array {
            Some(_) => dir_abs.join("logs").join(format!("{stem}-%a.log")),
            None => dir_abs.join("logs").join(format!("{stem}.log")),
        };
        let mut text = format!(
            "#!/bin/bash\n\
             # Relevo plan {plan_dir}, building {out}: {what}.\n\
             # `relevo {subcommand} --plan DIR --submit slurm` submits it with --array (the\n\
             # tasks left) and --dependency=afterok on the step before; by hand, in step order:\n\
             #   sbatch {path}\n\
             #SBATCH --job-name={prefix}-{i:02}\n",
            plan_dir = dir_abs.display(),
            out = plan.target().display(),
            path = script.path.display(),
        );
        if let Some(a) = &array {
            text.push_str(&format!("#SBATCH --array={a}\n"));
        }
        text.push_str(&format!("#SBATCH --output={}\n", log.display()));
        text.push_str(&format!(
            "#SBATCH --cpus-per-task={cpus}\n#SBATCH --mem={mem}\n"
        ));
        if let Some(p) = &options.partition {
            text.push_str(&format!("#SBATCH --partition={p}\n"));
        }
        if let Some(t) = &options.time {
            text.push_str(&format!("#SBATCH --time={t}\n"));
        }
        text.push_str(&format!(
            "set -euo pipefail\n\
             export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-1}}\"\n\
             exec {command}\n"
        ));
        std::fs::write(&script.path, text).with_context(|| script.path.display().to_string())?;
    }
    Ok(())
}

/// Run a Slurm command, its stdout on success.
fn slurm(program: &str, args: &[String]) -> Result<String> {
    let out = Command::new(program).args(args).output().with_context(|| {
        format!("cannot run {program}: is Slurm's client installed and on PATH?")
    })?;
    if !out.status.success() {
        bail!(
            "{program} {} failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).to_string())
}

/// Submit the jobs of `plan` (in `dir`) that are not done, and its
/// finish; with `options`, the scripts are written anew first (else the
/// ones in `dir/slurm/`, written at the first submission, are used as they
/// are). Refused while jobs of the plan are still queued or running.
pub fn submit(
    dir: &Path,
    plan: &dyn Jobs,
    options: Option<&SlurmOptions>,
) -> Result<Vec<Submitted>> {
    let scripts = scripts(dir, plan)?;
    match options {
        Some(o) => {
            write_scripts(dir, plan, o)?;
        }
        None if !scripts.iter().all(|s| s.path.is_file()) => {
            write_scripts(dir, plan, &SlurmOptions::default())?;
        }
        None => {}
    }
    let prefix = job_name_prefix(dir)?;
    let queue = slurm("squeue", &["-h".into(), "-o".into(), "%i %j %T".into()])?;
    let queued: Vec<&str> = queue
        .lines()
        .filter(|l| {
            l.split_whitespace()
                .nth(1)
                .is_some_and(|n| n.starts_with(&prefix))
        })
        .collect();
    if !queued.is_empty() {
        let ids: Vec<&str> = queued
            .iter()
            .filter_map(|l| l.split_whitespace().next())
            .collect();
        bail!(
            "{}: {} Slurm jobs of this plan are still queued or running ({}); wait for them, \
             or cancel them (scancel {}) and submit again",
            dir.display(),
            queued.len(),
            queued.join("; "),
            ids.join(" ")
        );
    }
    let steps = plan.steps()?;
    let mut left: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for job in plan.unfinished(dir)? {
        let step = steps
            .iter()
            .position(|s| (s.1..=s.2).contains(&job))
            .context("a job of no step of the plan")?;
        left.entry(step).or_default().push(job);
    }
    let mut submitted = Vec::new();
    let mut after: Option<String> = None;
    for (i, script) in scripts.iter().enumerate() {
        let jobs: Vec<usize> = match &script.step {
            Some(_) => match left.get(&i) {
                Some(jobs) => jobs.clone(),
                None => continue,
            },
            None => Vec::new(),
        };
        let mut args = vec!["--parsable".to_string()];
        if let Some((_, first, _)) = &script.step {
            let tasks: Vec<String> = jobs.iter().map(|j| (j - first).to_string()).collect();
            args.push(format!("--array={}", tasks.join(",")));
        }
        if let Some(id) = &after {
            args.push(format!("--dependency=afterok:{id}"));
        }
        args.push(script.path.display().to_string());
        let out = slurm("sbatch", &args)?;
        // `--parsable` prints `id` or `id;cluster`.
        let id = out.trim().split(';').next().unwrap_or_default().to_string();
        if id.is_empty() {
            bail!("sbatch printed no job id for {}", script.path.display());
        }
        submitted.push(Submitted {
            script: script.path.clone(),
            step: script
                .step
                .as_ref()
                .map_or_else(|| "finish".into(), |s| s.0.clone()),
            jobs,
            slurm_job_id: id.clone(),
        });
        after = Some(id);
    }
    Ok(submitted)
}
