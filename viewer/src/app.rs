//! The window: the 3D view (the shared offscreen targets shown as an egui
//! image), the HUD, the side panel and the keys. Flying and drawing go
//! through [`Flight`] and [`gpu::Renderer`], the same code the headless
//! renders use; what is on screen comes from relevo-core.

use crate::flight::{Controls, Flight};
use crate::gpu::{self, FrameStats};
use crate::hud;
use crate::keys::{self, Action, Axis, Input};
use crate::samples::SamplesTab;
use crate::scene::Scene;
use crate::settings::{self, Settings, TerrainMode};
use eframe::egui;
use eframe::egui_wgpu::{self, wgpu};
use relevo_core::horizon;
use relevo_core::scene::CameraPose;
use relevo_core::zbuffer::Representation;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// A side-panel label with the key that does the same: "wireframe (w)".
fn with_key(text: &str, action: Action) -> String {
    format!("{text} ({})", keys::label_of(action))
}

/// Frames the frame-time plot keeps.
const HISTORY: usize = 240;

/// A scripted flight for tests and demos: fly forward while turning for a
/// number of frames, then save a screenshot of the window and close it.
pub struct Tour {
    pub frames: u32,
    pub screenshot: PathBuf,
    /// Set by the screenshot callback: `Ok` once written, or why not.
    pub outcome: Arc<Mutex<Option<Result<(), String>>>>,
    requested: bool,
}

impl Tour {
    pub fn new(frames: u32, screenshot: PathBuf) -> Self {
        Tour {
            frames,
            screenshot,
            outcome: Arc::new(Mutex::new(None)),
            requested: false,
        }
    }
}

/// Seconds a tour frame advances the flight, whatever the frame took.
const TOUR_STEP_S: f64 = 1.0 / 30.0;

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

    /// Fly `tour` instead of waiting for input.
    pub fn with_tour(mut self, tour: Tour) -> Self {
        self.tour = Some(tour);
        self
    }

    /// The next tour step: its controls while frames remain; the screenshot
    /// and the close once they are flown.
    fn tour_step(&mut self, ctx: &egui::Context) -> Option<Controls> {
        let tour = self.tour.as_mut()?;
        if tour.frames > 0 {
            tour.frames -= 1;
            return Some(Controls {
                forward: 1.0,
                turn: 0.3,
                ..Default::default()
            });
        }
        if !tour.requested {
            tour.requested = true;
            let (path, outcome) = (tour.screenshot.clone(), tour.outcome.clone());
            ctx.request_screenshot(move |image| {
                let rgba: Vec<u8> = image.pixels.iter().flat_map(|p| p.to_array()).collect();
                let written =
                    relevo_core::raster::png::encode_rgba(&rgba, image.size[0], image.size[1])
                        .and_then(|png| relevo_core::atomic::write_file(&path, &png))
                        .map_err(|e| e.to_string());
                *outcome.lock().unwrap_or_else(|p| p.into_inner()) = Some(written);
            });
        } else if tour.outcome.lock().map(|o| o.is_some()).unwrap_or(true) {
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
        ctx.request_repaint();
        Some(Controls::default())
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

    /// Apply the keys pressed this frame (the list of [`keys::BINDINGS`]);
    /// returns the held flight controls.
    fn keys(&mut self, ctx: &egui::Context) -> Controls {
        let mut controls = Controls::default();
        if ctx.egui_wants_keyboard_input() {
            return controls;
        }
        let mut pressed = Vec::new();
        ctx.input(|i| {
            for binding in keys::BINDINGS {
                match binding.input {
                    Input::Held(axis, plus, minus) => {
                        let value = f64::from(u8::from(i.key_down(plus)))
                            - f64::from(u8::from(i.key_down(minus)));
                        match axis {
                            Axis::Forward => controls.forward = value,
                            Axis::Turn => controls.turn = value,
                            Axis::Climb => controls.climb = value,
                        }
                    }
                    Input::Pressed(keys) => pressed.extend(
                        keys.iter()
                            .filter(|&&(key, _)| i.key_pressed(key))
                            .map(|&(_, action)| action),
                    ),
                    Input::Pointer => {}
                }
            }
        });
        for action in pressed {
            self.apply(action, ctx);
        }
        controls
    }

    /// Do what a key pressed once asks.
    fn apply(&mut self, action: Action, ctx: &egui::Context) {
        let s = &mut self.settings;
        match action {
            Action::MeshOrRaycast => {
                s.mode = match s.mode {
                    TerrainMode::Mesh => TerrainMode::Raycast,
                    TerrainMode::Raycast | TerrainMode::ZBuffer(_) => TerrainMode::Mesh,
                };
            }
            Action::Wireframe => s.wireframe = !s.wireframe,
            Action::Texture => s.texture = !s.texture,
            Action::Geomorphing => s.morph = !s.morph,
            Action::FinerMesh => s.tau_px = (s.tau_px / 1.5).max(0.25),
            Action::CoarserMesh => s.tau_px = (s.tau_px * 1.5).min(64.0),
            Action::Objects => s.objects = !s.objects,
            Action::Sprites => s.sprites = !s.sprites,
            Action::ImpostorAlpha => s.alpha = !s.alpha,
            Action::ImpostorBlur => s.blur = !s.blur,
            Action::Help => self.show_help = !self.show_help,
            Action::Faster | Action::Slower | Action::TerrainFollowing => {
                if let Some(f) = &mut self.flight {
                    match action {
                        Action::Faster => f.speed_mps = (f.speed_mps * 1.5).min(50_000.0),
                        Action::Slower => f.speed_mps = (f.speed_mps / 1.5).max(1.0),
                        _ => f.follow_terrain = !f.follow_terrain,
                    }
                }
            }
            Action::Home => {
                if let Some(scene) = &self.scene {
                    self.flight = Some(Flight::home(scene));
                }
            }
            Action::CopyCamera => self.copy_camera(ctx),
        }
    }

    fn copy_camera(&self, ctx: &egui::Context) {
        if let (Some(scene), Some(flight)) = (&self.scene, &self.flight) {
            ctx.copy_text(flight.pose(scene, self.stats.height.max(1)).to_string());
        }
    }

    /// The side panel: the same toggles as the keys, τ, the raycast
    /// options, the camera typed or copied.
    fn side_panel(&mut self, ui: &mut egui::Ui) {
        ui.heading("relevo-view");
        if let Some(scene) = &self.scene {
            ui.label(scene.path.display().to_string());
        }
        ui.separator();
        let s = &mut self.settings;
        ui.horizontal(|ui| {
            ui.selectable_value(&mut s.mode, TerrainMode::Mesh, "mesh");
            ui.selectable_value(&mut s.mode, TerrainMode::Raycast, "raycast");
        });
        ui.horizontal_wrapped(|ui| {
            ui.label("z-buffer");
            for r in Representation::ALL {
                ui.selectable_value(&mut s.mode, TerrainMode::ZBuffer(r), r.letter().to_string())
                    .on_hover_text(format!("{r:?}"));
            }
        });
        ui.label("Mesh");
        ui.add(
            egui::Slider::new(&mut s.tau_px, 0.25..=32.0)
                .logarithmic(true)
                .text("τ (px)"),
        );
        ui.checkbox(&mut s.morph, with_key("geomorphing", Action::Geomorphing));
        ui.checkbox(&mut s.cull, "frustum culling");
        ui.checkbox(&mut s.wireframe, with_key("wireframe", Action::Wireframe));
        ui.checkbox(&mut s.texture, with_key("drape texture", Action::Texture));
        ui.label("Raycast");
        let mut bands = s.raycast.bands.len() > 1 || s.raycast.bands.iter().any(|b| b.subvoxel);
        if ui
            .checkbox(&mut bands, "bands 4 slices/cell + sub-voxel to 3 km")
            .changed()
        {
            s.raycast.bands = if bands {
                settings::detailed_bands()
            } else {
                horizon::RenderOptions::default().bands
            };
        }
        let mut fixed = s.raycast.arithmetic == horizon::Arithmetic::Fixed;
        if ui.checkbox(&mut fixed, "16.16 fixed point").changed() {
            s.raycast.arithmetic = if fixed {
                horizon::Arithmetic::Fixed
            } else {
                horizon::Arithmetic::Float
            };
        }
        ui.checkbox(&mut s.raycast.prefilter, "prefiltered colour");
        ui.checkbox(&mut s.raycast.grow_steps, "slices spread with distance");
        ui.separator();
        if let Some(f) = &mut self.flight {
            ui.add(
                egui::Slider::new(&mut f.speed_mps, 1.0..=50_000.0)
                    .logarithmic(true)
                    .text("speed (m/s)"),
            );
            ui.checkbox(
                &mut f.follow_terrain,
                with_key("terrain following", Action::TerrainFollowing),
            );
            ui.add(egui::Slider::new(&mut f.fov_x_deg, 20.0..=120.0).text("field of view (°)"));
        }
        ui.checkbox(
            &mut self.settings.objects,
            with_key("objects and vegetation", Action::Objects),
        );
        ui.checkbox(&mut self.settings.terrain, "terrain");
        if let Some(vegetation) = self.scene.as_ref().and_then(|s| s.vegetation.as_ref()) {
            vegetation_panel(ui, &mut self.settings, vegetation);
        }
        ui.separator();
        let label = ui.label("Camera X,Y,Z,HEADING[,PITCHdeg][,INCL]");
        // The field shows the camera as it flies, except while being edited.
        let field = ui.make_persistent_id("camera");
        if !ui.memory(|m| m.has_focus(field)) {
            if let (Some(scene), Some(flight)) = (&self.scene, &self.flight) {
                self.camera_text = flight.pose(scene, self.stats.height.max(1)).to_string();
            }
        }
        ui.add(egui::TextEdit::singleline(&mut self.camera_text).id(field))
            .labelled_by(label.id);
        ui.horizontal(|ui| {
            if ui.button("Go").clicked() {
                self.go_to_typed_camera();
            }
            if ui
                .button(with_key("Copy camera", Action::CopyCamera))
                .clicked()
            {
                self.copy_camera(ui.ctx());
            }
            if ui.button("Home").clicked() {
                if let Some(scene) = &self.scene {
                    self.flight = Some(Flight::home(scene));
                }
            }
        });
    }

    /// Move to the camera string typed in the side panel.
    pub fn go_to_typed_camera(&mut self) {
        match CameraPose::parse(&self.camera_text) {
            Ok(pose) => {
                self.pending_pose = Some(pose);
                self.error = None;
            }
            Err(e) => self.error = Some(e),
        }
    }

    /// Move to a camera string's pose, its INCL read for a view
    /// `height_px` tall.
    fn go_to(&mut self, pose: &CameraPose, height_px: u32) {
        let Some(scene) = &self.scene else {
            return;
        };
        match Flight::from_pose(scene, pose, height_px) {
            Some(mut f) => {
                if let Some(old) = &self.flight {
                    f.speed_mps = old.speed_mps;
                    f.fov_x_deg = old.fov_x_deg;
                }
                f.keep_above_ground(scene);
                self.flight = Some(f);
            }
            None => self.error = Some("the bundle's geotransform cannot be inverted".into()),
        }
    }

    /// Fly, draw and show the 3D view filling `ui`.
    fn view(
        &mut self,
        ui: &mut egui::Ui,
        render_state: Option<&egui_wgpu::RenderState>,
        controls: Controls,
    ) {
        let rect = ui.available_rect_before_wrap();
        let ppp = ui.ctx().pixels_per_point();
        let size = [
            ((rect.width() * ppp) as u32).max(1),
            ((rect.height() * ppp) as u32).max(1),
        ];
        let response = ui.allocate_rect(rect, egui::Sense::click_and_drag());
        if let Some(pose) = self.pending_pose.take() {
            self.go_to(&pose, size[1]);
        }
        let (Some(scene), Some(flight), Some(state)) =
            (&mut self.scene, &mut self.flight, render_state)
        else {
            return;
        };
        let now = Instant::now();
        let mut dt = self
            .last_frame
            .map_or(0.0, |t| (now - t).as_secs_f64())
            .min(0.25);
        self.last_frame = Some(now);
        if self.frame_times.len() == HISTORY {
            self.frame_times.pop_front();
        }
        if dt > 0.0 {
            self.frame_times.push_back(dt);
        }

        let mut controls = controls;
        if self.tour.is_some() {
            dt = TOUR_STEP_S;
        }
        let drag = response.drag_delta();
        if response.dragged_by(egui::PointerButton::Primary) {
            controls.turn += drag.x as f64 / 4.0 / dt.max(1e-3) / 60.0;
            controls.look += drag.y as f64 / rect.height() as f64 / dt.max(1e-3) / 0.5;
        }
        let camera = flight.camera(scene, size);
        let pointer = response
            .hover_pos()
            .map(|p| ((p.x - rect.min.x) * ppp, (p.y - rect.min.y) * ppp));
        let ground = pointer.and_then(|(px, py)| {
            let distance = horizon::pick(&scene.terrain, &camera, px as f64, py as f64)?;
            let ray = horizon::pixel_ray(&camera, px as f64, py as f64);
            let p = camera.position + glam::DVec3::from_array(ray) * distance;
            Some(p)
        });
        self.ground_under_pointer = ground.map(|p| {
            let (e, n) = scene.frame.world_from_terrain(p.x, p.y);
            [e, n, p.z]
        });
        if let Some(target) = ground {
            let scroll = ui.ctx().input(|i| i.smooth_scroll_delta.y) as f64;
            if scroll != 0.0 {
                // Zoom: move a fraction of the way towards the point.
                let fraction = (scroll / 400.0).clamp(-0.5, 0.5);
                flight.position += (target - flight.position) * fraction;
            }
            if response.dragged_by(egui::PointerButton::Secondary) {
                // Orbit: turn the eye about the vertical through the point.
                let angle = (drag.x as f64 / 4.0).to_radians();
                let offset = flight.position - target;
                let (s, c) = angle.sin_cos();
                flight.position = target
                    + glam::DVec3::new(
                        offset.x * c + offset.y * s,
                        -offset.x * s + offset.y * c,
                        offset.z,
                    );
                flight.heading_deg += drag.x as f64 / 4.0;
            }
        }
        flight.fly(scene, &controls, dt);

        let camera = flight.camera(scene, size);
        let (device, queue) = (&state.device, &state.queue);
        let renderer = self
            .renderer
            .get_or_insert_with(|| gpu::Renderer::new(device, queue, scene, size));
        match renderer.render(device, queue, scene, &camera, &self.settings) {
            Ok(stats) => self.stats = stats,
            Err(e) => {
                self.error = Some(format!("{e:#}"));
                self.settings.mode = TerrainMode::Mesh;
            }
        }
        let view = &renderer.targets.colour_view;
        let mut egui_renderer = state.renderer.write();
        let id = match self.texture {
            Some((id, registered)) if registered == size => id,
            Some((id, _)) => {
                egui_renderer.update_egui_texture_from_wgpu_texture(
                    device,
                    view,
                    wgpu::FilterMode::Nearest,
                    id,
                );
                id
            }
            None => egui_renderer.register_native_texture(device, view, wgpu::FilterMode::Nearest),
        };
        self.texture = Some((id, size));
        drop(egui_renderer);
        ui.painter().image(
            id,
            rect,
            egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
            egui::Color32::WHITE,
        );
        self.hud(ui, rect);
        ui.ctx().request_repaint();
    }

    /// The HUD over the view: its lines and a frame-time plot.
    fn hud(&self, ui: &egui::Ui, rect: egui::Rect) {
        let times: Vec<f64> = self.frame_times.iter().copied().collect();
        hud::paint(ui.painter(), rect, &self.hud_lines(), &times, HISTORY);
    }

    fn help(&mut self, ctx: &egui::Context) {
        let mut open = self.show_help;
        egui::Window::new("Keys")
            .open(&mut open)
            .collapsible(false)
            .show(ctx, |ui| {
                egui::Grid::new("keys").striped(true).show(ui, |ui| {
                    for keys::Binding {
                        label: key, what, ..
                    } in keys::BINDINGS
                    {
                        ui.monospace(*key);
                        ui.label(*what);
                        ui.end_row();
                    }
                });
            });
        self.show_help = open;
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

/// The vegetation controls: the selection, sprites, alpha, blur, the view
/// angle, and the cut's bands as the bundle was baked for them.
fn vegetation_panel(ui: &mut egui::Ui, s: &mut Settings, vegetation: &crate::scene::Vegetation) {
    use crate::settings::VegetationSelection;
    ui.separator();
    ui.label("Vegetation");
    ui.horizontal(|ui| {
        ui.selectable_value(&mut s.vegetation, VegetationSelection::Quadtree, "quadtree");
        ui.selectable_value(&mut s.vegetation, VegetationSelection::List, "list");
        ui.selectable_value(
            &mut s.vegetation,
            VegetationSelection::Blobs { side_m: 3000.0 },
            "blobs 3 km",
        );
    });
    ui.checkbox(&mut s.sprites, with_key("sprites", Action::Sprites));
    ui.checkbox(&mut s.alpha, with_key("alpha", Action::ImpostorAlpha));
    ui.checkbox(&mut s.blur, with_key("blur", Action::ImpostorBlur));
    ui.add(egui::Slider::new(&mut s.view_angle_deg, 0.0..=90.0).text("top view above (°)"));
    ui.checkbox(
        &mut s.automatic_view_angle,
        "automatic view angle (per impostor)",
    );
    ui.add(egui::Slider::new(&mut s.level_fade, 0.0..=1.0).text("cluster to children fade"));
    let bands: Vec<String> = vegetation
        .cut
        .bands
        .iter()
        .map(|b| format!("≤{:.0} m: {}", b.until_m, b.max_cluster))
        .collect();
    ui.label(format!("bands (largest cluster): {}", bands.join(", ")));
}
