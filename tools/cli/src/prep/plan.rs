//! `relevo prep --plan DIR`: a pyramid build split into jobs that run on
//! several machines sharing a file system — by hand, or as Slurm array
//! jobs (`slurm`).
//!
//! - `relevo prep REGION --tiled --plan DIR --jobs N --out OUT` reads the
//!   input once (the scan for voids, or the in-memory grid stages, which
//!   then write the heights themselves), starts the build in OUT's staging
//!   folder and writes `DIR/plan.json`: the region, the pyramid's
//!   description, how the heights are read, and the build's steps, each
//!   cut into at most N jobs ([`relevo_core::pyramid::jobs`]).
//! - `relevo prep --plan DIR --job K` runs job K: its tiles not yet done,
//!   each marked once its data is on the disk; refused while a step before
//!   its own is incomplete. Run again, it finishes what a killed run left.
//! - `relevo prep --plan DIR --finish` checks that every job is done
//!   (naming those that are not, and the commands that run them), writes
//!   the manifest, validates the pyramid and moves it to OUT: the bytes of
//!   `relevo prep REGION --tiled --out OUT` on one machine.
//!
//! Every job records what it did in `DIR/jobs/K.json`; the manifest's
//! timings are their sums.

use super::direct::DirectSource;
use super::region::RegionSpec;
use super::tiled::{
    height_source, region_name, write_options, Heights, TiledOptions, TiledSummary,
};
use crate::plan::absolute;
use anyhow::{bail, Context, Result};
use relevo_core::bundle::{staging_path, StageTiming, StagedFiles, PLAN_MARK};
use relevo_core::pyramid::jobs::{self, Job};
use relevo_core::pyramid::{
    self, build, BuildReport, PyramidDescription, Step, TileLayout, WriteOptions,
};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `format` of a plan's `plan.json`.
pub const PLAN_FORMAT: &str = "relevo-plan";
const PLAN_VERSION: u32 = 1;

/// `DIR/plan.json`: everything a job needs to run without the user's
/// command line.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Plan {
    pub format: String,
    pub format_version: u32,
    /// The bundle the plan writes (absolute).
    pub out: PathBuf,
    pub region: RegionSpec,
    pub description: PyramidDescription,
    pub write: WriteOptions,
    /// Most jobs a step is cut into.
    pub jobs_per_step: usize,
    pub heights: PlannedHeights,
    /// The jobs of each step, for people reading the plan.
    pub steps: Vec<PlannedStep>,
}

/// How the heights step gets the DEM.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlannedHeights {
    /// The jobs read the DEM window by window, filling these holes
    /// (`[c0, r0, c1, r1]`, inclusive), which the plan's scan found.
    Windows { holes: Vec<[usize; 4]> },
    /// The plan wrote the heights (the grid stages ran in memory).
    Written,
}

/// A step and the jobs it is cut into.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PlannedStep {
    pub step: Step,
    pub name: String,
    /// First and last job.
    pub jobs: [usize; 2],
    pub tiles: usize,
}

/// What a job did (`DIR/jobs/K.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct JobRecord {
    pub job: usize,
    pub step: String,
    pub tiles: usize,
    /// Tiles this run computed (the others were done before it).
    pub computed: usize,
    pub ms: f64,
    pub host: String,
    pub threads: usize,
    /// The memory budget the job ran under (`--max-memory`, cgroup,
    /// Slurm's `--mem`, available memory: the smallest), bytes.
    pub memory_budget_bytes: u64,
    /// Slurm's job and array task ids, when Slurm ran it.
    pub slurm: Option<String>,
}

impl Plan {
    /// Read `dir/plan.json`.
    pub fn load(dir: &Path) -> Result<Plan> {
        crate::plan::load(dir, PLAN_FORMAT, PLAN_VERSION)
    }

    pub fn layout(&self) -> Result<TileLayout> {
        Ok(TileLayout::new(
            self.description.grid.side,
            self.write.tile_cells,
        )?)
    }

    /// The plan's jobs, numbered as `--job` takes them.
    pub fn jobs(&self) -> Result<Vec<Job>> {
        Ok(jobs::jobs(
            &self.layout()?,
            self.write.build.drape,
            self.jobs_per_step,
        ))
    }

    /// The build's tile files, shared by the jobs.
    pub fn store(&self) -> Result<pyramid::store::TileStore> {
        Ok(pyramid::open_build(&self.out, self.layout()?)?)
    }
}

impl crate::plan::Jobs for Plan {
    fn subcommand(&self) -> &'static [&'static str] {
        &["prep"]
    }

    /// From the jobs the plan's tiling gives (not the table kept for
    /// people, which an edit could make disagree).
    fn steps(&self) -> Result<Vec<(String, usize, usize)>> {
        Ok(step_table(&self.jobs()?)
            .into_iter()
            .map(|s| (s.name, s.jobs[0], s.jobs[1]))
            .collect())
    }

    fn finished(&self, _: &Path) -> bool {
        !staging_path(&self.out).exists() && pyramid::Pyramid::open(&self.out).is_ok()
    }

    fn unfinished(&self, _: &Path) -> Result<Vec<usize>> {
        Ok(unfinished(self)?
            .into_iter()
            .map(|(j, _)| j.index)
            .collect())
    }

    fn target(&self) -> &Path {
        &self.out
    }

    fn working_bytes(&self, threads: usize) -> Result<u64> {
        Ok(build::working_bytes(&self.layout()?, threads))
    }
}

/// Each step of `jobs` (in order) with its first and last job and tiles.
fn step_table(jobs: &[Job]) -> Vec<PlannedStep> {
    let mut table: Vec<PlannedStep> = Vec::new();
    for job in jobs {
        match table.last_mut() {
            Some(s) if s.step == job.step => {
                s.jobs[1] = job.index;
                s.tiles += job.tiles.len();
            }
            _ => table.push(PlannedStep {
                step: job.step,
                name: job.step.name(),
                jobs: [job.index, job.index],
                tiles: job.tiles.len(),
            }),
        }
    }
    table
}

/// How a plan is made.
#[derive(Debug, Clone, Copy)]
pub struct PlanOptions {
    /// Cells a tile side (2^k); none: the default for the grid.
    pub tile_cells: Option<usize>,
    pub jobs_per_step: usize,
    /// Replace an existing plan in DIR and, at the finish, the bundle.
    pub force: bool,
}

/// Plan the pyramid of `region` at `out` in `dir`: the input read once,
/// the build started in `out`'s staging folder, `dir/plan.json` written.
pub fn create(region: &RegionSpec, out: &Path, dir: &Path, options: PlanOptions) -> Result<Plan> {
    if region.image.is_some() || region.vegetation.is_some() || region.clusters.is_some() {
        bail!(
            "the jobs of a plan derive the pyramid's drape from the heights and detect no \
             vegetation; drop [image], [vegetation] and [clusters], or build the pyramid on one \
             machine with `prep --tiled`, which reads them"
        );
    }
    if options.jobs_per_step == 0 {
        bail!("--jobs must be at least 1");
    }
    crate::plan::prepare(dir, options.force)?;
    let out = absolute(out)?;
    if out.symlink_metadata().is_ok() && !options.force {
        bail!(
            "{}: already exists (pass --force to replace it at the finish)",
            out.display()
        );
    }
    let name = region_name(region, &out);
    // The manifest names the inputs as given, as `prep` does; the jobs,
    // which may run in another folder, read them by absolute paths.
    let (source, description, _) = height_source(region, &name, &out, options.tile_cells, false)?;
    let mut region = region.clone();
    for f in &mut region.dem.files {
        *f = absolute(f)?;
    }
    let tiled = TiledOptions {
        tile_cells: options.tile_cells,
        force: options.force,
        resume: false,
    };
    let write = write_options(&region, &description, tiled);
    let (staging, store) = pyramid::start_build(&out, &description, &write)?;
    let layout = store.layout;
    let heights = match &source {
        Heights::Windows(d) => PlannedHeights::Windows {
            holes: d.holes().to_vec(),
        },
        Heights::Grid(_) => {
            // The grid is in memory now and in no job's: write its tiles here.
            let bar = crate::progress::pass_bar();
            build::run_step(
                Some(source.source()),
                None,
                &store,
                &write.build,
                Step::Heights,
                &Step::Heights.tiles(&layout),
                &|p| crate::progress::show_pass(&bar, p),
            )?;
            bar.finish_and_clear();
            PlannedHeights::Written
        }
    };
    drop(store);
    let mark = staging.dir().join(PLAN_MARK);
    let plan_dir = std::fs::canonicalize(dir)?;
    std::fs::write(&mark, plan_dir.display().to_string())
        .with_context(|| mark.display().to_string())?;
    staging.keep();
    let steps = step_table(&jobs::jobs(
        &layout,
        write.build.drape,
        options.jobs_per_step,
    ));
    let plan = Plan {
        format: PLAN_FORMAT.into(),
        format_version: PLAN_VERSION,
        out,
        region,
        description,
        write,
        jobs_per_step: options.jobs_per_step,
        heights,
        steps,
    };
    crate::plan::save(dir, &plan)?;
    Ok(plan)
}

/// Run job `index` of the plan in `dir`.
pub fn run_job(dir: &Path, index: usize) -> Result<JobRecord> {
    let plan = Plan::load(dir)?;
    let layout = plan.layout()?;
    let all = plan.jobs()?;
    let job = all.get(index).with_context(|| {
        format!(
            "{}: no job {index}; the plan has jobs 0–{}",
            dir.display(),
            all.len() - 1
        )
    })?;
    build::check_working_memory(&layout)?;
    let store = plan.store()?;
    let before = job.step.missing(&store, &job.tiles)?.len();
    let source = match (&plan.heights, job.step) {
        (PlannedHeights::Windows { holes }, Step::Heights) => {
            let changed = || {
                format!(
                    "{}: the DEM no longer reads as it did when the plan was made; make the \
                     plan again",
                    plan.region.dem.files[0].display()
                )
            };
            let source = DirectSource::open(&plan.region)?.with_context(changed)?;
            if source.grid != plan.description.grid {
                bail!(changed());
            }
            Some(source.with_holes(holes.clone()))
        }
        _ => None,
    };
    let bar = crate::progress::pass_bar();
    let ms = jobs::run_job(
        source.as_ref().map(|s| s as &dyn pyramid::HeightSource),
        &store,
        &plan.write.build,
        &all,
        index,
        &|p| crate::progress::show_pass(&bar, p),
    )?;
    bar.finish_and_clear();
    let slurm = std::env::var("SLURM_ARRAY_JOB_ID")
        .ok()
        .map(|id| {
            let task = std::env::var("SLURM_ARRAY_TASK_ID").unwrap_or_default();
            format!("{id}_{task}")
        })
        .or_else(|| std::env::var("SLURM_JOB_ID").ok());
    let record = JobRecord {
        job: index,
        step: job.step.name(),
        tiles: job.tiles.len(),
        computed: before,
        ms,
        host: crate::plan::hostname(),
        threads: rayon::current_num_threads(),
        memory_budget_bytes: relevo_core::memory::budget(),
        slurm,
    };
    crate::plan::write_json(&crate::plan::job_record(dir, index), &record)?;
    Ok(record)
}

/// The plan's jobs not done, each with its step and tiles left, in order.
pub fn unfinished(plan: &Plan) -> Result<Vec<(Job, usize)>> {
    let all = plan.jobs()?;
    let store = plan.store()?;
    Ok(jobs::unfinished(&store, &all)?
        .into_iter()
        .map(|(i, left)| (all[i].clone(), left.len()))
        .collect())
}

/// Finish the plan in `dir`: refused, naming the jobs left and how to run
/// them, unless every job is done; else the pyramid sealed and moved to
/// its place.
pub fn finish(dir: &Path) -> Result<TiledSummary> {
    let plan = Plan::load(dir)?;
    if crate::plan::Jobs::finished(&plan, dir) {
        bail!(
            "{}: this plan is already finished; its pyramid is {}",
            dir.display(),
            plan.out.display()
        );
    }
    let left = unfinished(&plan)?;
    if !left.is_empty() {
        let names: Vec<String> = left
            .iter()
            .map(|(job, n)| {
                let tiles = if *n == 1 { "tile" } else { "tiles" };
                format!("{} ({}, {n} {tiles})", job.index, job.step.name())
            })
            .collect();
        let indices: Vec<String> = left.iter().map(|(j, _)| j.index.to_string()).collect();
        bail!(
            "{}: {} jobs are not done: {}. Run each with `relevo prep --plan {} --job K` \
             (K = {}), in step order, or resubmit them all with `relevo prep --plan {} \
             --submit slurm`; then finish again",
            dir.display(),
            left.len(),
            names.join(", "),
            dir.display(),
            indices.join(" "),
            dir.display()
        );
    }
    let start = Instant::now();
    let options = WriteOptions {
        resume: true,
        ..plan.write
    };
    let (staging, store) = pyramid::start_build(&plan.out, &plan.description, &options)?;
    let (height_range_m, valid_vertices) = build::statistics(&store)?;
    let mut timings = job_timings(dir, &plan)?;
    StageTiming::add(
        &mut timings,
        "statistics",
        start.elapsed().as_secs_f64() * 1e3,
    );
    let report = BuildReport {
        height_range_m,
        valid_vertices,
        timings,
    };
    let extras = StagedFiles::new(staging.dir());
    let bundle = pyramid::seal_build(
        staging,
        store,
        report,
        plan.description.clone(),
        &options,
        extras,
        &|_| Vec::new(),
    )?;
    let pyramid_ms = start.elapsed().as_secs_f64() * 1e3;
    let windows = matches!(plan.heights, PlannedHeights::Windows { .. });
    TiledSummary::of(bundle, windows, 0.0, pyramid_ms)
}

/// The jobs' wall times summed by the stage the manifest records them
/// under (a job run twice counts its last run).
fn job_timings(dir: &Path, plan: &Plan) -> Result<Vec<StageTiming>> {
    let mut timings: Vec<StageTiming> = Vec::new();
    for job in plan.jobs()? {
        let path = crate::plan::job_record(dir, job.index);
        let Ok(text) = std::fs::read_to_string(&path) else {
            continue; // done by a run that left no record (killed after its last mark)
        };
        let record: JobRecord =
            serde_json::from_str(&text).with_context(|| path.display().to_string())?;
        StageTiming::add(&mut timings, job.step.timing_name(), record.ms);
    }
    Ok(timings)
}
