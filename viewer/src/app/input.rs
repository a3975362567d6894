//! Keys and cameras: the key list applied to the flight and the settings,
//! the camera string copied, typed or given on the command line.

use super::ViewerApp;
use crate::flight::{Controls, Flight};
use crate::keys::{self, Action, Axis, Input};
use crate::settings::TerrainMode;
use eframe::egui;
use relevo_core::scene::CameraPose;

impl ViewerApp {
    /// Apply the keys pressed this frame (the list of [`keys::BINDINGS`]);
    /// returns the held flight controls.
    pub(super) fn keys(&mut self, ctx: &egui::Context) -> Controls {
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
    pub(super) fn apply(&mut self, action: Action, ctx: &egui::Context) {
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

    pub(super) fn copy_camera(&self, ctx: &egui::Context) {
        if let (Some(scene), Some(flight)) = (&self.scene, &self.flight) {
            ctx.copy_text(flight.pose(scene, self.stats.height.max(1)).to_string());
        }
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
    pub(super) fn go_to(&mut self, pose: &CameraPose, height_px: u32) {
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
}
