//! The scripted tour: fly forward while turning for a number of frames,
//! then save a screenshot of the window and close it (tests, demos, the
//! README's picture).

use super::ViewerApp;
use crate::flight::Controls;
use eframe::egui;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

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
pub(super) const TOUR_STEP_S: f64 = 1.0 / 30.0;

impl ViewerApp {
    /// Fly `tour` instead of waiting for input.
    pub fn with_tour(mut self, tour: Tour) -> Self {
        self.tour = Some(tour);
        self
    }

    /// The next tour step: its controls while frames remain; the screenshot
    /// and the close once they are flown.
    pub(super) fn tour_step(&mut self, ctx: &egui::Context) -> Option<Controls> {
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
}
