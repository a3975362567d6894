//! `relevo veg detect | eval`: vegetation from marked samples, and its score
//! against truth boxes.

use super::args::{parse_percentiles, PlanArgs};
use crate::output;
use crate::veg_io;
use crate::veg_plan::{ImageSpec, VegPlan, VegPlanRequest};
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use relevo_core::raster::png::encode_rgba;
use relevo_core::veg::pipeline::{self, Contrast, DetectionMode, VegOptions};
use relevo_core::veg::{baseline, db, eval, samples};
use std::path::{Path, PathBuf};

#[derive(Subcommand, Debug)]
pub enum VegCommand {
    /// Split-and-merge the image, learn Haar signatures from the samples,
    /// classify every region and write the vegetation objects.
    #[command(
        after_help = "Samples: a semicolon CSV `class;xmin;ymin;xmax;ymax` of pixel rectangles, or
GeoJSON polygons with a `class` property in the image CRS. Samples of the
negative class (default `other`) are counter-examples; every other class is
vegetation.

Examples:
  relevo veg detect ortho.tif --samples marks.csv --out trees.csv --gpkg trees.gpkg
  relevo veg detect crop.png --pixel-size 0.1 --samples marks.csv --out trees.csv --overlay check.png
  relevo veg detect landsat.tif --bands 3,2,1 --stretch 1,99 --samples forest.geojson \\
      --density 150 --labels regions.tif --out forest.csv
  relevo veg detect scene.tif --bands 3,2,1 --contrast samples --samples forest.csv \\
      --out forest.csv   # coarse imagery: thresholds scaled to the samples' contrast too
  relevo veg detect crop.png --pixel-size 0.1 --samples round2.csv --crown-spacing 3 \\
      --crown-size 5.7 --out trees.csv   # keep the spacing and size an earlier round reported
  relevo veg detect rgb.vrt --samples marks.csv --out forest.csv --land-cover labels.gpkg
  relevo veg detect state_naip.vrt --samples marks.csv --plan /shared/veg --jobs 64 \\
      --out /shared/trees.csv --submit slurm --mem 8G   # as Slurm array jobs
  relevo veg detect --plan /shared/veg --job 3      # one job, on any machine
  relevo veg detect --plan /shared/veg --status     # jobs done of all
  relevo veg detect --plan /shared/veg --finish     # gather the jobs' objects"
    )]
    Detect(Box<VegDetectArgs>),
    /// Precision, recall and F1 of detections against truth boxes (pixels).
    #[command(
        after_help = "A detection is a true positive when its centre falls inside a truth box not
yet matched (or, with --iou, when its crown box, a square of its size, overlaps
one by at least that intersection over union), taking detections from the
highest score down.

Examples:
  relevo veg eval --detections trees.csv --truth crop.xml
  relevo veg eval --detections trees.csv --truth crop.xml --iou 0.4 --pixel-size 0.1
  relevo veg eval --detections trees.csv --truth boxes.csv --json
  relevo veg eval --detections trees.csv --truth crop.xml --matches matches.geojson"
    )]
    Eval {
        /// Database written by `veg detect` (id;x;y;class;size;score).
        #[arg(long)]
        detections: PathBuf,
        /// Pascal VOC XML (classes from <name>), or CSV lines
        /// xmin,ymin,xmax,ymax[,class].
        #[arg(long)]
        truth: PathBuf,
        /// Match by crown box: at least this intersection over union
        /// (0.4 and 0.5 are usual) instead of the centre inside the box.
        #[arg(long, value_name = "MIN")]
        iou: Option<f64>,
        /// Metres per unit of x and y: the pixel size where detections and
        /// truth are in pixels (a crop that is not georeferenced); sizes are
        /// metres. Default 1 (x and y in metres).
        #[arg(long, default_value_t = 1.0)]
        pixel_size: f64,
        /// Also write the matches as GeoJSON: detections (matched or not)
        /// and truth boxes (found or missed), in the inputs' coordinates.
        #[arg(long, value_name = "FILE.geojson")]
        matches: Option<PathBuf>,
        /// Replace an existing --matches file.
        #[arg(long)]
        force: bool,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Args, Debug)]
pub struct VegDetectArgs {
    /// The image (anything GDAL reads).
    #[arg(required_unless_present = "plan")]
    pub image: Option<PathBuf>,
    /// Marked samples: .csv (pixel rectangles) or .geojson (polygons).
    #[arg(long, required_unless_present = "plan")]
    pub samples: Option<PathBuf>,
    /// Bands to analyse, 1-based (1 to 4), e.g. 3,2,1 or 1,2,3,4. Default:
    /// red, green, blue and near-infrared when the image has a band named
    /// so (or an untagged fourth band after red, green, blue, as NAIP);
    /// else the first three.
    #[arg(long, value_delimiter = ',')]
    pub bands: Option<Vec<usize>>,
    /// Percentiles LOW,HIGH stretched to 0..255 (default: none for 8-bit, 2,98 otherwise).
    #[arg(long, value_name = "LOW,HIGH", value_parser = parse_percentiles)]
    pub stretch: Option<[f64; 2]>,
    /// Ground size of a pixel in metres, for images that are not georeferenced.
    #[arg(long, allow_negative_numbers = true)]
    pub pixel_size: Option<f64>,
    /// Largest brightness standard deviation in a region (8-bit units).
    #[arg(long, allow_negative_numbers = true)]
    pub brightness_std: Option<f32>,
    /// Largest chroma standard deviation in a region (8-bit units).
    #[arg(long, allow_negative_numbers = true)]
    pub chroma_std: Option<f32>,
    /// Regions smaller than this (pixels) join their most similar neighbour.
    #[arg(long)]
    pub min_region: Option<u32>,
    /// Side of the smallest split block, pixels (1, 2, 4, …, 64).
    #[arg(long)]
    pub min_block: Option<u32>,
    /// Smallest window side (pixels) a region's signature covers.
    #[arg(long)]
    pub window: Option<u32>,
    /// Nearest learnt signatures per class a region's distance averages.
    #[arg(long)]
    pub neighbours: Option<usize>,
    /// Class of counter-examples.
    #[arg(long)]
    pub negative: Option<String>,
    /// Crowns (fine imagery) or fill (coarse imagery); auto picks by pixel size.
    #[arg(long, value_enum)]
    pub mode: Option<ModeArg>,
    /// Smallest distance between crown centres, metres (default: learnt
    /// from the marked crowns, 1 to 3 m).
    #[arg(long, allow_negative_numbers = true)]
    pub crown_spacing: Option<f64>,
    /// The typical crown's side, metres, which each crown's size is drawn
    /// toward (default: learnt from the marked crowns, the lower quartile
    /// of their sides); e.g. the size a round that looked right reported,
    /// when the marks added since move it.
    #[arg(long, allow_negative_numbers = true)]
    pub crown_size: Option<f64>,
    /// Smallest crown radius kept, metres.
    #[arg(long, allow_negative_numbers = true)]
    pub crown_min_radius: Option<f64>,
    /// Fill mode: objects per hectare.
    #[arg(long, allow_negative_numbers = true)]
    pub density: Option<f64>,
    /// Side of the tiles a large image is analysed in, pixels (default
    /// 2048; at least 256): an image no larger is analysed whole; smaller
    /// tiles use less memory.
    #[arg(long)]
    pub tile: Option<usize>,
    /// Split-and-merge thresholds scaled by the marked samples' contrast
    /// (samples: a duller or harsher image is cut into the same regions),
    /// or in 8-bit units as given (absolute); auto, the default, scales
    /// them where crowns are placed and keeps them in fill mode.
    #[arg(long, value_enum)]
    pub contrast: Option<ContrastArg>,
    /// The database (semicolon CSV).
    #[arg(long, short, required_unless_present = "plan")]
    pub out: Option<PathBuf>,
    /// Also write the objects as a GeoPackage.
    #[arg(long)]
    pub gpkg: Option<PathBuf>,
    /// Also write region and class labels as a GeoTIFF.
    #[arg(long)]
    pub labels: Option<PathBuf>,
    /// Also write a PNG of regions and objects over the image.
    #[arg(long)]
    pub overlay: Option<PathBuf>,
    /// Score the classified pixels against land-cover labels (a vector
    /// file of polygons and points, e.g. GeoPackage): per land-cover class,
    /// the share of its pixels called vegetation and each class's count.
    #[arg(long, value_name = "FILE")]
    pub land_cover: Option<PathBuf>,
    /// The field of --land-cover that names each feature's class.
    #[arg(long, default_value = "name")]
    pub land_cover_field: String,
    #[command(flatten)]
    pub plan: PlanArgs,
    /// Print a JSON report.
    #[arg(long)]
    pub json: bool,
    /// Replace existing outputs (and, with --plan, an existing plan).
    #[arg(long)]
    pub force: bool,
}

impl VegDetectArgs {
    /// The flags given, over the defaults.
    pub fn options(&self) -> VegOptions {
        let mut o = VegOptions::default();
        macro_rules! set {
            ($($flag:ident => $field:ident),*) => {$(
                if let Some(v) = self.$flag.clone() { o.$field = v; }
            )*};
        }
        set!(brightness_std => brightness_std, chroma_std => chroma_std,
             min_region => min_region_px, min_block => min_block_px, window => window_px, neighbours => neighbours, negative => negative_class,
             crown_min_radius => crown_min_radius_m, density => density_per_ha, tile => tile_px);
        if let Some(mode) = self.mode {
            o.mode = mode.into();
        }
        if self.crown_spacing.is_some() {
            o.crown_spacing_m = self.crown_spacing;
        }
        if self.crown_size.is_some() {
            o.crown_size_m = self.crown_size;
        }
        if let Some(contrast) = self.contrast {
            o.contrast = match contrast {
                ContrastArg::Auto => Contrast::Auto,
                ContrastArg::Absolute => Contrast::Absolute,
                ContrastArg::Samples => Contrast::Samples,
            };
        }
        o
    }
}

/// How the split-and-merge thresholds meet the image's contrast.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum ContrastArg {
    /// Samples in crowns mode, absolute in fill mode.
    Auto,
    /// In 8-bit units, as given.
    Absolute,
    /// Scaled by the marked samples' contrast over 30.
    Samples,
}

/// Crowns (fine imagery) or fill (coarse imagery).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum ModeArg {
    /// Crowns when a pixel is at most 1 m, else fill.
    Auto,
    Crowns,
    Fill,
}

impl From<ModeArg> for DetectionMode {
    fn from(m: ModeArg) -> DetectionMode {
        match m {
            ModeArg::Auto => DetectionMode::Auto,
            ModeArg::Crowns => DetectionMode::Crowns,
            ModeArg::Fill => DetectionMode::Fill,
        }
    }
}

/// Run `veg detect` or `veg eval`.
pub fn run(command: VegCommand) -> Result<()> {
    match command {
        VegCommand::Detect(a) => detect(a),
        VegCommand::Eval {
            detections,
            truth,
            iou,
            pixel_size,
            matches,
            force,
            json,
        } => {
            let criterion = match iou {
                None => eval::Criterion::Centre,
                Some(min) if min > 0.0 && min <= 1.0 => eval::Criterion::Iou { min },
                Some(min) => bail!("--iou: {min} is not an overlap between 0 (excluded) and 1"),
            };
            if !(pixel_size.is_finite() && pixel_size > 0.0) {
                bail!("--pixel-size: {pixel_size} is not a positive size in metres");
            }
            score(
                &detections,
                &truth,
                criterion,
                pixel_size,
                matches.as_deref(),
                force,
                json,
            )
        }
    }
}

fn detect(a: Box<VegDetectArgs>) -> Result<()> {
    if let Some(dir) = &a.plan.plan {
        return detect_plan(dir, &a);
    }
    let (Some(image_path), Some(samples_path), Some(out)) = (&a.image, &a.samples, &a.out) else {
        bail!("give the image, --samples and --out");
    };
    let outputs = std::iter::once(out)
        .chain(a.gpkg.iter())
        .chain(a.labels.iter())
        .chain(a.overlay.iter());
    output::check(&outputs.map(PathBuf::as_path).collect::<Vec<_>>(), a.force)?;
    let reader =
        veg_io::ImageReader::open(image_path, a.bands.as_deref(), a.stretch, a.pixel_size)?;
    let band_roles = reader.band_roles.clone();
    let image = reader.whole()?;
    let samples = samples::read_file(
        samples_path,
        image.geotransform,
        image.image.width,
        image.image.height,
    )?;
    // Land-cover labels are read before any work, so bad ones cost nothing.
    let land_cover_labels = a
        .land_cover
        .as_ref()
        .map(|path| veg_io::read_land_cover(path, &a.land_cover_field, &image))
        .transpose()?;
    let options = a.options();
    // Only the labels raster, the overlay and the land-cover figures read
    // the region of every pixel.
    let region_map = if a.labels.is_some() || a.overlay.is_some() || land_cover_labels.is_some() {
        pipeline::RegionMap::Keep
    } else {
        pipeline::RegionMap::Skip
    };
    let extraction = extract_with_progress(&image, &samples, &options, region_map)
        .with_context(|| format!("{}", image_path.display()))?;
    // All outputs are made whole first, then moved into place together.
    let mut outputs = relevo_core::atomic::Outputs::default();
    let csv = db::to_csv(&extraction.objects);
    output::write_atomic(&outputs.pending(out), csv.as_bytes())?;
    if let Some(path) = &a.gpkg {
        veg_io::write_gpkg(&outputs.pending(path), &extraction.objects, &image.crs_wkt)?;
    }
    if let Some(path) = &a.labels {
        veg_io::write_labels(&outputs.pending(path), &image, &extraction)?;
    }
    if let Some(path) = &a.overlay {
        let rgba = pipeline::overlay(&image, &extraction, &samples, &options.negative_class)?;
        let png = encode_rgba(&rgba, image.image.width, image.image.height)?;
        output::write_atomic(&outputs.pending(path), &png)?;
    }
    outputs.commit()?;
    let land_cover = land_cover_labels
        .as_ref()
        .map(|labels| land_cover_figures(labels, &extraction, &image))
        .transpose()?;
    let r = &extraction.report;
    if a.json {
        let mut report = serde_json::to_value(r)?;
        report["bands"] = serde_json::to_value(&band_roles)?;
        report["crown_scale"] = serde_json::to_value(r.crown_scale())?;
        if let Some((figures, baseline)) = &land_cover {
            report["land_cover"] = serde_json::to_value(figures)?;
            report["land_cover_excess_green"] = serde_json::to_value(baseline)?;
        }
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "{}: {}×{} px of {:.2} m, {} leaves → {} regions, {} objects ({:.0} ms split-and-merge, {:.0} ms classify, {:.0} ms place)",
            image_path.display(), r.width, r.height, r.pixel_m, r.leaves, r.regions, r.objects,
            r.segment_ms, r.classify_ms, r.detect_ms
        );
        println!(
            "  bands analysed: {}{}",
            band_roles.join(", "),
            if a.bands.is_none() {
                " (the default: red, green, blue and near-infrared when the image has it)"
            } else {
                ""
            }
        );
        print_crown_placement(r, &options, &samples);
        if r.threshold_gain != 1.0 {
            println!(
                "  thresholds scaled by {:.2} to the samples' contrast",
                r.threshold_gain
            );
        }
        for c in &r.classes {
            println!(
                "  {:<12} {:>10} signatures {:>4}  regions {:>7}  pixels {:>10}  objects {:>7}",
                c.class,
                if c.vegetation {
                    "vegetation"
                } else {
                    "negative"
                },
                c.signatures,
                c.regions,
                c.pixels,
                c.objects
            );
        }
        if let Some((figures, baseline)) = &land_cover {
            println!("  land cover       pixels  called vegetation  excess green  by class");
            for (k, f) in figures.iter().enumerate() {
                let by: Vec<String> = f.by_class.iter().map(|(c, n)| format!("{c} {n}")).collect();
                let green = baseline.as_ref().map_or("—".into(), |b| {
                    format!("{:>5.1} %", 100.0 * b[k].vegetation_share)
                });
                println!(
                    "  {:<12} {:>10}  {:>8} ({:>5.1} %)  {:>12}  {}",
                    f.class,
                    f.pixels,
                    f.vegetation,
                    100.0 * f.vegetation_share,
                    green,
                    by.join(", ")
                );
            }
        }
    }
    Ok(())
}

/// The report's lines on how crowns were placed: the spacing when it was
/// learnt (and the mark of `samples` that kept it from being closer), the
/// marked crowns' pattern when crowns were centred by it, and the size
/// crowns are drawn toward (the marks' or the one given).
fn print_crown_placement(r: &pipeline::Report, options: &VegOptions, samples: &[samples::Sample]) {
    if let (relevo_core::veg::detect::Placement::Crowns { template, .. }, Some(scale)) =
        (&r.placement, r.crown_scale())
    {
        if options.crown_spacing_m.is_none() {
            let spacing_m = scale.spacing_m;
            println!("  crowns at least {spacing_m:.1} m apart, learnt from the marked crowns");
            if let Some(split) = r.spacing_split_note(samples) {
                println!("    {split}");
            }
        }
        if let Some(t) = template {
            let taps = 2 * t.reach + 1;
            println!(
                "  crowns centred where brightness and likeness to the marked crowns peak \
                 ({taps}×{taps} taps {} px apart)",
                2 * t.tap_radius_px + 1
            );
        }
        if let Some(size_m) = scale.size_m {
            let [low, high] =
                relevo_core::veg::detect::crown_size_range(size_m as f32).map(|m| m as f64);
            let toward = match options.crown_size_m {
                Some(_) => "the given",
                None => "the marked crowns'",
            };
            println!(
                "  crown sizes from the valleys around each crown, drawn toward {toward} \
                 {size_m:.1} m (within {low:.1}–{high:.1} m)"
            );
        }
    }
}

/// The classified pixels against land-cover `labels`, and the
/// excess-green baseline's (R, G, B bands) beside them.
fn land_cover_figures(
    labels: &[samples::Sample],
    extraction: &pipeline::Extraction,
    image: &pipeline::VegImage,
) -> Result<(
    Vec<eval::LandCoverFigures>,
    Option<Vec<eval::LandCoverFigures>>,
)> {
    let names: Vec<(&str, bool)> = class_kinds(extraction).collect();
    let region_map = extraction.pixel_regions()?;
    let (w, h) = (image.image.width, image.image.height);
    let valid = |i: usize| image.valid.as_ref().is_none_or(|v| v[i]);
    let ours = eval::land_cover(labels, w, h, |i| {
        valid(i).then(|| names[extraction.labels[region_map[i] as usize].class])
    });
    let baseline = (image.image.bands >= 3).then(|| {
        let green = baseline::excess_green_mask(&image.image);
        eval::land_cover(labels, w, h, |i| {
            valid(i).then_some(if green[i] {
                ("excess green", true)
            } else {
                ("not green", false)
            })
        })
    });
    Ok((ours, baseline))
}

/// `veg detect --plan DIR`: with the image, make the plan (and submit it
/// with --submit); alone, run a job, finish or submit.
fn detect_plan(dir: &Path, a: &VegDetectArgs) -> Result<()> {
    let p = &a.plan;
    if let (Some(image), Some(samples), Some(out)) = (&a.image, &a.samples, &a.out) {
        if a.labels.is_some() || a.overlay.is_some() || a.land_cover.is_some() {
            bail!("--labels, --overlay and --land-cover need the whole image: not with --plan");
        }
        if p.job.is_some() || p.finish {
            bail!("--job and --finish act on a plan already made: give --plan alone");
        }
        let plan = VegPlan::create(
            dir,
            VegPlanRequest {
                image: ImageSpec {
                    path: image.clone(),
                    bands: a.bands.clone(),
                    stretch: a.stretch,
                    pixel_size: a.pixel_size,
                },
                samples,
                options: a.options(),
                out,
                gpkg: a.gpkg.as_deref(),
                jobs: p.jobs,
                force: a.force,
            },
        )?;
        let tiles = plan.model.tiles().len();
        if !a.json {
            println!(
                "{}: a plan of {} jobs over {tiles} tiles of {}×{} px, writing {}",
                dir.display(),
                plan.jobs.len(),
                plan.model.size[0],
                plan.model.size[1],
                plan.out.display()
            );
        }
        if p.submit.is_some() {
            return p.submit_to(dir, &plan, a.json);
        }
        if !a.json {
            println!(
                "run each job with `relevo veg detect --plan {0} --job K`, or `relevo veg \
                 detect --plan {0} --submit slurm`; then `relevo veg detect --plan {0} --finish`",
                dir.display()
            );
        }
        return Ok(());
    }
    let plan = VegPlan::load(dir)?;
    if let Some(k) = p.job {
        let r = plan.run_job(dir, k)?;
        println!(
            "job {k}: tiles {}–{}, {} objects in {:.1} s",
            r.tiles[0],
            r.tiles[1],
            r.objects.len(),
            r.ms / 1e3
        );
        return Ok(());
    }
    if p.finish {
        let n = plan.finish(dir)?;
        println!("{}: {n} objects", plan.out.display());
        return Ok(());
    }
    if p.status {
        return p.print_status(dir, &plan, a.json);
    }
    p.submit_to(dir, &plan, a.json)
}

/// [`pipeline::extract`] on a worker thread while a bar shows its steps
/// (learning from the samples, then each tile).
fn extract_with_progress(
    image: &pipeline::VegImage,
    samples: &[samples::Sample],
    options: &VegOptions,
    region_map: pipeline::RegionMap,
) -> relevo_core::Result<pipeline::Extraction> {
    let watch = pipeline::Watch::default();
    let bar = crate::progress::bar(1, "vegetation");
    let result = std::thread::scope(|scope| {
        let worker =
            scope.spawn(|| pipeline::extract_watched(image, samples, options, region_map, &watch));
        while !worker.is_finished() {
            let (done, all) = watch.progress();
            bar.set_length(all.max(1) as u64);
            bar.set_position(done as u64);
            bar.set_message(if done == 0 {
                "learning from the samples"
            } else {
                "tiles"
            });
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        worker.join()
    });
    bar.finish_and_clear();
    match result {
        Ok(extraction) => extraction,
        Err(_) => Err(relevo_core::Error::Input(
            "the vegetation extraction stopped unexpectedly".into(),
        )),
    }
}

/// Each extraction class's name and whether it is vegetation, by index.
fn class_kinds(extraction: &pipeline::Extraction) -> impl Iterator<Item = (&str, bool)> {
    extraction
        .report
        .classes
        .iter()
        .map(|c| (c.class.as_str(), c.vegetation))
}

/// `veg eval`: overall and per-class figures, and the matches as GeoJSON.
fn score(
    detections: &Path,
    truth: &Path,
    criterion: eval::Criterion,
    metres_per_unit: f64,
    matches_out: Option<&Path>,
    force: bool,
    json: bool,
) -> Result<()> {
    if let Some(path) = matches_out {
        output::check(&[path], force)?;
    }
    let read = |p: &Path| relevo_core::files::read_to_string(p);
    let objects = db::from_csv(&read(detections)?)
        .map_err(|e| anyhow::anyhow!("{}: {e}", detections.display()))?;
    let text = read(truth)?;
    let boxes =
        eval::parse_truth(&text).map_err(|e| anyhow::anyhow!("{}: {e}", truth.display()))?;
    let found = eval::matches(
        &eval::Detection::of_objects(&objects, metres_per_unit),
        &eval::bounds(&boxes),
        criterion,
    );
    let e = eval::Evaluation::of(&found, boxes.len());
    let classes: Vec<&str> = objects.iter().map(|o| o.class.as_str()).collect();
    let per_class = eval::per_class(&classes, &boxes, &found);
    if let Some(path) = matches_out {
        output::write_atomic(
            path,
            eval::matches_geojson(&objects, &boxes, &found).as_bytes(),
        )?;
    }
    if json {
        // The overall figures at the top (as before), the classes beside them.
        let mut report = serde_json::to_value(e)?;
        report["criterion"] = serde_json::to_value(criterion)?;
        report["classes"] = serde_json::to_value(&per_class.classes)?;
        report["confusion"] = serde_json::to_value(&per_class.confusion)?;
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "precision {:.3}  recall {:.3}  F1 {:.3}  (TP {}, FP {}, FN {}; {} detections, {} boxes)",
        e.precision,
        e.recall,
        e.f1,
        e.true_positives,
        e.false_positives,
        e.false_negatives,
        e.detections,
        e.truth
    );
    // A ratio, or a dash when nothing was counted.
    let ratio = |value: f64, of: usize| {
        if of > 0 {
            format!("{value:.3}")
        } else {
            "—".into()
        }
    };
    println!("  class          detections  matched  precision    boxes  found  recall");
    for c in &per_class.classes {
        println!(
            "  {:<14} {:>10}  {:>7}  {:>9}  {:>7}  {:>5}  {:>6}",
            c.class,
            c.detections,
            c.matched,
            ratio(c.precision, c.detections),
            c.truth,
            c.found,
            ratio(c.recall, c.truth),
        );
    }
    println!("  matches (detection class → truth class):");
    for (from, row) in &per_class.confusion {
        let cells: Vec<String> = row.iter().map(|(to, n)| format!("{to} {n}")).collect();
        println!("    {from:<14} → {}", cells.join(", "));
    }
    Ok(())
}
