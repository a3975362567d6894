//! A pyramid raycast: the floating-horizon renderer's distance bands
//! (seed 000 §6.3) are the pyramid's levels. Band l reads level l, whose
//! cells are 2^l level-0 cells, from where such a cell shrinks to
//! `max_cell_px` pixels on screen; each band loads only its level's
//! lattice under the ground its slices reach. Nothing the size of the
//! region is held: a frame holds a few windows of about the same number
//! of vertices, one a level. [`LevelWindows`] keeps them for the next
//! frame, so a moving camera reads a level again only when its band leaves
//! the window read before.

use super::reader::Pyramid;
use crate::camera::Camera;
use crate::geo::TerrainFrame;
use crate::grid::vertex_normal_of;
use crate::horizon::{
    hillshade, ColorSource, DistanceBand, GridExtent, LevelTerrain, Levels, RaycastFrame,
    Raycaster, RenderOptions, Terrain,
};
use crate::lp::window::Rect;
use crate::Result;
use std::sync::{Arc, Mutex, PoisonError};

/// How a pyramid is raycast beyond the raycaster's own options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelOptions {
    /// The largest a level's cell may look on screen, pixels, before the
    /// next band reads the next coarser level.
    pub max_cell_px: f64,
    /// Bake a hillshade into each level's colour: sun azimuth and
    /// elevation, degrees.
    pub hillshade: Option<[f64; 2]>,
}

/// The bands that make level l serve the forward distances where its cell
/// (2^l level-0 cells) looks between `max_cell_px`/2 and `max_cell_px`
/// pixels (level 0 from the eye on, the top level to the end), one slice a
/// level cell, nearest samples.
pub fn level_bands(p: &Pyramid, camera: &Camera, max_cell_px: f64) -> Vec<DistanceBand> {
    let levels = p.layout.levels();
    let cell = p.manifest.grid.cell_size_m;
    let d = camera.plane_distance_px();
    (0..levels)
        .map(|l| {
            let scale = (1u64 << l) as f64;
            DistanceBand {
                // A level-(l+1) cell, 2^(l+1)·cell, is max_cell_px pixels at
                // forward distance 2^(l+1)·cell·d / max_cell_px.
                until_m: if l + 1 == levels {
                    f64::INFINITY
                } else {
                    2.0 * scale * cell * d / max_cell_px
                },
                slices_per_cell: 1.0 / scale,
                subvoxel: false,
            }
        })
        .collect()
}

/// A level a raycast read: its number and the lattice window, vertices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LevelRead {
    pub level: u32,
    pub width: usize,
    pub height: usize,
}

/// The level windows a pyramid's raycasts read, kept from one frame to the
/// next. A band whose ground lies inside the window its level read before
/// reads nothing; one that leaves it reads its window grown by
/// [`WINDOW_MARGIN`] of its size on each side (clamped to the level), so a
/// camera that moves or turns a little reads nothing new. The raycast is
/// the same whichever window a level comes from: a sample reads its
/// lattice vertices' heights, mask and colour, and a baked hillshade's
/// normals look past the window's edge (where a level's cell is under a
/// pixel, beyond the last band's reach, the drape's averaged colour levels
/// follow the window's origin).
#[derive(Default)]
pub struct LevelWindows {
    /// Per level, the window held.
    held: Mutex<Vec<Option<HeldWindow>>>,
    /// The hillshade the windows were baked with.
    hillshade: Option<[f64; 2]>,
}

/// A level's lattice window and its terrain.
#[derive(Clone)]
struct HeldWindow {
    rect: Rect,
    terrain: Arc<LevelTerrain>,
}

/// How much larger than a band's ground a level window is read, as a
/// fraction of the ground's width and height on each side.
pub const WINDOW_MARGIN: f64 = 0.25;

impl LevelWindows {
    /// Level `level` over the ground box `[x0, y0, x1, y1]` (level-0
    /// terrain frame, metres): the window held when it covers the box, else
    /// a grown one read from `p`; with the window read (`None` when none
    /// was).
    fn level(
        &self,
        p: &Pyramid,
        level: u32,
        ground: [f64; 4],
        hillshade: Option<[f64; 2]>,
    ) -> Result<(Arc<LevelTerrain>, Option<LevelRead>)> {
        let wanted = lattice_rect(p, level, ground, 0.0);
        let l = level as usize;
        let room_for_level = |windows: &mut Vec<Option<HeldWindow>>| {
            if windows.len() <= l {
                windows.resize(l + 1, None);
            }
        };
        {
            let mut windows = self.held.lock().unwrap_or_else(PoisonError::into_inner);
            room_for_level(&mut windows);
            if let Some(window) = windows[l].as_ref().filter(|w| contains(&w.rect, &wanted)) {
                return Ok((window.terrain.clone(), None));
            }
        }
        // Read without the lock: other levels are read beside this one.
        let rect = lattice_rect(p, level, ground, WINDOW_MARGIN);
        let (terrain, read) = load_level(p, level, rect, hillshade)?;
        let terrain = Arc::new(terrain);
        let mut windows = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        room_for_level(&mut windows);
        windows[l] = Some(HeldWindow {
            rect,
            terrain: terrain.clone(),
        });
        Ok((terrain, Some(read)))
    }
}

/// Whether lattice window `outer` holds all of `inner`.
fn contains(outer: &Rect, inner: &Rect) -> bool {
    outer.c0 <= inner.c0
        && outer.r0 <= inner.r0
        && inner.c0 + inner.width <= outer.c0 + outer.width
        && inner.r0 + inner.height <= outer.r0 + outer.height
}

/// Raycast `p` from `camera` (in the level-0 terrain frame) with `opts`,
/// whose bands are replaced by [`level_bands`]; the frame and the levels
/// it read, nearest first.
pub fn render(
    p: &Pyramid,
    camera: &Camera,
    opts: &RenderOptions,
    levels: LevelOptions,
) -> Result<(RaycastFrame, Vec<LevelRead>)> {
    let mut raycaster = Raycaster::default();
    let read = render_with(
        &mut raycaster,
        &mut LevelWindows::default(),
        p,
        camera,
        opts,
        levels,
    )?;
    Ok((raycaster.into_frame(), read))
}

/// [`render`] into `raycaster`'s frame, its buffers and the level windows
/// in `windows` reused from one frame to the next (as the viewer does);
/// the levels read this frame, nearest first.
pub fn render_with(
    raycaster: &mut Raycaster,
    windows: &mut LevelWindows,
    p: &Pyramid,
    camera: &Camera,
    opts: &RenderOptions,
    levels: LevelOptions,
) -> Result<Vec<LevelRead>> {
    if !(levels.max_cell_px.is_finite() && levels.max_cell_px > 0.0) {
        return Err(crate::Error::Input(format!(
            "the largest cell on screen must be a positive number of pixels, got {}",
            levels.max_cell_px
        )));
    }
    let opts = RenderOptions {
        bands: level_bands(p, camera, levels.max_cell_px),
        ..opts.clone()
    };
    let g = &p.manifest.grid;
    let [lowest, highest] = g.height_range_m.map(f64::from);
    let extent = GridExtent {
        side: g.side,
        cell_m: g.cell_size_m,
        lowest_m: lowest,
        highest_m: highest,
    };
    if windows.hillshade != levels.hillshade {
        *windows = LevelWindows {
            hillshade: levels.hillshade,
            ..LevelWindows::default()
        };
    }
    let read = Mutex::new(Vec::new());
    let load = |level: u32, ground: [f64; 4]| {
        let (terrain, window) = windows.level(p, level, ground, levels.hillshade)?;
        if let Some(window) = window {
            read.lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(window);
        }
        Ok(terrain)
    };
    raycaster.render_levels(
        &Levels {
            extent,
            load: &load,
        },
        camera,
        &opts,
    )?;
    let mut read = read.into_inner().unwrap_or_else(PoisonError::into_inner);
    read.sort_by_key(|r| r.level);
    Ok(read)
}

/// Level `level`'s lattice window under the ground box `[x0, y0, x1, y1]`
/// (level-0 terrain frame, metres) grown by `margin` of its width and
/// height on each side, clamped to the level.
fn lattice_rect(p: &Pyramid, level: u32, [x0, y0, x1, y1]: [f64; 4], margin: f64) -> Rect {
    let (side, cell) = (p.layout.side, p.manifest.grid.cell_size_m);
    let s = p.layout.stride(level) as f64;
    let last = ((side - 1) as f64 / s).floor();
    let grow_x = margin * (x1 - x0).max(0.0);
    let grow_y = margin * (y1 - y0).max(0.0);
    let (x0, x1, y0, y1) = (x0 - grow_x, x1 + grow_x, y0 - grow_y, y1 + grow_y);
    // Lattice columns and rows under the box (rows grow southwards).
    let lattice = |v: f64| (v / s).clamp(0.0, last);
    let (u0, u1) = (lattice(x0 / cell).floor(), lattice(x1 / cell).ceil());
    let top = (side - 1) as f64 - y1 / cell;
    let bottom = (side - 1) as f64 - y0 / cell;
    let (v0, v1) = (lattice(top).floor(), lattice(bottom).ceil());
    let (u0, v0) = (u0 as usize, v0 as usize);
    Rect {
        c0: u0,
        r0: v0,
        width: u1 as usize - u0 + 1,
        height: v1 as usize - v0 + 1,
    }
}

/// The hillshade of level `level`'s lattice window `rect` under a sun at
/// `[azimuth, elevation]` degrees, laid out as its `square`² terrain: each
/// normal from the level's lattice around the vertex, read one vertex past
/// the window, so a vertex is shaded alike whichever window holds it.
fn window_shade(
    p: &Pyramid,
    level: u32,
    rect: Rect,
    square: usize,
    [azimuth, elevation]: [f64; 2],
) -> Result<Vec<f32>> {
    let s = p.layout.stride(level);
    let lattice_side = (p.layout.side - 1) / s + 1;
    let c0 = rect.c0.saturating_sub(1);
    let r0 = rect.r0.saturating_sub(1);
    let ring = Rect {
        c0,
        r0,
        width: (rect.c0 + rect.width + 1).min(lattice_side) - c0,
        height: (rect.r0 + rect.height + 1).min(lattice_side) - r0,
    };
    let (heights, _) = p.lattice_heights(level, ring)?;
    let z = |c: usize, r: usize| heights[(r - ring.r0) * ring.width + c - ring.c0];
    let cell = p.manifest.grid.cell_size_m * s as f64;
    let mut shade = vec![1.0f32; square * square];
    for r in 0..rect.height {
        for c in 0..rect.width {
            let n = vertex_normal_of(&z, lattice_side, cell, rect.c0 + c, rect.r0 + r);
            shade[r * square + c] = hillshade(n, azimuth, elevation);
        }
    }
    Ok(shade)
}

/// Level `level`'s lattice window `rect` as a square terrain with its
/// drape, and where its frame lies in the level-0 frame; with the window
/// read.
fn load_level(
    p: &Pyramid,
    level: u32,
    rect: Rect,
    hillshade: Option<[f64; 2]>,
) -> Result<(LevelTerrain, LevelRead)> {
    let (side, cell) = (p.layout.side, p.manifest.grid.cell_size_m);
    let s = p.layout.stride(level);
    let (u0, v0, w, h) = (rect.c0, rect.r0, rect.width, rect.height);
    // The raycaster's terrains are square: the rest is no data.
    let square = w.max(h).max(2);
    Terrain::check_size(square, (w * h) as u64)?;
    let (window_heights, window_mask) = p.lattice_heights(level, rect)?;
    let (rgba, geotransform) = p.lattice_drape(level, rect)?;
    p.release_pages();
    let mut heights = vec![0.0f32; square * square];
    let mut mask = vec![0u8; square * square];
    for r in 0..h {
        heights[r * square..r * square + w].copy_from_slice(&window_heights[r * w..(r + 1) * w]);
        mask[r * square..r * square + w].copy_from_slice(&window_mask[r * w..(r + 1) * w]);
    }
    let level_cell = cell * s as f64;
    let frame = TerrainFrame {
        side: square,
        cell_size_m: level_cell,
        geotransform,
    };
    let color = ColorSource::new(&rgba, w, h, &geotransform, &frame);
    let mut terrain = Terrain::new(square, level_cell, heights, mask, color);
    if let Some([azimuth, elevation]) = hillshade {
        terrain = terrain.with_shade(window_shade(p, level, rect, square, [azimuth, elevation])?);
    }
    // The terrain's origin, its south-west vertex, is level-0 vertex
    // (u0·s, (v0 + square − 1)·s).
    let offset_m = [
        (u0 * s) as f64 * cell,
        ((side - 1) as f64 - ((v0 + square - 1) * s) as f64) * cell,
    ];
    let read = LevelRead {
        level,
        width: w,
        height: h,
    };
    Ok((LevelTerrain { terrain, offset_m }, read))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lp::refine::tests::terrains;
    use crate::pyramid::paging::tests::pyramid_of;
    use glam::DVec3;

    /// A flight low over two crops, forward and turning, four bands deep
    /// (`max_cell_px` 16), with a baked hillshade: the level windows kept
    /// from frame to frame give the frames that windows read afresh give,
    /// pixel for pixel and depth for depth, and read under half as many
    /// windows.
    #[test]
    fn kept_level_windows_raycast_as_fresh_ones() {
        let levels = LevelOptions {
            max_cell_px: 16.0,
            hillshade: Some([315.0, 45.0]),
        };
        for t in terrains().into_iter().take(2) {
            let (_dir, p) = pyramid_of(&t, 32);
            let extent = (t.h.side - 1) as f64 * t.h.cell_size_m;
            let top = t.heights.iter().cloned().fold(f32::MIN, f32::max) as f64;
            let (mut kept, mut raycaster) = (LevelWindows::default(), Raycaster::default());
            let (mut kept_reads, mut fresh_reads) = (0, 0);
            for frame in 0..24 {
                let f = frame as f64;
                let camera = Camera {
                    position: DVec3::new(
                        0.1 * extent + f * 0.01 * extent,
                        0.2 * extent,
                        top + 20.0,
                    ),
                    heading_deg: 30.0 + 1.5 * f,
                    pitch_deg: -10.0,
                    incl_px: 90.0,
                    fov_x_deg: 60.0,
                    width: 320,
                    height: 180,
                    near_m: 1.0,
                    far_m: extent * 3.0,
                };
                let opts = RenderOptions::default();
                let read =
                    render_with(&mut raycaster, &mut kept, &p, &camera, &opts, levels).unwrap();
                kept_reads += read.len();
                let (fresh, read) = render(&p, &camera, &opts, levels).unwrap();
                fresh_reads += read.len();
                assert!(
                    read.len() >= 3,
                    "{}: the flight sees {} levels",
                    t.name,
                    read.len()
                );
                let got = raycaster.frame();
                assert!(
                    got.rgba == fresh.rgba && got.depth == fresh.depth,
                    "{} frame {frame}: kept windows raycast differently",
                    t.name
                );
            }
            assert!(
                2 * kept_reads < fresh_reads,
                "{}: kept windows read {kept_reads} windows, fresh ones {fresh_reads}",
                t.name
            );
        }
    }
}
