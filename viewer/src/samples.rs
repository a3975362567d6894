//! The samples tab: the seed's buildDB in the window. The bundle's drape in
//! a pan-and-zoom view (right or middle drag pans, scroll zooms); a person
//! drags rectangles with the left button and gives each a class; detection
//! runs relevo-core's vegetation pipeline on the drape in the background;
//! its objects are overlaid by class; accepting writes the samples and the
//! database into the bundle and re-bakes its clusters, atomically, and the
//! 3D view reloads them. With truth boxes loaded, each detection is scored
//! as a round of the correction loop (relevo-core's protocol figures), and
//! the rectangles added since the round before are drawn apart. The mark
//! that kept the learnt crown spacing from being closer is drawn in red and
//! named in the status. Each round shows the crown spacing and size it
//! placed crowns at; a person may keep them for the rounds after, so that
//! the marks added then teach the classes and hold their places without
//! moving the scale.

use anyhow::Context;
use eframe::egui;
use relevo_core::bundle::BundleFiles;
use relevo_core::bundle::{Bundle, BundleLock};
use relevo_core::cluster::model::ModelSource;
use relevo_core::cluster::store::{self, NewVegetation};
use relevo_core::veg::db::VegObject;
use relevo_core::veg::pipeline::{self, CrownScale, VegImage, VegOptions, Watch};
use relevo_core::veg::samples::Sample;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::thread::JoinHandle;

/// A detection running in the background, and the flag that cancels it
/// (its result is then dropped).
struct Job {
    handle: JoinHandle<Result<Detection, String>>,
    watch: Arc<Watch>,
}

/// What a detection found: the objects and relevo-core's overlay of the
/// drape (regions tinted by class, segment borders darkened, objects as
/// rings), RGBA8 at the drape's size.
pub struct Detection {
    pub objects: Vec<VegObject>,
    pub overlay: Vec<u8>,
    /// The marked crown that kept the learnt crown spacing from being
    /// closer, said for a person (relevo-core's report), and its rectangle
    /// (drape pixels).
    pub spacing_note: Option<String>,
    pub spacing_mark: Option<[f32; 4]>,
    /// The crown spacing and size crowns were placed at (none in fill
    /// mode).
    pub scale: Option<CrownScale>,
    /// The factor the segmentation thresholds were scaled by to the
    /// samples' contrast (1 when they were used as given).
    pub threshold_gain: f32,
}

/// What the tab keeps between frames.
pub struct SamplesTab {
    bundle: PathBuf,
    texture: Option<egui::TextureHandle>,
    /// The last detection's overlay, shown instead of the drape while
    /// `show_overlay`.
    overlay: Option<egui::TextureHandle>,
    pending_overlay: Option<Vec<u8>>,
    pub show_overlay: bool,
    size: [usize; 2],
    /// World → drape pixel, and why there is no drape to show; both read
    /// once, with the texture.
    to_pixel: Option<relevo_core::geo::GeoTransform>,
    no_drape: Option<String>,
    scene_rect: egui::Rect,
    /// Marked rectangles, drape pixels `[x0, y0, x1, y1]`, with their class.
    pub samples: Vec<(String, [f32; 4])>,
    /// The class a new rectangle gets.
    pub class: String,
    /// Where the rectangle being drawn started (drape pixels).
    drag_from: Option<egui::Pos2>,
    /// The extraction's options: those the bundle was made with (its
    /// REGION.toml's `[vegetation.options]`), else the defaults; the slider
    /// sets the segmentation's brightness threshold.
    pub options: VegOptions,
    job: Option<Job>,
    /// Objects of the last detection, or of the bundle when none ran.
    pub detections: Vec<VegObject>,
    /// Whether `detections` are new (not yet accepted).
    pub fresh: bool,
    pub status: String,
    /// What went wrong last (a samples file that cannot be read, a bundle
    /// that cannot be written), shown in red until the next action works.
    pub problem: Option<String>,
    /// The samples file the *load* button reads (CSV of drape pixels, or
    /// GeoJSON polygons in the drape's CRS).
    pub samples_path: String,
    /// The truth boxes file (Pascal VOC or CSV, drape pixels) and the boxes
    /// read from it.
    pub truth_path: String,
    pub truth: Option<Vec<[f64; 4]>>,
    /// Each detection's figures against the truth, in order: the rounds.
    pub rounds: Vec<Round>,
    /// Detections run, the marks the last was given, and where those it
    /// added to the one before start (`samples[added_from..marks]`).
    runs: usize,
    marks: usize,
    added_from: usize,
    /// The rectangle of the mark the last detection named as keeping the
    /// crown spacing from being closer (as detection was given it, in
    /// whole pixels): drawn in red while it is marked.
    pub spacing_mark: Option<[f32; 4]>,
    /// The crown scale of the last detection, and the one the person
    /// chose to keep: detections give it instead of learning it.
    pub scale: Option<CrownScale>,
    pub kept_scale: Option<CrownScale>,
}

/// One detection scored against the truth boxes.
#[derive(Debug, Clone)]
pub struct Round {
    /// Marks it ran with, and how many of them were new.
    pub marks: usize,
    pub added: usize,
    /// The crown spacing and size it placed crowns at.
    pub scale: Option<CrownScale>,
    pub scores: relevo_core::veg::protocol::Scores,
}

/// A crown scale for a person: "crowns ≥ 3.0 m apart, sized toward 5.7 m".
fn scale_text(scale: &CrownScale) -> String {
    let mut text = format!("crowns ≥ {:.1} m apart", scale.spacing_m);
    if let Some(size_m) = scale.size_m {
        text += &format!(", sized toward {size_m:.1} m");
    }
    text
}

impl SamplesTab {
    pub fn new(bundle: &Path) -> Self {
        let opened = Bundle::open(bundle).ok();
        let detections = opened
            .as_ref()
            .and_then(|b| b.vegetation().ok().flatten())
            .unwrap_or_default();
        let options = opened.as_ref().map(bundle_options).unwrap_or_default();
        let mut tab = SamplesTab {
            bundle: bundle.to_path_buf(),
            texture: None,
            overlay: None,
            pending_overlay: None,
            show_overlay: true,
            size: [0, 0],
            to_pixel: None,
            no_drape: None,
            scene_rect: egui::Rect::ZERO,
            samples: Vec::new(),
            class: "forest".into(),
            drag_from: None,
            options,
            job: None,
            detections,
            fresh: false,
            status: String::new(),
            problem: None,
            samples_path: String::new(),
            truth_path: String::new(),
            truth: None,
            rounds: Vec::new(),
            runs: 0,
            marks: 0,
            added_from: 0,
            spacing_mark: None,
            scale: None,
            kept_scale: None,
        };
        // The samples the bundle keeps, to go on from.
        let kept = opened.as_ref().and_then(|b| {
            b.manifest
                .artifacts
                .get(relevo_core::bundle::names::VEGETATION_SAMPLES.key)
                .map(|a| b.dir.join(&a.file))
        });
        if let Some(path) = kept {
            tab.samples_path = path.display().to_string();
            tab.load_samples();
        }
        tab
    }

    /// Replace the rectangles with those of the file at `samples_path`
    /// (relevo-core's samples reader; a polygon becomes its bounding box).
    /// On failure the rectangles stay as they were and `problem` says why,
    /// naming the file.
    pub fn load_samples(&mut self) {
        let path = PathBuf::from(self.samples_path.trim());
        match read_samples(&self.bundle, &path) {
            Ok(samples) => {
                self.status = format!("{} samples read from {}", samples.len(), path.display());
                self.samples = samples;
                self.problem = None;
            }
            Err(e) => self.problem = Some(format!("{e:#}")),
        }
    }

    /// The samples as the CSV `samples::parse_csv` reads, in whole pixels.
    /// The rectangles already lie on the drape (drawn on it, or read from a
    /// file checked against its size), so nothing is clipped.
    pub fn samples_csv(&self) -> String {
        let rectangles: Vec<Sample> = self
            .samples
            .iter()
            .map(|(class, bounds)| Sample::rectangle(class, bounds.map(|v| f64::from(v).round())))
            .collect();
        relevo_core::veg::samples::to_csv(&rectangles, usize::MAX, usize::MAX)
    }

    /// Read the truth boxes of the file at `truth_path` (drape pixels);
    /// rounds from here on are scored against them. On failure `problem`
    /// says why, naming the file.
    pub fn load_truth(&mut self) {
        let path = PathBuf::from(self.truth_path.trim());
        let boxes = relevo_core::files::read_to_string(&path).and_then(|text| {
            relevo_core::veg::eval::parse_truth(&text)
                .map_err(|e| relevo_core::Error::Input(format!("{}: {e}", path.display())))
        });
        match boxes {
            Ok(boxes) => {
                self.status = format!("{} truth boxes read from {}", boxes.len(), path.display());
                self.truth = Some(relevo_core::veg::eval::bounds(&boxes));
                self.rounds.clear();
                self.problem = None;
            }
            Err(e) => self.problem = Some(format!("{e:#}")),
        }
    }

    /// The last detection against the truth boxes, when they are loaded
    /// and the drape's georeferencing is known: the detections taken to
    /// drape pixels, their sizes to pixels of the drape.
    fn score_round(&mut self) {
        let (Some(truth), Some(g)) = (&self.truth, self.to_pixel) else {
            return;
        };
        // The drape's pixel size, as its detection took it.
        let pixel_m = g.smallest_cell_side();
        let detections: Vec<relevo_core::veg::eval::Detection> = self
            .detections
            .iter()
            .filter_map(|o| {
                let (x, y) = g.invert(o.x, o.y)?;
                Some(relevo_core::veg::eval::Detection {
                    x,
                    y,
                    diameter: o.size / pixel_m,
                    score: o.score,
                })
            })
            .collect();
        self.rounds.push(Round {
            marks: self.marks,
            added: self.marks - self.added_from,
            scale: self.scale,
            scores: relevo_core::veg::protocol::Scores::of(&detections, truth),
        });
    }

    /// Start detection on the drape with the marked samples.
    pub fn detect(&mut self) {
        // The marks this round adds: those since the round before (all of
        // them for the first, or when marks were deleted since).
        self.added_from = if self.runs > 0 && self.samples.len() >= self.marks {
            self.marks
        } else {
            0
        };
        self.marks = self.samples.len();
        self.runs += 1;
        let bundle = self.bundle.clone();
        let csv = self.samples_csv();
        let mut options = self.options.clone();
        if let Some(kept) = &self.kept_scale {
            kept.keep_in(&mut options);
        }
        let watch = Arc::new(Watch::default());
        let watched = watch.clone();
        let handle = std::thread::spawn(move || {
            detect(&bundle, &csv, &options, &watched).map_err(|e| format!("{e:#}"))
        });
        self.job = Some(Job { handle, watch });
        self.status = "detecting…".into();
    }

    pub fn running(&self) -> bool {
        self.job.is_some()
    }

    /// Pick up a finished detection.
    pub fn poll(&mut self) {
        if !self.job.as_ref().is_some_and(|j| j.handle.is_finished()) {
            return;
        }
        let Some(job) = self.job.take() else { return };
        match job.handle.join() {
            Ok(Ok(found)) => {
                self.status = format!(
                    "{} objects detected; accept to write them",
                    found.objects.len()
                );
                if let Some(scale) = &found.scale {
                    self.status += &format!("\n{}", scale_text(scale));
                }
                if found.threshold_gain != 1.0 {
                    self.status += &format!(
                        "\nsegmentation thresholds scaled by {:.2} to the samples' contrast",
                        found.threshold_gain
                    );
                }
                if let Some(note) = &found.spacing_note {
                    self.status += &format!("\nlearnt crown spacing (the mark in red): {note}");
                }
                self.spacing_mark = found.spacing_mark;
                self.scale = found.scale;
                self.detections = found.objects;
                self.pending_overlay = Some(found.overlay);
                self.fresh = true;
                self.score_round();
            }
            Ok(Err(e)) => self.status = e,
            Err(_) => {
                self.status =
                    "the detection stopped on an internal error (please report it)".into();
            }
        }
    }

    /// Write the samples and the detections into the bundle and re-bake its
    /// clusters with the options they were baked with.
    pub fn accept(&mut self) -> anyhow::Result<()> {
        let lock = BundleLock::acquire(&self.bundle)?;
        let bundle = Bundle::open(&self.bundle)?;
        let (options, models) = match store::read_index(&bundle)? {
            Some(index) => {
                let models: BTreeMap<String, ModelSource> = index
                    .classes
                    .iter()
                    .map(|c| (c.name.clone(), c.model.clone()))
                    .collect();
                (index.options, models)
            }
            None => Default::default(),
        };
        let csv = self.samples_csv();
        let new = NewVegetation {
            database: Some(&self.detections),
            samples_csv: Some(&csv),
        };
        store::rewrite_bundle(lock, &bundle, &new, &models, &options, &|_, _| {})?;
        self.fresh = false;
        self.problem = None;
        self.status = format!("{} objects written and clustered", self.detections.len());
        Ok(())
    }

    /// The tab: controls on the left, the drape on the right.
    pub fn ui(&mut self, ui: &mut egui::Ui) -> Option<anyhow::Result<()>> {
        self.poll();
        let mut accepted = None;
        egui::Panel::left("sample controls").show(ui, |ui| {
            ui.heading("Samples");
            if let Some(problem) = &self.problem {
                ui.colored_label(egui::Color32::from_rgb(230, 90, 80), problem);
            }
            ui.label("Left-drag on the image marks a rectangle; right-drag pans; scroll zooms.");
            ui.horizontal(|ui| {
                let label = ui.label("samples file");
                ui.text_edit_singleline(&mut self.samples_path)
                    .labelled_by(label.id);
                if ui.button("load").clicked() {
                    self.load_samples();
                }
            });
            ui.horizontal(|ui| {
                let label = ui.label("truth boxes");
                ui.text_edit_singleline(&mut self.truth_path)
                    .labelled_by(label.id);
                if ui.button("load truth").clicked() {
                    self.load_truth();
                }
            });
            for (k, round) in self.rounds.iter().enumerate() {
                let (a, b) = (&round.scores.iou_0_4, &round.scores.iou_0_5);
                // No scale in fill mode, and no separator for it.
                let scale = round
                    .scale
                    .as_ref()
                    .map(|s| format!(" · {}", scale_text(s)))
                    .unwrap_or_default();
                ui.label(format!(
                    "round {k}: {} marks (+{}){scale} · IoU 0.4: P {:.2} R {:.2} F1 {:.3} · IoU 0.5: F1 {:.3}",
                    round.marks, round.added, a.precision, a.recall, a.f1, b.f1
                ));
            }
            if let Some(scale) = self.kept_scale.or(self.scale) {
                let mut keep = self.kept_scale.is_some();
                let text = format!("keep {} in the next detections", scale_text(&scale));
                if ui.checkbox(&mut keep, text).changed() {
                    self.kept_scale = keep.then_some(scale);
                }
            }
            ui.horizontal(|ui| {
                let label = ui.label("class");
                ui.text_edit_singleline(&mut self.class)
                    .labelled_by(label.id);
            });
            let mut remove = None;
            for (i, (class, r)) in self.samples.iter_mut().enumerate() {
                ui.horizontal(|ui| {
                    ui.text_edit_singleline(class);
                    ui.label(format!("{:.0},{:.0}–{:.0},{:.0}", r[0], r[1], r[2], r[3]));
                    if ui.button("delete").clicked() {
                        remove = Some(i);
                    }
                });
            }
            if let Some(i) = remove {
                self.samples.remove(i);
            }
            ui.add(
                egui::Slider::new(&mut self.options.brightness_std, 4.0..=64.0)
                    .text("segmentation threshold"),
            );
            ui.horizontal(|ui| {
                if let Some(job) = &self.job {
                    ui.add(
                        egui::ProgressBar::new(job.watch.fraction())
                            .desired_width(120.0)
                            .show_percentage(),
                    );
                    if ui.button("cancel").clicked() {
                        job.watch.cancel();
                        self.status = "cancelling at the next stage…".into();
                    }
                } else if ui
                    .add_enabled(!self.samples.is_empty(), egui::Button::new("detect"))
                    .clicked()
                {
                    self.detect();
                }
                if ui
                    .add_enabled(self.fresh && !self.running(), egui::Button::new("accept"))
                    .clicked()
                {
                    accepted = Some(self.accept());
                }
            });
            ui.checkbox(
                &mut self.show_overlay,
                "overlay: classes, segment borders, objects",
            );
            ui.label(&self.status);
        });
        egui::CentralPanel::default().show(ui, |ui| self.image(ui));
        if self.running() {
            ui.ctx().request_repaint();
        }
        accepted
    }

    /// The drape with samples and detections, panned and zoomed.
    fn image(&mut self, ui: &mut egui::Ui) {
        if self.texture.is_none() && self.no_drape.is_none() {
            match drape_image(&self.bundle) {
                Ok(Some((image, size, to_pixel))) => {
                    self.size = size;
                    self.to_pixel = Some(to_pixel);
                    self.texture = Some(ui.ctx().load_texture(
                        "drape",
                        image,
                        egui::TextureOptions::LINEAR,
                    ));
                }
                Ok(None) => {
                    self.no_drape =
                        Some("This bundle has no drape image to mark samples on.".into());
                }
                Err(e) => self.no_drape = Some(format!("{e:#}")),
            }
        }
        if let Some(why) = &self.no_drape {
            ui.label(why);
            return;
        }
        if let Some(rgba) = self.pending_overlay.take() {
            let image = egui::ColorImage::from_rgba_unmultiplied(self.size, &rgba);
            self.overlay = Some(ui.ctx().load_texture(
                "overlay",
                image,
                egui::TextureOptions::NEAREST,
            ));
        }
        let shown = if self.show_overlay {
            self.overlay.as_ref()
        } else {
            None
        };
        let Some(texture) = shown.or(self.texture.as_ref()) else {
            return;
        };
        let [w, h] = self.size.map(|v| v as f32);
        let to_pixel = self.to_pixel;
        egui::Scene::new()
            .drag_pan_buttons(egui::DragPanButtons::SECONDARY | egui::DragPanButtons::MIDDLE)
            .zoom_range(0.1..=32.0)
            .show(ui, &mut self.scene_rect, |ui| {
                let rect = egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(w, h));
                let response = ui.put(
                    rect,
                    egui::Image::new((texture.id(), rect.size())).sense(egui::Sense::drag()),
                );
                let painter = ui.painter();
                if let Some(g) = to_pixel {
                    let colour = if self.fresh {
                        egui::Color32::from_rgb(255, 220, 40)
                    } else {
                        egui::Color32::from_rgb(60, 230, 90)
                    };
                    for o in &self.detections {
                        if let Some((x, y)) = g.invert(o.x, o.y) {
                            painter.circle_stroke(
                                egui::pos2(x as f32, y as f32),
                                1.5,
                                (0.6, colour),
                            );
                        }
                    }
                }
                // The marks the last round added to the one before, in
                // orange; the one that kept the crown spacing from being
                // closer, in red.
                let added = self.added_from..self.marks;
                for (k, (class, [x0, y0, x1, y1])) in self.samples.iter().enumerate() {
                    let r = egui::Rect::from_min_max(egui::pos2(*x0, *y0), egui::pos2(*x1, *y1));
                    // Detection is given the rectangles rounded to whole
                    // pixels (`samples_csv`).
                    let sent = [*x0, *y0, *x1, *y1].map(f32::round);
                    let colour = if self.spacing_mark == Some(sent) {
                        egui::Color32::from_rgb(230, 40, 40)
                    } else if added.contains(&k) && self.runs > 1 {
                        egui::Color32::from_rgb(255, 150, 30)
                    } else {
                        egui::Color32::WHITE
                    };
                    painter.rect_stroke(r, 0.0, (1.0, colour), egui::StrokeKind::Outside);
                    painter.text(
                        r.left_top(),
                        egui::Align2::LEFT_BOTTOM,
                        class,
                        egui::FontId::proportional(6.0),
                        colour,
                    );
                }
                // A rectangle follows the pointer while it is dragged (also
                // while the view pans): pointer positions are taken in the
                // image's pixels through the scene's transform.
                let ctx = ui.ctx().clone();
                let pointer = ctx.pointer_latest_pos().map(|p| {
                    ctx.layer_transform_from_global(ui.layer_id())
                        .map_or(p, |t| t * p)
                });
                if response.drag_started_by(egui::PointerButton::Primary) {
                    self.drag_from = pointer;
                }
                let clamp = |p: egui::Pos2| egui::pos2(p.x.clamp(0.0, w), p.y.clamp(0.0, h));
                if let (Some(from), Some(to)) = (self.drag_from, pointer) {
                    let r = egui::Rect::from_two_pos(clamp(from), clamp(to));
                    painter.rect_stroke(
                        r,
                        0.0,
                        (1.0, egui::Color32::YELLOW),
                        egui::StrokeKind::Outside,
                    );
                    if response.drag_stopped() {
                        if r.width() >= 2.0 && r.height() >= 2.0 {
                            self.samples
                                .push((self.class.clone(), [r.min.x, r.min.y, r.max.x, r.max.y]));
                        }
                        self.drag_from = None;
                    }
                }
            });
    }
}

/// The bundle's drape as an egui image, its size and georeferencing.
type DrapeImage = (egui::ColorImage, [usize; 2], relevo_core::geo::GeoTransform);

fn drape_image(bundle: &Path) -> anyhow::Result<Option<DrapeImage>> {
    let bundle = Bundle::open(bundle)?;
    let Some(drape) = bundle.drape()? else {
        return Ok(None);
    };
    let size = [drape.info.width, drape.info.height];
    Ok(Some((
        egui::ColorImage::from_rgba_unmultiplied(size, &drape.rgba),
        size,
        drape.info.geotransform,
    )))
}

/// The samples file at `path` as rectangles in the drape's pixels of
/// `bundle` (relevo-core's reader: CSV rectangles, or GeoJSON polygons in
/// the drape's CRS taken as their bounding boxes). Errors name the file.
fn read_samples(bundle: &Path, path: &Path) -> anyhow::Result<Vec<(String, [f32; 4])>> {
    let bundle = Bundle::open(bundle)?;
    // The drape's size and georeferencing, from the manifest.
    let info = bundle.manifest.color.as_ref().ok_or_else(|| {
        anyhow::anyhow!(
            "{}: the bundle has no drape image to mark samples on",
            bundle.dir.display()
        )
    })?;
    let samples = relevo_core::veg::samples::read_file(
        path,
        Some(info.geotransform),
        info.width,
        info.height,
    )?;
    Ok(samples
        .into_iter()
        .map(|s| {
            let mut r = [f32::MAX, f32::MAX, f32::MIN, f32::MIN];
            for [x, y] in &s.polygon {
                r = [
                    r[0].min(*x as f32),
                    r[1].min(*y as f32),
                    r[2].max(*x as f32),
                    r[3].max(*y as f32),
                ];
            }
            (s.class, r)
        })
        .collect())
}

/// relevo-core's extraction on the bundle's drape with samples in drape
/// pixels (the same pipeline as `relevo prep` and `relevo veg detect`), and
/// its overlay; `watch` follows and can cancel it.
pub fn detect(
    bundle: &Path,
    samples_csv: &str,
    options: &VegOptions,
    watch: &Watch,
) -> anyhow::Result<Detection> {
    let opened = Bundle::open(bundle)?;
    let drape = opened
        .drape()?
        .ok_or_else(|| anyhow::anyhow!("{}: the bundle has no drape image", bundle.display()))?;
    let (w, h) = (drape.info.width, drape.info.height);
    let image = VegImage::from_drape(
        &drape.rgba,
        w,
        h,
        drape.info.geotransform,
        &opened.manifest.crs.wkt,
    )?;
    let samples: Vec<Sample> = relevo_core::veg::samples::parse_csv(samples_csv, w, h)?;
    let extraction =
        pipeline::extract_watched(&image, &samples, options, pipeline::RegionMap::Keep, watch)?;
    let overlay = pipeline::overlay(&image, &extraction, &samples, &options.negative_class)?;
    let spacing_mark = extraction.report.spacing_split.and_then(|split| {
        let [x0, y0, x1, y1] = samples.get(split.sample)?.bounds();
        Some([x0, y0, x1, y1].map(|v| v as f32))
    });
    Ok(Detection {
        spacing_note: extraction.report.spacing_split_note(&samples),
        spacing_mark,
        scale: extraction.report.crown_scale(),
        threshold_gain: extraction.report.threshold_gain,
        objects: extraction.objects,
        overlay,
    })
}

/// The options the bundle's vegetation was extracted with (its REGION's
/// `[vegetation.options]`), else the defaults.
pub fn bundle_options(bundle: &Bundle) -> VegOptions {
    bundle
        .manifest
        .parameters
        .get("vegetation")
        .and_then(|v| v.get("options"))
        .and_then(|o| serde_json::from_value(o.clone()).ok())
        .unwrap_or_default()
}

/// The samples tab as an image for inspection (`relevo-view render --tab
/// samples`): detection with the samples CSV at `samples` (drape pixels)
/// on the drape and relevo-core's overlay, the sample rectangles outlined
/// (white, black for counter-examples). RGBA8, its size and the objects
/// found. Errors name the file.
pub fn render_tab(bundle: &Path, samples: &Path) -> anyhow::Result<(Vec<u8>, [usize; 2], usize)> {
    let opened = Bundle::open(bundle)?;
    let options = bundle_options(&opened);
    let drape =
        opened.manifest.color.as_ref().ok_or_else(|| {
            anyhow::anyhow!("{}: the bundle has no drape image", bundle.display())
        })?;
    let [w, h] = [drape.width, drape.height];
    let samples_csv = relevo_core::files::read_to_string(samples)?;
    relevo_core::veg::samples::parse_csv(&samples_csv, w, h)
        .with_context(|| samples.display().to_string())?;
    let found = detect(bundle, &samples_csv, &options, &Watch::default())?;
    Ok((found.overlay, [w, h], found.objects.len()))
}
