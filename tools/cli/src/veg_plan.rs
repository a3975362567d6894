//! `relevo veg detect IMAGE --plan DIR --jobs N`: vegetation detection split
//! into jobs that machines sharing a file system run side by side — by
//! hand, or as Slurm array jobs (`prep::slurm`).
//!
//! The plan learns once, reading only the image's tiles that hold samples
//! (and each sample's window when the thresholds follow their contrast),
//! and keeps what it learnt ([`Model`]) in `DIR/plan.json`. The image's
//! tiles — each a core it owns and a margin of context around it — are cut
//! into N jobs of consecutive tiles; job K reads only its tiles' windows
//! and writes the objects its tiles own to `DIR/jobs/K.json`. A crown on a
//! window's border lies in one tile's core, so it is found once. The
//! finish gathers the jobs' objects in tile order, numbers them as one
//! extraction does and writes the database: the bytes `relevo veg detect`
//! writes on one machine.

use crate::output;
use crate::plan::Jobs;
use crate::plan::{absolute, job_record, write_json};
use crate::veg_io::{self, ImageReader};
use anyhow::{bail, Context, Result};
use relevo_core::geo::GeoTransform;
use relevo_core::veg::db;
use relevo_core::veg::detect::Object;
use relevo_core::veg::pipeline::{world_objects, Model, PixelSource, VegOptions};
use relevo_core::veg::samples::{self, Sample};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `format` of a vegetation plan's `plan.json`.
pub const VEG_PLAN_FORMAT: &str = "relevo-veg-plan";
const VERSION: u32 = 1;

/// How the image is read, as `veg detect` was told.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ImageSpec {
    /// The image (absolute).
    pub path: PathBuf,
    pub bands: Option<Vec<usize>>,
    pub stretch: Option<[f64; 2]>,
    pub pixel_size: Option<f64>,
}

impl ImageSpec {
    fn open(&self) -> Result<ImageReader> {
        ImageReader::open(
            &self.path,
            self.bands.as_deref(),
            self.stretch,
            self.pixel_size,
        )
    }
}

/// `DIR/plan.json` of a vegetation plan.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct VegPlan {
    pub format: String,
    pub format_version: u32,
    pub image: ImageSpec,
    /// The database the finish writes (absolute), and its GeoPackage copy.
    pub out: PathBuf,
    pub gpkg: Option<PathBuf>,
    pub force: bool,
    pub crs_wkt: String,
    pub geotransform: Option<GeoTransform>,
    pub model: Model,
    /// Each job's tiles: `[first, end)` in the model's tile order.
    pub jobs: Vec<[usize; 2]>,
}

/// What job K did (`DIR/jobs/K.json`): the objects its tiles own.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct VegJobRecord {
    pub job: usize,
    pub tiles: [usize; 2],
    pub ms: f64,
    pub host: String,
    pub memory_budget_bytes: u64,
    pub objects: Vec<Object>,
}

/// What `veg detect --plan` is given when it makes a plan.
pub struct VegPlanRequest<'a> {
    pub image: ImageSpec,
    pub samples: &'a Path,
    pub options: VegOptions,
    pub out: &'a Path,
    pub gpkg: Option<&'a Path>,
    pub jobs: usize,
    pub force: bool,
}

impl VegPlan {
    /// Read `dir/plan.json`; refused when its jobs do not cut the
    /// model's tiles or its crown template cannot be used.
    pub fn load(dir: &Path) -> Result<VegPlan> {
        let plan: VegPlan = crate::plan::load(dir, VEG_PLAN_FORMAT, VERSION)?;
        let tiles = plan.model.tiles().len();
        let mut next = 0;
        for &[from, to] in &plan.jobs {
            if from != next || to < from || to > tiles {
                bail!(
                    "{}: its jobs do not cut the {tiles} tiles in order; make the plan again",
                    dir.join("plan.json").display()
                );
            }
            next = to;
        }
        if next != tiles {
            bail!(
                "{}: its jobs leave tiles out; make the plan again",
                dir.join("plan.json").display()
            );
        }
        if let Some(problem) = plan.model.placement.problem() {
            bail!(
                "{}: {problem}; make the plan again",
                dir.join("plan.json").display()
            );
        }
        Ok(plan)
    }

    /// Learn from the samples and write the plan in `dir` (a new or empty
    /// folder, or an earlier plan's with `force`).
    pub fn create(dir: &Path, r: VegPlanRequest) -> Result<VegPlan> {
        if r.jobs == 0 {
            bail!("--jobs must be at least 1");
        }
        crate::plan::prepare(dir, r.force)?;
        let image = ImageSpec {
            path: absolute(&r.image.path)?,
            ..r.image
        };
        let reader = image.open()?;
        let (w, h) = reader.size();
        let samples = samples::read_file(r.samples, reader.geotransform, w, h)?;
        let gain = match r.options.contrast_at(reader.pixel_m) {
            relevo_core::veg::pipeline::Contrast::Samples => {
                VegOptions::samples_gain(samples_contrast(&reader, &samples)?)
            }
            _ => 1.0,
        };
        let model = Model::learn(&reader, reader.pixel_m, &samples, &r.options, gain)
            .with_context(|| image.path.display().to_string())?;
        let tiles = model.tiles().len();
        let n = r.jobs.clamp(1, tiles);
        let jobs = (0..n)
            .map(|k| [k * tiles / n, (k + 1) * tiles / n])
            .collect();
        let plan = VegPlan {
            format: VEG_PLAN_FORMAT.into(),
            format_version: VERSION,
            image,
            out: absolute(r.out)?,
            gpkg: r.gpkg.map(absolute).transpose()?,
            force: r.force,
            crs_wkt: reader.crs_wkt.clone(),
            geotransform: reader.geotransform,
            model,
            jobs,
        };
        crate::plan::save(dir, &plan)?;
        Ok(plan)
    }

    /// Run job `k`: analyse its tiles, reading only their windows.
    pub fn run_job(&self, dir: &Path, k: usize) -> Result<VegJobRecord> {
        let Some(&[from, to]) = self.jobs.get(k) else {
            bail!(
                "{}: no job {k}; the plan has jobs 0–{}",
                dir.display(),
                self.jobs.len() - 1
            );
        };
        let start = Instant::now();
        let reader = self.image.open()?;
        if reader.size() != (self.model.size[0], self.model.size[1]) {
            bail!(
                "{}: {}×{} pixels, not the {}×{} the plan was made for; make the plan again",
                self.image.path.display(),
                reader.width,
                reader.height,
                self.model.size[0],
                self.model.size[1]
            );
        }
        let tiles = self.model.tiles()[from..to].to_vec();
        let objects = self
            .model
            .analyse(&reader, tiles)
            .with_context(|| self.image.path.display().to_string())?;
        let record = VegJobRecord {
            job: k,
            tiles: [from, to],
            ms: start.elapsed().as_secs_f64() * 1e3,
            host: crate::plan::hostname(),
            memory_budget_bytes: relevo_core::memory::budget(),
            objects,
        };
        write_json(&job_record(dir, k), &record)?;
        Ok(record)
    }

    /// The jobs without a record.
    pub fn missing(&self, dir: &Path) -> Vec<usize> {
        (0..self.jobs.len())
            .filter(|&k| !job_record(dir, k).is_file())
            .collect()
    }

    /// Gather the jobs' objects into the database (and its GeoPackage);
    /// refused, naming the jobs left, unless every job is done. Returns the
    /// objects written.
    pub fn finish(&self, dir: &Path) -> Result<usize> {
        let missing = self.missing(dir);
        if !missing.is_empty() {
            let list: Vec<String> = missing.iter().map(|k| k.to_string()).collect();
            bail!(
                "{}: {} jobs are not done: {}. Run each with `relevo veg detect --plan {} --job \
                 K`, or resubmit them with `relevo veg detect --plan {} --submit slurm`; then \
                 finish again",
                dir.display(),
                missing.len(),
                list.join(", "),
                dir.display(),
                dir.display()
            );
        }
        let mut found = Vec::new();
        for k in 0..self.jobs.len() {
            let path = job_record(dir, k);
            let record: VegJobRecord =
                serde_json::from_str(&relevo_core::files::read_to_string(&path)?)
                    .with_context(|| path.display().to_string())?;
            found.extend(record.objects);
        }
        // As one extraction gathers them: by row, then column, tile order
        // kept among equals.
        found.sort_by(|a, b| a.y.total_cmp(&b.y).then(a.x.total_cmp(&b.x)));
        let found = self.model.marked_places.hold(found);
        let objects =
            world_objects(
                &found,
                &self.model.classes,
                self.model.pixel_m,
                |x, y| match &self.geotransform {
                    Some(g) => g.apply(x, y),
                    None => (x, y),
                },
            );
        let mut paths = vec![self.out.as_path()];
        paths.extend(self.gpkg.as_deref());
        output::check(&paths, self.force)?;
        let mut outputs = relevo_core::atomic::Outputs::default();
        output::write_atomic(&outputs.pending(&self.out), db::to_csv(&objects).as_bytes())?;
        if let Some(path) = &self.gpkg {
            veg_io::write_gpkg(&outputs.pending(path), &objects, &self.crs_wkt)?;
        }
        outputs.commit()?;
        Ok(objects.len())
    }
}

/// The samples' contrast as one extraction measures it on the whole image,
/// each sample measured on the window it covers.
fn samples_contrast(reader: &ImageReader, samples: &[Sample]) -> Result<Option<f32>> {
    let (w, h) = reader.size();
    let mut spreads = Vec::new();
    for s in samples {
        let [x0, y0, x1, y1] = s.pixel_bounds(w, h);
        if x1 <= x0 || y1 <= y0 {
            continue;
        }
        let window = reader.window([x0, y0, x1, y1], Vec::new())?;
        let local = s.translated(-(x0 as f64), -(y0 as f64));
        spreads.extend(local.brightness_std(window.image()));
    }
    Ok(samples::median_spread(spreads))
}

impl Jobs for VegPlan {
    fn subcommand(&self) -> &'static [&'static str] {
        &["veg", "detect"]
    }

    fn steps(&self) -> Result<Vec<(String, usize, usize)>> {
        Ok(vec![(
            "vegetation".into(),
            0,
            self.jobs.len().saturating_sub(1),
        )])
    }

    fn unfinished(&self, dir: &Path) -> Result<Vec<usize>> {
        Ok(self.missing(dir))
    }

    /// The database is written and no job was run again since.
    fn finished(&self, dir: &Path) -> bool {
        let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
        let Some(written) = modified(&self.out) else {
            return false;
        };
        (0..self.jobs.len()).all(|k| modified(&job_record(dir, k)).is_some_and(|t| t <= written))
    }

    fn target(&self) -> &Path {
        &self.out
    }

    fn working_bytes(&self, threads: usize) -> Result<u64> {
        Ok(self.model.working_bytes(threads))
    }
}
