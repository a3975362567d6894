//! The HUD (after SJD-Vis3D and Enviro): frame rate and time with a
//! frame-time plot, what was drawn, speed, camera and ground positions in
//! the bundle's CRS. The window paints it over the view each frame;
//! `relevo-view render --hud` paints the same lines into the image.

use crate::flight::Flight;
use crate::gpu::FrameStats;
use crate::scene::Scene;
use crate::settings::{Settings, TerrainMode};
use eframe::egui;

/// What the HUD reports.
pub struct Readings<'a> {
    pub fps: f64,
    pub frame_ms: f64,
    pub settings: &'a Settings,
    pub stats: &'a FrameStats,
    pub scene: Option<&'a Scene>,
    pub flight: Option<&'a Flight>,
    /// World (east, north, height) of the ground under the pointer.
    pub pointer: Option<[f64; 3]>,
}

/// The HUD's lines.
pub fn lines(r: &Readings) -> Vec<String> {
    let mut lines = vec![format!("{:.0} fps   {:.1} ms", r.fps, r.frame_ms)];
    let s = r.settings;
    let mode = match s.mode {
        TerrainMode::Mesh => format!(
            "mesh τ {:.1} px{}",
            s.tau_px,
            if s.morph { ", geomorphing" } else { "" }
        ),
        TerrainMode::Raycast => "raycast (floating horizon)".to_string(),
        TerrainMode::ZBuffer(rep) => format!("z-buffer baseline [{}] {rep:?}", rep.letter()),
    };
    lines.push(format!("{mode}   {} triangles", r.stats.triangles));
    if let (Some(scene), Some(flight)) = (r.scene, r.flight) {
        let pose = flight.pose(scene, r.stats.height.max(1));
        let [e, n, z] = pose.eye;
        lines.push(format!("speed {:.0} km/h", flight.speed_mps * 3.6));
        lines.push(format!(
            "camera E {e:.1}  N {n:.1}  h {z:.1} m  heading {:.0}°",
            pose.heading_deg
        ));
        match flight.height_above_ground(scene) {
            Some(h) => lines.push(format!("above ground {h:.1} m")),
            None => lines.push("above ground: off the data".into()),
        }
    }
    match r.pointer {
        Some([e, n, z]) => lines.push(format!("pointer E {e:.1}  N {n:.1}  ground {z:.1} m")),
        None => lines.push("pointer: sky".into()),
    }
    if let Some(p) = &r.stats.paging {
        let under = r
            .pointer
            .zip(r.scene)
            .and_then(|([e, n, _], scene)| scene.tile_level_at(e, n))
            .map_or(String::new(), |l| format!(", level {l} under the pointer"));
        lines.push(format!(
            "tiles: {} resident ({:.0} MB), {} loading, {} drawn down to level {}{under}",
            p.resident,
            p.resident_bytes as f64 / 1e6,
            p.loading,
            p.leaves,
            p.finest_level,
        ));
    }
    let windows = r.scene.and_then(|scene| scene.level_windows.as_ref());
    if let (TerrainMode::Raycast, Some(w)) = (s.mode, windows) {
        let reads = w.reads();
        lines.push(format!(
            "level windows: {} read ahead, {} waited for ({} this frame)",
            reads.ahead, reads.waited, r.stats.level_windows_waited
        ));
    }
    let objects = match r.scene.and_then(|scene| scene.objects.as_ref()) {
        None => "objects: none loaded".to_string(),
        Some(o) if s.objects => format!(
            "objects on: {} features, {} triangles",
            o.features, r.stats.object_triangles
        ),
        Some(o) => format!("objects off ({} features)", o.features),
    };
    lines.push(format!("{objects}   h: help"));
    if let Some(v) = r.scene.and_then(|scene| scene.vegetation.as_ref()) {
        if s.objects {
            lines.push(format!(
                "vegetation ({}{}): {} objects represented",
                s.vegetation,
                if s.sprites { ", sprites" } else { "" },
                r.stats.vegetation_represented,
            ));
            lines.push(format!(
                "  {} impostors drawn ({} views), cut {:.2} ms",
                r.stats.impostors, r.stats.impostor_views, r.stats.cut_ms
            ));
            let per_depth: Vec<String> = v
                .list
                .clusters_per_depth
                .iter()
                .enumerate()
                .filter(|(_, &n)| n > 0)
                .map(|(depth, n)| format!("d{depth}:{n}"))
                .collect();
            let bands: Vec<String> = v
                .cut
                .bands
                .iter()
                .map(|b| format!("{:.0}m:{}", b.until_m, b.max_cluster))
                .collect();
            lines.push(format!(
                "  clusters by depth {}",
                if per_depth.is_empty() {
                    "none".to_string()
                } else {
                    per_depth.join(" ")
                },
            ));
            lines.push(format!(
                "  bands {}   top view {}",
                bands.join(" "),
                if s.automatic_view_angle {
                    "where it shows more".to_string()
                } else {
                    format!("above {:.0}°", s.view_angle_deg)
                }
            ));
        } else {
            lines.push(format!(
                "vegetation off ({} objects)",
                v.clusters.tree.objects.len()
            ));
        }
    }
    lines
}

/// Paint `lines` and a plot of `frame_times` (seconds, newest last, at
/// most `history` of them) in a dark panel at the top left of `rect`.
pub fn paint(
    painter: &egui::Painter,
    rect: egui::Rect,
    lines: &[String],
    frame_times: &[f64],
    history: usize,
) {
    let font = egui::FontId::monospace(13.0);
    let galleys: Vec<_> = lines
        .iter()
        .map(|line| painter.layout_no_wrap(line.clone(), font.clone(), egui::Color32::WHITE))
        .collect();
    // As wide as the longest line (at least 430 px), within the view.
    let widest = galleys.iter().map(|g| g.size().x).fold(0.0, f32::max);
    let width = (widest + 16.0).max(430.0).min(rect.width() - 16.0);
    let height = 16.0 * lines.len() as f32 + 60.0;
    let panel =
        egui::Rect::from_min_size(rect.min + egui::vec2(8.0, 8.0), egui::vec2(width, height));
    painter.rect_filled(panel, 4.0, egui::Color32::from_black_alpha(150));
    let text = painter.with_clip_rect(panel);
    for (k, galley) in galleys.into_iter().enumerate() {
        text.galley(
            panel.min + egui::vec2(8.0, 6.0 + 16.0 * k as f32),
            galley,
            egui::Color32::WHITE,
        );
    }
    // Frame time, newest on the right; the line marks 33 ms (30 fps).
    let plot = egui::Rect::from_min_size(
        egui::pos2(panel.min.x + 8.0, panel.max.y - 48.0),
        egui::vec2(panel.width() - 16.0, 40.0),
    );
    let to_y = |seconds: f64| plot.max.y - (seconds / 0.1).min(1.0) as f32 * plot.height();
    painter.line_segment(
        [
            egui::pos2(plot.min.x, to_y(1.0 / 30.0)),
            egui::pos2(plot.max.x, to_y(1.0 / 30.0)),
        ],
        egui::Stroke::new(1.0, egui::Color32::from_rgb(200, 120, 60)),
    );
    let points: Vec<egui::Pos2> = frame_times
        .iter()
        .enumerate()
        .map(|(k, &t)| {
            egui::pos2(
                plot.min.x + plot.width() * k as f32 / history as f32,
                to_y(t),
            )
        })
        .collect();
    painter.add(egui::Shape::line(
        points,
        egui::Stroke::new(1.0, egui::Color32::LIGHT_GREEN),
    ));
}
