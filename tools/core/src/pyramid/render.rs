//! A pyramid raycast: the floating-horizon renderer's distance bands
//! (seed 000 §6.3) are the pyramid's levels. Band l reads level l, whose
//! cells are 2^l level-0 cells, from where such a cell shrinks to
//! `max_cell_px` pixels on screen; each band loads only its level's
//! lattice under the ground its slices reach. Nothing the size of the
//! region is held: a frame holds a few windows of about the same number
//! of vertices, one a level.

use super::reader::Pyramid;
use crate::camera::Camera;
use crate::geo::TerrainFrame;
use crate::horizon::{
    ColorSource, DistanceBand, GridExtent, LevelTerrain, Levels, RaycastFrame, Raycaster,
    RenderOptions, Terrain,
};
use crate::lp::window::Rect;
use crate::Result;

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
    let read = render_with(&mut raycaster, p, camera, opts, levels)?;
    Ok((raycaster.into_frame(), read))
}

/// [`render`] into `raycaster`'s frame (its buffers reused from one frame
/// to the next, as the viewer does); the levels read, nearest first.
pub fn render_with(
    raycaster: &mut Raycaster,
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
    let read = std::sync::Mutex::new(Vec::new());
    let load = |level: u32, ground: [f64; 4]| {
        let (terrain, window) = load_level(p, level, ground, levels.hillshade)?;
        if let Ok(mut read) = read.lock() {
            read.push(window);
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
    Ok(read.into_inner().unwrap_or_default())
}

/// Level `level` under the ground box `[x0, y0, x1, y1]` (level-0 terrain
/// frame, metres) as a square terrain with its drape, and where its frame
/// lies in the level-0 frame; with the window read.
fn load_level(
    p: &Pyramid,
    level: u32,
    [x0, y0, x1, y1]: [f64; 4],
    hillshade: Option<[f64; 2]>,
) -> Result<(LevelTerrain, LevelRead)> {
    let (side, cell) = (p.layout.side, p.manifest.grid.cell_size_m);
    let s = p.layout.stride(level);
    let last = ((side - 1) / s) as f64;
    // Lattice columns and rows under the box (rows grow southwards).
    let lattice = |v: f64| (v / s as f64).clamp(0.0, last);
    let (u0, u1) = (lattice(x0 / cell).floor(), lattice(x1 / cell).ceil());
    let top = (side - 1) as f64 - y1 / cell;
    let bottom = (side - 1) as f64 - y0 / cell;
    let (v0, v1) = (lattice(top).floor(), lattice(bottom).ceil());
    let (u0, v0) = (u0 as usize, v0 as usize);
    let (w, h) = (u1 as usize - u0 + 1, v1 as usize - v0 + 1);
    // The raycaster's terrains are square: the rest is no data.
    let square = w.max(h).max(2);
    Terrain::check_size(square, (w * h) as u64)?;
    let rect = Rect {
        c0: u0,
        r0: v0,
        width: w,
        height: h,
    };
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
        terrain = terrain.with_hillshade(azimuth, elevation);
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
