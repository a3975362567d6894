//! The window: the 3D view (the shared offscreen targets shown as an egui
//! image), the HUD, the side panel and the keys. Flying and drawing go
//! through [`Flight`] and [`gpu::Renderer`], the same code the headless
//! renders use; what is on screen comes from relevo-core.
//!
//! - `input`: keys and camera strings.
//! - `panel`: the side panel.
//! - `view`: the 3D view, HUD and help.
//! - `tour`: the scripted tour.

mod input;
mod panel;
mod tour;
mod view;

pub use tour::Tour;

use crate::flight::Flight;
use crate::gpu::{self, FrameStats};
use crate::hud;
use crate::samples::SamplesTab;
use crate::scene::Scene;
use crate::settings::{Settings, TerrainMode};
use eframe::egui;
use relevo_core::scene::CameraPose;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Frames the frame-time plot keeps.
const HISTORY: usize = 240;

/// The viewer application.
pub struct ViewerApp {
    scene: Option<Scene>,
    /// Why the last bundle could not be opened, shown in the window.
    error: Option<String>,
    flight: Option<Flight>,
    pub settings: Settings,
    renderer: Option<gpu::Renderer>,
    texture: Option<(egui::TextureId, [u32; 2])>,
    /// Frame times, seconds, newest last.
    frame_times: VecDeque<f64>,
    last_frame: Option<Instant>,
    pub stats: FrameStats,
    pub show_help: bool,
    /// The side panel's camera string: the current camera, or what is being typed.
    pub camera_text: String,
    /// A camera to move to once the view's size is known.
    pending_pose: Option<CameraPose>,
    /// World (east, north, height) of the ground under the pointer.
    pub ground_under_pointer: Option<[f64; 3]>,
    tour: Option<Tour>,
    /// The samples tab, when shown (it keeps its marks while hidden).
    samples: Option<SamplesTab>,
    pub tab: Tab,
}

/// The window's tabs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tab {
    /// The 3D view.
    View,
    /// Marking samples on the drape and detecting vegetation.
    Samples,
}

impl ViewerApp {
    /// A viewer showing `bundle`, or asking for one.
    pub fn new(bundle: Option<&Path>) -> Self {
        let mut app = ViewerApp {
            scene: None,
            error: None,
            flight: None,
            settings: Settings::default(),
            renderer: None,
            texture: None,
            frame_times: VecDeque::with_capacity(HISTORY),
            last_frame: None,
            stats: FrameStats::default(),
            show_help: false,
            camera_text: String::new(),
            pending_pose: None,
            ground_under_pointer: None,
            tour: None,
            samples: None,
            tab: Tab::View,
        };
        if let Some(path) = bundle {
            app.open(path);
        }
        app
    }

    /// Open a bundle; on failure keep the current one and show why.
    pub fn open(&mut self, path: &Path) {
        match Scene::open(path) {
            Ok(scene) => {
                self.flight = Some(Flight::home(&scene));
                self.samples = Some(SamplesTab::new(path));
                self.scene = Some(scene);
                self.renderer = None;
                self.error = None;
            }
            Err(e) => self.error = Some(format!("{e:#}")),
        }
    }

    /// The samples tab of the open bundle.
    pub fn samples_tab(&mut self) -> Option<&mut SamplesTab> {
        self.samples.as_mut()
    }

    /// Open the current bundle again (after its vegetation was rewritten),
    /// keeping the camera and the objects.
    fn reload(&mut self) {
        let Some(old) = self.scene.take() else { return };
        match Scene::open(&old.path) {
            Ok(mut scene) => {
                scene.objects = old.objects;
                self.scene = Some(scene);
                self.renderer = None;
                self.error = None;
            }
            Err(e) => {
                self.error = Some(format!("{e:#}"));
                self.scene = Some(old);
            }
        }
    }

    /// Place the objects of a placement file on the open bundle; on failure
    /// show why.
    pub fn load_objects(&mut self, path: &Path) {
        let Some(scene) = &mut self.scene else {
            return;
        };
        if let Err(e) = scene.load_objects(path) {
            self.error = Some(format!("{e:#}"));
        }
    }

    /// The message shown instead of a view, if any.
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    /// The flight, once a bundle is open.
    pub fn flight(&self) -> Option<&Flight> {
        self.flight.as_ref()
    }

    /// Mean frames per second over the plot's history.
    fn fps(&self) -> f64 {
        let total: f64 = self.frame_times.iter().sum();
        if total > 0.0 {
            self.frame_times.len() as f64 / total
        } else {
            0.0
        }
    }

    /// The HUD's lines: frame rate, frame time, what was drawn, where the
    /// camera and the pointer are.
    pub fn hud_lines(&self) -> Vec<String> {
        let frame_ms = self.frame_times.back().map_or(0.0, |t| t * 1e3);
        hud::lines(&hud::Readings {
            fps: self.fps(),
            frame_ms,
            settings: &self.settings,
            stats: &self.stats,
            scene: self.scene.as_ref(),
            flight: self.flight.as_ref(),
            pointer: self.ground_under_pointer,
        })
    }
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        let dropped: Option<PathBuf> =
            ctx.input(|i| i.raw.dropped_files.first().map(|f| f.path().to_path_buf()));
        if let Some(path) = dropped {
            self.open(&path);
        }
        let keys = self.keys(&ctx);
        let controls = self.tour_step(&ctx).unwrap_or(keys);
        egui::Panel::top("tabs").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.selectable_value(&mut self.tab, Tab::View, "3D view");
                ui.selectable_value(&mut self.tab, Tab::Samples, "samples");
            });
        });
        if self.tab == Tab::Samples {
            let accepted = egui::CentralPanel::default()
                .show(ui, |ui| match &mut self.samples {
                    Some(tab) => tab.ui(ui),
                    None => {
                        ui.label("Open a bundle first.");
                        None
                    }
                })
                .inner;
            match accepted {
                Some(Ok(())) => self.reload(),
                Some(Err(e)) => {
                    if let Some(tab) = &mut self.samples {
                        tab.problem = Some(format!("{e:#}"));
                    }
                }
                None => {}
            }
            self.help(&ctx);
            return;
        }
        egui::Panel::right("settings").show(ui, |ui| self.side_panel(ui));
        egui::CentralPanel::no_frame().show(ui, |ui| {
            if let Some(error) = &self.error {
                ui.colored_label(egui::Color32::from_rgb(230, 90, 80), error);
            }
            if self.scene.is_none() {
                ui.centered_and_justified(|ui| {
                    ui.heading(
                        "Drop a bundle folder (NAME.relevo) here, or start relevo-view NAME.relevo",
                    );
                });
                return;
            }
            self.view(ui, frame.wgpu_render_state(), controls);
        });
        self.help(&ctx);
    }
}

/// What the window starts with.
#[derive(Default)]
pub struct Start {
    /// The bundle (none: wait for one dropped on the window).
    pub bundle: Option<PathBuf>,
    /// A placement file of objects to composite.
    pub objects: Option<PathBuf>,
    /// A camera string to start at instead of the home view.
    pub camera: Option<String>,
    /// How the terrain is drawn at first (the keys and the side panel
    /// change it).
    pub mode: TerrainMode,
    /// A scripted flight ending with a screenshot.
    pub tour: Option<Tour>,
}

/// Open the window as `start` says; with a tour, fly it, save the
/// screenshot and close. Problems with the bundle, objects or camera are
/// shown in the window.
pub fn run(start: Start) -> anyhow::Result<()> {
    let Start {
        bundle,
        objects,
        camera,
        mode,
        tour,
    } = start;
    let outcome = tour
        .as_ref()
        .map(|t| (t.outcome.clone(), t.screenshot.clone()));
    let options = eframe::NativeOptions {
        renderer: eframe::Renderer::Wgpu,
        viewport: egui::ViewportBuilder::default()
            .with_title("relevo-view")
            .with_inner_size([1280.0, 800.0])
            .with_drag_and_drop(true),
        ..Default::default()
    };
    eframe::run_native(
        "relevo-view",
        options,
        Box::new(move |_| {
            let mut app = ViewerApp::new(bundle.as_deref());
            app.settings.mode = mode;
            if let Some(path) = &objects {
                app.load_objects(path);
            }
            if let Some(text) = camera {
                app.camera_text = text;
                app.go_to_typed_camera();
            }
            Ok(Box::new(match tour {
                Some(tour) => app.with_tour(tour),
                None => app,
            }))
        }),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the window: {e}"))?;
    if let Some((outcome, path)) = outcome {
        let result = outcome.lock().ok().and_then(|mut o| o.take());
        match result {
            Some(Ok(())) => eprintln!("{}: screenshot of the window", path.display()),
            Some(Err(e)) => anyhow::bail!("{}: {e}", path.display()),
            None => anyhow::bail!(
                "{}: the window closed before its screenshot",
                path.display()
            ),
        }
    }
    Ok(())
}
