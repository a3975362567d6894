//! The 3D view: the pointer's navigation (look, orbit, zoom about the
//! ground under it), the flight, the frame drawn by the GPU renderer and
//! shown as an egui image, the HUD over it and the help window.

use super::tour::TOUR_STEP_S;
use super::{ViewerApp, HISTORY};
use crate::flight::Controls;
use crate::gpu;
use crate::hud;
use crate::keys;
use crate::settings::TerrainMode;
use eframe::egui;
use eframe::egui_wgpu::{self, wgpu};
use relevo_core::horizon;
use std::time::Instant;

impl ViewerApp {
    /// Fly, draw and show the 3D view filling `ui`.
    pub(super) fn view(
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
    pub(super) fn hud(&self, ui: &egui::Ui, rect: egui::Rect) {
        let times: Vec<f64> = self.frame_times.iter().copied().collect();
        hud::paint(ui.painter(), rect, &self.hud_lines(), &times, HISTORY);
    }

    pub(super) fn help(&mut self, ctx: &egui::Context) {
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
