//! Two bundles compared — before and after an input changed, a sample
//! moved or Relevo was upgraded: per artifact whether it changed, and for
//! grids on the same cells the largest change and where, the RMS and the
//! area changed beyond a threshold; the vegetation matched object to
//! object; renders at named cameras compared; and pictures of all that.

use super::check::render_reference;
use super::record::RenderRecord;
use super::vegetation::{match_objects, ClassChanges};
use crate::bundle::BundleFiles;
use crate::bundle::{names, Bundle};
use crate::raster::compare::{difference, difference_image, ImageDifference};
use crate::raster::png::encode_rgba;
use crate::raster::tint::terrain_drape;
use crate::veg::db::VegObject;
use crate::Result;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};

/// What a diff looks for.
#[derive(Debug, Clone)]
pub struct DiffOptions {
    /// Height changes larger than this count towards the area changed, metres.
    pub threshold_m: f64,
    /// Vegetation objects of one class closer than this are the same object
    /// moved, metres.
    pub match_radius_m: f64,
    /// Renders of both bundles to compare.
    pub renders: Vec<RenderRecord>,
}

/// A grid vertex or drape pixel and where its centre is in the CRS.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Location {
    pub col: usize,
    pub row: usize,
    pub x: f64,
    pub y: f64,
}

/// How a grid of values (heights, LP errors) changed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GridChange {
    /// Vertices with data in both whose value changed.
    pub changed_cells: usize,
    /// The largest |after − before| and where, with both values.
    pub largest: f64,
    pub at: Option<Location>,
    pub before: f64,
    pub after: f64,
    /// Root mean square of the change over vertices with data in both.
    pub rms: f64,
    /// Vertices whose change exceeds the threshold, and their area (m²).
    pub cells_beyond_threshold: usize,
    pub area_beyond_threshold_m2: f64,
}

/// How the drape changed (same size and place).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DrapeChange {
    pub changed_pixels: usize,
    /// The largest channel change, levels, and where.
    pub largest_levels: u8,
    pub at: Option<Location>,
}

/// One class's vegetation change, in figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClassSummary {
    pub before: usize,
    pub after: usize,
    pub kept: usize,
    pub moved: usize,
    pub added: usize,
    pub removed: usize,
    /// The farthest move, metres.
    pub largest_move_m: f64,
}

/// A render of both bundles compared.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RenderChange {
    pub name: String,
    pub camera: String,
    pub difference: ImageDifference,
}

/// Everything a diff found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DiffReport {
    /// Manifest keys (artifacts and exports) whose files differ, are only
    /// in the first bundle, or only in the second.
    pub changed: Vec<String>,
    pub only_before: Vec<String>,
    pub only_after: Vec<String>,
    /// Whether both grids have the same cells (side and georeferencing):
    /// only then are they compared cell by cell.
    pub same_grid: bool,
    pub sides: [usize; 2],
    pub threshold_m: f64,
    pub height: Option<GridChange>,
    /// Vertices that gained data, and that lost it.
    pub mask_gained: usize,
    pub mask_lost: usize,
    pub lp_error: Option<GridChange>,
    pub drape: Option<DrapeChange>,
    pub vegetation: BTreeMap<String, ClassSummary>,
    /// Whether the clusters were baked again (any cluster file differs).
    pub clusters_rebaked: bool,
    pub renders: Vec<RenderChange>,
}

impl DiffReport {
    /// Whether the bundles hold the same artifacts, byte for byte, and
    /// the renders are equal.
    pub fn identical(&self) -> bool {
        self.changed.is_empty()
            && self.only_before.is_empty()
            && self.only_after.is_empty()
            && self.renders.iter().all(|r| r.difference.pixels_off == 0)
    }
}

/// Compare bundle `a` (before) with `b` (after).
pub fn diff(a: &Bundle, b: &Bundle, options: &DiffOptions) -> Result<DiffReport> {
    let files = |x: &Bundle| -> BTreeMap<String, String> {
        x.manifest
            .artifacts
            .iter()
            .chain(&x.manifest.exports)
            .map(|(k, v)| (k.clone(), v.sha256.clone()))
            .collect()
    };
    let (fa, fb) = (files(a), files(b));
    let keys: BTreeSet<&String> = fa.keys().chain(fb.keys()).collect();
    let (mut changed, mut only_before, mut only_after) = (Vec::new(), Vec::new(), Vec::new());
    for k in keys {
        match (fa.get(k), fb.get(k)) {
            (Some(x), Some(y)) if x != y => changed.push(k.clone()),
            (Some(_), None) => only_before.push(k.clone()),
            (None, Some(_)) => only_after.push(k.clone()),
            _ => {}
        }
    }
    let (ga, gb) = (&a.manifest.grid, &b.manifest.grid);
    let same_grid = ga.side == gb.side && ga.geotransform == gb.geotransform;
    let mut report = DiffReport {
        clusters_rebaked: changed
            .iter()
            .chain(&only_before)
            .chain(&only_after)
            .any(|k| k.starts_with(names::CLUSTERS_PREFIX)),
        changed,
        only_before,
        only_after,
        same_grid,
        sides: [ga.side, gb.side],
        threshold_m: options.threshold_m,
        height: None,
        mask_gained: 0,
        mask_lost: 0,
        lp_error: None,
        drape: None,
        vegetation: BTreeMap::new(),
        renders: Vec::new(),
    };
    if same_grid {
        compare_grids(a, b, options, &mut report)?;
    }
    report.drape = compare_drapes(a, b)?;
    let (va, vb) = (
        a.vegetation()?.unwrap_or_default(),
        b.vegetation()?.unwrap_or_default(),
    );
    report.vegetation = match_objects(&va, &vb, options.match_radius_m)
        .into_iter()
        .map(|(class, c)| (class, summarise(&c)))
        .collect();
    for render in &options.renders {
        let (ra, rb) = (render_reference(a, render)?, render_reference(b, render)?);
        if let Some(d) = difference(&rb, &ra, 16) {
            report.renders.push(RenderChange {
                name: render.name.clone(),
                camera: render.camera.clone(),
                difference: d,
            });
        }
    }
    Ok(report)
}

fn summarise(c: &ClassChanges) -> ClassSummary {
    ClassSummary {
        before: c.before,
        after: c.after,
        kept: c.kept,
        moved: c.moved.len(),
        added: c.added.len(),
        removed: c.removed.len(),
        largest_move_m: c
            .moved
            .iter()
            .map(|(p, q)| (p.x - q.x).hypot(p.y - q.y))
            .fold(0.0, f64::max),
    }
}

/// Heights, mask and LP errors vertex by vertex (same grid).
fn compare_grids(
    a: &Bundle,
    b: &Bundle,
    options: &DiffOptions,
    report: &mut DiffReport,
) -> Result<()> {
    let g = &a.manifest.grid;
    let frame = a.frame();
    let locate = |i: usize| {
        let (col, row) = (i % g.side, i / g.side);
        let (x, y) = frame.world_from_vertex(col as f64, row as f64);
        Location { col, row, x, y }
    };
    let (ha, hb, ma, mb) = (a.heights()?, b.heights()?, a.mask()?, b.mask()?);
    let both = |i: usize| ma[i] == 1 && mb[i] == 1;
    report.mask_gained = ma
        .iter()
        .zip(mb.iter())
        .filter(|(x, y)| **x == 0 && **y == 1)
        .count();
    report.mask_lost = ma
        .iter()
        .zip(mb.iter())
        .filter(|(x, y)| **x == 1 && **y == 0)
        .count();
    let cell_area = g.cell_size_m * g.cell_size_m;
    report.height = Some(grid_change(
        ha.len(),
        |i| both(i).then(|| (f64::from(ha[i]), f64::from(hb[i]))),
        options.threshold_m,
        cell_area,
        &locate,
    ));
    let (la, lb) = (a.lp()?, b.lp()?);
    let (ea, eb) = (la.hierarchy(), lb.hierarchy());
    report.lp_error = Some(grid_change(
        ha.len(),
        |i| Some((f64::from(ea.error(i)), f64::from(eb.error(i)))),
        options.threshold_m,
        cell_area,
        &locate,
    ));
    Ok(())
}

/// The change of `n` paired values (`None` where not compared).
fn grid_change(
    n: usize,
    pair: impl Fn(usize) -> Option<(f64, f64)>,
    threshold: f64,
    cell_area_m2: f64,
    locate: &dyn Fn(usize) -> Location,
) -> GridChange {
    let mut change = GridChange {
        changed_cells: 0,
        largest: 0.0,
        at: None,
        before: 0.0,
        after: 0.0,
        rms: 0.0,
        cells_beyond_threshold: 0,
        area_beyond_threshold_m2: 0.0,
    };
    let (mut squares, mut compared) = (0.0f64, 0usize);
    for i in 0..n {
        let Some((x, y)) = pair(i) else { continue };
        compared += 1;
        let d = (y - x).abs();
        squares += d * d;
        if d > 0.0 {
            change.changed_cells += 1;
        }
        if d > threshold {
            change.cells_beyond_threshold += 1;
        }
        if d > change.largest {
            change.largest = d;
            change.at = Some(locate(i));
            change.before = x;
            change.after = y;
        }
    }
    change.rms = (squares / compared.max(1) as f64).sqrt();
    change.area_beyond_threshold_m2 = change.cells_beyond_threshold as f64 * cell_area_m2;
    change
}

/// The drapes pixel by pixel, when both have one of the same size and place.
fn compare_drapes(a: &Bundle, b: &Bundle) -> Result<Option<DrapeChange>> {
    let (Some(da), Some(db)) = (a.drape()?, b.drape()?) else {
        return Ok(None);
    };
    if (da.info.width, da.info.height, da.info.geotransform)
        != (db.info.width, db.info.height, db.info.geotransform)
    {
        return Ok(None);
    }
    let mut change = DrapeChange {
        changed_pixels: 0,
        largest_levels: 0,
        at: None,
    };
    for (i, (p, q)) in da
        .rgba
        .chunks_exact(4)
        .zip(db.rgba.chunks_exact(4))
        .enumerate()
    {
        let d = (0..4).map(|k| p[k].abs_diff(q[k])).max().unwrap_or(0);
        if d > 0 {
            change.changed_pixels += 1;
        }
        if d > change.largest_levels {
            change.largest_levels = d;
            let (col, row) = (i % da.info.width, i / da.info.width);
            let (x, y) = da
                .info
                .geotransform
                .apply(col as f64 + 0.5, row as f64 + 0.5);
            change.at = Some(Location { col, row, x, y });
        }
    }
    Ok(Some(change))
}

/// Pictures of a diff, as (file name, PNG bytes): `height_change.png`, the
/// height change over the first bundle's shaded relief (red raised, blue
/// lowered, full colour at the largest change); `vegetation_change.png`,
/// the vegetation over the same relief (green added, red removed, yellow
/// moved, with a line from where it was); per render `render_NAME_before`,
/// `_after` and `_difference`.
pub fn diff_images(
    a: &Bundle,
    b: &Bundle,
    report: &DiffReport,
    options: &DiffOptions,
) -> Result<Vec<(String, Vec<u8>)>> {
    let mut images = Vec::new();
    let g = &a.manifest.grid;
    let side = g.side;
    crate::memory::check(
        &format!("diff pictures of a {side}×{side} grid"),
        (side * side) as u64,
        16,
        "compare smaller bundles",
    )?;
    // Small grids are enlarged (whole pixels a vertex) to be seen.
    let scale = (PICTURE_SIDE / side).max(1);
    let (ha, ma) = (a.heights()?, a.mask()?);
    let relief = grey_relief(&ha, &ma, side, g.cell_size_m, g.height_range_m);
    if report.same_grid {
        let hb = b.heights()?;
        let largest = report.height.as_ref().map_or(0.0, |h| h.largest).max(1e-9);
        let mut rgba = relief.clone();
        for (i, px) in rgba.chunks_exact_mut(4).enumerate() {
            let d = f64::from(hb[i]) - f64::from(ha[i]);
            if d == 0.0 || ma[i] == 0 {
                continue;
            }
            let t = (d.abs() / largest).sqrt().clamp(0.25, 1.0);
            let colour = if d > 0.0 {
                [230.0, 40.0, 30.0]
            } else {
                [30.0, 80.0, 230.0]
            };
            for k in 0..3 {
                px[k] = (f64::from(px[k]) * (1.0 - t) + colour[k] * t).round() as u8;
            }
        }
        let (big, big_side) = enlarged(&rgba, side, scale);
        images.push((
            "height_change.png".into(),
            encode_rgba(&big, big_side, big_side)?,
        ));
    }
    let (va, vb) = (
        a.vegetation()?.unwrap_or_default(),
        b.vegetation()?.unwrap_or_default(),
    );
    if !(va.is_empty() && vb.is_empty()) {
        let changes = match_objects(&va, &vb, options.match_radius_m);
        let (big, big_side) = enlarged(&relief, side, scale);
        let png = vegetation_picture(&big, big_side, scale, &g.geotransform, &changes)?;
        images.push(("vegetation_change.png".into(), png));
    }
    for render in &options.renders {
        let (ra, rb) = (render_reference(a, render)?, render_reference(b, render)?);
        let [w, h] = render.size.map(|v| v as usize);
        images.push((
            format!("render_{}_before.png", render.name),
            encode_rgba(&ra, w, h)?,
        ));
        images.push((
            format!("render_{}_after.png", render.name),
            encode_rgba(&rb, w, h)?,
        ));
        images.push((
            format!("render_{}_difference.png", render.name),
            encode_rgba(&difference_image(&rb, &ra), w, h)?,
        ));
    }
    Ok(images)
}

/// Side below which diff pictures are enlarged, pixels.
const PICTURE_SIDE: usize = 512;

/// A `side`² RGBA8 image with each pixel repeated `scale`² times.
fn enlarged(rgba: &[u8], side: usize, scale: usize) -> (Vec<u8>, usize) {
    let big = side * scale;
    let mut out = Vec::with_capacity(big * big * 4);
    for r in 0..big {
        for c in 0..big {
            let i = ((r / scale) * side + c / scale) * 4;
            out.extend_from_slice(&rgba[i..i + 4]);
        }
    }
    (out, big)
}

/// The grid's shaded relief in grey, dimmed so colours read over it;
/// black where there is no data.
fn grey_relief(heights: &[f32], mask: &[u8], side: usize, cell: f64, range: [f32; 2]) -> Vec<u8> {
    let mut rgba = terrain_drape(heights, mask, side, cell, range);
    for px in rgba.chunks_exact_mut(4) {
        let grey =
            (0.3 * f64::from(px[0]) + 0.59 * f64::from(px[1]) + 0.11 * f64::from(px[2])) * 0.8;
        px[..3].fill(grey.round() as u8);
        px[3] = 255;
    }
    rgba
}

/// The vegetation changes drawn over `relief` (`scale` pixels a vertex).
fn vegetation_picture(
    relief: &[u8],
    side: usize,
    scale: usize,
    geo: &crate::geo::GeoTransform,
    changes: &BTreeMap<String, ClassChanges>,
) -> Result<Vec<u8>> {
    let size = tiny_skia::IntSize::from_wh(side as u32, side as u32)
        .ok_or_else(|| crate::Error::Input("an empty grid has no picture".into()))?;
    let mut pixmap = tiny_skia::Pixmap::from_vec(relief.to_vec(), size)
        .ok_or_else(|| crate::Error::Input("cannot draw the vegetation picture".into()))?;
    let at = |o: &VegObject| {
        let (c, r) = geo.invert(o.x, o.y).unwrap_or((-1.0, -1.0));
        ((c * scale as f64) as f32, (r * scale as f64) as f32)
    };
    let radius = (side as f32 / 300.0).max(2.0);
    let paint = |rgb: [u8; 3]| {
        let mut p = tiny_skia::Paint::default();
        p.set_color_rgba8(rgb[0], rgb[1], rgb[2], 255);
        p.anti_alias = true;
        p
    };
    let stroke = tiny_skia::Stroke {
        width: (radius / 2.0).max(1.0),
        ..Default::default()
    };
    let dot = |pixmap: &mut tiny_skia::Pixmap, (x, y): (f32, f32), rgb| {
        if let Some(path) = tiny_skia::PathBuilder::from_circle(x, y, radius) {
            pixmap.fill_path(
                &path,
                &paint(rgb),
                tiny_skia::FillRule::Winding,
                tiny_skia::Transform::identity(),
                None,
            );
        }
    };
    for c in changes.values() {
        for o in &c.removed {
            dot(&mut pixmap, at(o), [230, 40, 30]);
        }
        for o in &c.added {
            dot(&mut pixmap, at(o), [40, 200, 60]);
        }
        for (p, q) in &c.moved {
            let mut line = tiny_skia::PathBuilder::new();
            line.move_to(at(p).0, at(p).1);
            line.line_to(at(q).0, at(q).1);
            if let Some(path) = line.finish() {
                pixmap.stroke_path(
                    &path,
                    &paint([240, 220, 40]),
                    &stroke,
                    tiny_skia::Transform::identity(),
                    None,
                );
            }
            dot(&mut pixmap, at(q), [240, 220, 40]);
        }
    }
    encode_rgba(pixmap.data(), side, side)
}
