//! The side panel: the same toggles as the keys (labelled with them), τ,
//! the raycast and vegetation options, the camera typed or copied.

use super::ViewerApp;
use crate::flight::Flight;
use crate::keys::{self, Action};
use crate::settings::{self, Settings, TerrainMode};
use eframe::egui;
use relevo_core::horizon;
use relevo_core::zbuffer::Representation;

/// A side-panel label with the key that does the same: "wireframe (w)".
fn with_key(text: &str, action: Action) -> String {
    format!("{text} ({})", keys::label_of(action))
}

impl ViewerApp {
    /// The side panel: the same toggles as the keys, τ, the raycast
    /// options, the camera typed or copied.
    pub(super) fn side_panel(&mut self, ui: &mut egui::Ui) {
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
