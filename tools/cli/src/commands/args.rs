//! Argument types and parsers that several subcommands share.

use relevo_core::lp::ErrorMetric;
use relevo_core::raster::encoding::Encoding;

/// How tiles encode heights.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum EncodingArg {
    Plain,
    TerrainRgb,
    Terrarium,
}

impl From<EncodingArg> for Encoding {
    fn from(e: EncodingArg) -> Encoding {
        match e {
            EncodingArg::Plain => Encoding::Plain,
            EncodingArg::TerrainRgb => Encoding::TerrainRgb,
            EncodingArg::Terrarium => Encoding::Terrarium,
        }
    }
}

/// How the hierarchy measures a vertex's own error (relevo-core's
/// `ErrorMetric`).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum ErrorMetricArg {
    /// The largest vertical distance from the grid points a vertex's
    /// triangles cover: `mesh --max-error` is then a true bound.
    Bound,
    /// The vertex's height against its hypotenuse's midpoint, as
    /// @mapbox/martini (its meshes, vertex for vertex).
    Midpoint,
}

impl From<ErrorMetricArg> for ErrorMetric {
    fn from(m: ErrorMetricArg) -> ErrorMetric {
        match m {
            ErrorMetricArg::Bound => ErrorMetric::Bound,
            ErrorMetricArg::Midpoint => ErrorMetric::Midpoint,
        }
    }
}

/// `LOW,HIGH` percentiles with 0 ≤ LOW < HIGH ≤ 100.
pub(crate) fn parse_percentiles(text: &str) -> Result<[f64; 2], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{text:?} is not two numbers"))?;
    match values[..] {
        [lo, hi] if (0.0..100.0).contains(&lo) && lo < hi && hi <= 100.0 => Ok([lo, hi]),
        _ => Err("--stretch takes LOW,HIGH percentiles with 0 <= LOW < HIGH <= 100".into()),
    }
}

/// Renders at named cameras (`relevo check --bless`, `relevo diff`).
#[derive(clap::Args, Debug)]
pub struct NamedCameras {
    /// A render of relevo-core's raycaster at NAME=X,Y,Z,HEADING[,PITCHdeg][,INCL]
    /// (repeatable).
    #[arg(
        long = "camera",
        value_name = "NAME=CAMERA",
        allow_hyphen_values = true
    )]
    pub cameras: Vec<String>,
    /// Size of those renders, WIDTHxHEIGHT.
    #[arg(long, default_value = "480x270", value_parser = relevo_core::scene::parse_size)]
    pub render_size: [u32; 2],
}

impl NamedCameras {
    /// The renders asked for (their files left for the caller to name).
    pub fn renders(&self) -> anyhow::Result<Vec<relevo_core::golden::RenderRecord>> {
        self.cameras
            .iter()
            .map(|spec| named_camera(spec, self.render_size))
            .collect()
    }
}

/// One `--camera NAME=CAMERA`.
fn named_camera(spec: &str, size: [u32; 2]) -> anyhow::Result<relevo_core::golden::RenderRecord> {
    let (name, camera) = spec
        .split_once('=')
        .filter(|(n, _)| {
            !n.is_empty()
                && n
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        })
        .ok_or_else(|| {
            anyhow::anyhow!(
                "--camera {spec:?}: expected NAME=X,Y,Z,HEADING with NAME of letters, digits, _ or -"
            )
        })?;
    relevo_core::scene::CameraPose::parse(camera)
        .map_err(|e| anyhow::anyhow!("--camera {name}: {e}"))?;
    Ok(relevo_core::golden::RenderRecord {
        name: name.to_string(),
        camera: camera.to_string(),
        size,
        file: String::new(),
    })
}

/// Schedulers `--submit` sends a plan's jobs to.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Scheduler {
    Slurm,
}

/// A plan's flags (`prep` and `veg detect`): make one, run one of its
/// jobs, finish it, or submit it to a scheduler.
#[derive(clap::Args, Debug)]
pub struct PlanArgs {
    /// Split the work into jobs for several machines sharing a file
    /// system (see docs/guide.md, "Running on a Slurm cluster"): with the
    /// inputs and --jobs, write the plan in this folder; alone, act on the
    /// plan there (--job, --finish, --submit).
    #[arg(long, value_name = "DIR")]
    pub plan: Option<std::path::PathBuf>,
    /// With --plan and the inputs: cut each step of the work into at most
    /// N jobs.
    #[arg(long, value_name = "N", requires = "plan", default_value_t = 1)]
    pub jobs: usize,
    /// With --plan: run job K (idempotent: what it finds done is kept).
    #[arg(long, value_name = "K", requires = "plan", conflicts_with_all = ["finish", "submit"])]
    pub job: Option<usize>,
    /// With --plan: check every job is done and write the result.
    #[arg(long, requires = "plan", conflicts_with = "submit")]
    pub finish: bool,
    /// With --plan: how far the plan has come, step by step.
    #[arg(long, requires = "plan", conflicts_with_all = ["job", "finish", "submit"])]
    pub status: bool,
    /// With --plan: submit the jobs not done, step after step, then the
    /// finish, to a scheduler (Slurm's sbatch); prints the job ids.
    #[arg(long, value_enum, requires = "plan")]
    pub submit: Option<Scheduler>,
    /// With --submit: the Slurm partition.
    #[arg(long, requires = "submit")]
    pub partition: Option<String>,
    /// With --submit: memory a task, as sbatch takes it (e.g. 4G; default
    /// twice the working estimate and 256M).
    #[arg(long, requires = "submit")]
    pub mem: Option<String>,
    /// With --submit: CPUs a task, the threads each job runs.
    #[arg(long, requires = "submit", default_value_t = 1)]
    pub cpus_per_task: usize,
    /// With --submit: time limit a task, as sbatch takes it (e.g. 2:00:00).
    #[arg(long, requires = "submit")]
    pub time: Option<String>,
}

impl PlanArgs {
    /// `--status`: each step's jobs done of all (as JSON with `json`).
    pub fn print_status(
        &self,
        dir: &std::path::Path,
        plan: &dyn crate::plan::Jobs,
        json: bool,
    ) -> anyhow::Result<()> {
        let status = crate::plan::status(dir, plan)?;
        if json {
            println!("{}", serde_json::to_string(&status)?);
            return Ok(());
        }
        for s in &status.steps {
            println!("{:>18}: {} of {} jobs done", s.step, s.done, s.jobs);
        }
        let (done, all) = status
            .steps
            .iter()
            .fold((0, 0), |(d, a), s| (d + s.done, a + s.jobs));
        let next = if status.finished {
            format!("; finished: {}", plan.target().display())
        } else if done == all {
            "; finish with --finish".to_string()
        } else {
            String::new()
        };
        println!("{}: {done} of {all} jobs done{next}", dir.display());
        Ok(())
    }

    /// `--submit`: the jobs of `plan` (in `dir`) not done, then its finish;
    /// the ids printed (as JSON with `json`).
    pub fn submit_to(
        &self,
        dir: &std::path::Path,
        plan: &dyn crate::plan::Jobs,
        json: bool,
    ) -> anyhow::Result<()> {
        let Some(Scheduler::Slurm) = self.submit else {
            anyhow::bail!(
                "{}: say what to do with the plan: --job K, --status, --finish or --submit slurm",
                dir.display()
            );
        };
        if plan.finished(dir) {
            anyhow::bail!(
                "{}: this plan is already finished: {}",
                dir.display(),
                plan.target().display()
            );
        }
        let given = self.partition.is_some()
            || self.mem.is_some()
            || self.time.is_some()
            || self.cpus_per_task != 1;
        let options = crate::plan::slurm::SlurmOptions {
            partition: self.partition.clone(),
            mem: self.mem.clone(),
            cpus_per_task: self.cpus_per_task,
            time: self.time.clone(),
        };
        let submitted = crate::plan::slurm::submit(dir, plan, given.then_some(&options))?;
        if json {
            println!("{}", serde_json::to_string(&submitted)?);
        } else {
            for s in &submitted {
                let jobs: Vec<String> = s.jobs.iter().map(|j| j.to_string()).collect();
                let jobs = if jobs.is_empty() {
                    String::new()
                } else {
                    format!(" (jobs {})", jobs.join(" "))
                };
                println!("Slurm job {:>8}: {}{jobs}", s.slurm_job_id, s.step);
            }
        }
        Ok(())
    }
}
