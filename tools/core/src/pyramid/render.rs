//! A pyramid raycast: the floating-horizon renderer's distance bands
//! (seed 000 §6.3) are the pyramid's levels. Band l reads level l, whose
//! cells are 2^l level-0 cells, from where such a cell shrinks to
//! `max_cell_px` pixels on screen; each band loads only its level's
//! lattice under the ground its slices reach. Nothing the size of the
//! region is held: a frame holds a few windows of about the same number
//! of vertices, one a level. [`LevelWindows`] keeps them for the next
//! frame and reads the next ones ahead, beside the frames, as the camera
//! moves toward their edges.

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
use std::sync::mpsc::{sync_channel, Receiver, TryRecvError};
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

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
/// next and read ahead. A band whose ground lies inside the window its
/// level holds reads nothing; once its ground has moved a quarter of the
/// margin toward the window's edge, the window around it grown by
/// [`WINDOW_MARGIN`] of its size on each side (clamped to the level) is
/// read on the windows' own thread pool while frames go on with the one
/// held, and replaces it once it has arrived. A frame waits only when its
/// band has left the window held before the next one arrived (a jump, or
/// the first frame). The raycast is
/// the same whichever window a level comes from: a sample reads its
/// lattice vertices' heights, mask and colour, and a baked hillshade's
/// normals look past the window's edge (where a level's cell is under a
/// pixel, beyond the last band's reach, the drape's averaged colour levels
/// follow the window's origin).
pub struct LevelWindows {
    pyramid: Arc<Pyramid>,
    /// The hillshade the windows are baked with.
    hillshade: Option<[f64; 2]>,
    /// Per level, the window held and the one being read ahead.
    levels: Mutex<Vec<LevelSlot>>,
    reads: Mutex<WindowReads>,
    /// The threads windows are read ahead on, made at the first read
    /// ahead (`None` when they could not be made). Never the frames' pool:
    /// a frame's worker waiting for a window would otherwise hold up the
    /// read it waits for (rayon may run the read's parallel work beneath
    /// that very wait on the worker's stack).
    readers: OnceLock<Option<rayon::ThreadPool>>,
}

/// How a raycast's level windows were read, since the windows were made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WindowReads {
    /// Windows a frame waited for.
    pub waited: u64,
    /// Windows read ahead, beside the frames.
    pub ahead: u64,
}

/// A level's window held, and the one being read ahead.
#[derive(Default)]
struct LevelSlot {
    held: Option<HeldWindow>,
    ahead: Option<ReadAhead>,
}

/// A level's lattice window and its terrain.
struct HeldWindow {
    rect: Rect,
    terrain: Arc<LevelTerrain>,
}

/// A window being read ahead.
struct ReadAhead {
    rect: Rect,
    arrived: Receiver<Result<(LevelTerrain, LevelRead)>>,
}

/// How much larger than a band's ground a level window is read, as a
/// fraction of the ground's width and height on each side.
pub const WINDOW_MARGIN: f64 = 0.25;

impl LevelWindows {
    /// No windows yet of `pyramid`'s levels.
    pub fn new(pyramid: Arc<Pyramid>) -> LevelWindows {
        LevelWindows {
            pyramid,
            hillshade: None,
            levels: Mutex::default(),
            reads: Mutex::default(),
            readers: OnceLock::new(),
        }
    }

    /// The pyramid the windows are read from.
    pub fn pyramid(&self) -> &Pyramid {
        &self.pyramid
    }

    /// How the windows were read so far.
    pub fn reads(&self) -> WindowReads {
        *self.reads.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Bake `hillshade` into the windows from now on (those held are
    /// dropped when it changes).
    fn set_hillshade(&mut self, hillshade: Option<[f64; 2]>) {
        if self.hillshade != hillshade {
            self.hillshade = hillshade;
            self.levels = Mutex::default();
        }
    }

    /// Level `level` over the ground box `[x0, y0, x1, y1]` (level-0
    /// terrain frame, metres): the window held when it covers the box, else
    /// one read now; with the window the frame waited for (`None` when it
    /// did not wait).
    fn level(
        &self,
        level: u32,
        ground: [f64; 4],
    ) -> Result<(Arc<LevelTerrain>, Option<LevelRead>)> {
        let p = &*self.pyramid;
        let wanted = lattice_rect(p, level, ground, 0.0);
        let grown = || lattice_rect(p, level, ground, WINDOW_MARGIN);
        let l = level as usize;
        let pending = {
            let mut levels = self.levels.lock().unwrap_or_else(PoisonError::into_inner);
            if levels.len() <= l {
                levels.resize_with(l + 1, LevelSlot::default);
            }
            let slot = &mut levels[l];
            slot.take_arrived(&wanted);
            if let Some(held) = slot.held.as_ref().filter(|w| contains(&w.rect, &wanted)) {
                let terrain = held.terrain.clone();
                if slot.ahead.is_none() && !contains(&inset(&held.rect), &wanted) {
                    slot.ahead = Some(self.read_ahead(level, grown()));
                }
                return Ok((terrain, None));
            }
            // Nothing held covers the band: this frame waits, for the
            // window under way if it will cover the band.
            slot.ahead.take().filter(|a| contains(&a.rect, &wanted))
        };
        // The read runs on `readers`, which need nothing from this thread.
        let (rect, (terrain, read)) =
            match pending.and_then(|a| Some((a.rect, a.arrived.recv().ok()?))) {
                Some((rect, arrived)) => (rect, arrived?),
                None => {
                    let rect = grown();
                    (rect, load_level(p, level, rect, self.hillshade)?)
                }
            };
        let terrain = Arc::new(terrain);
        self.reads
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .waited += 1;
        let mut levels = self.levels.lock().unwrap_or_else(PoisonError::into_inner);
        levels[l].held = Some(HeldWindow {
            rect,
            terrain: terrain.clone(),
        });
        Ok((terrain, Some(read)))
    }

    /// Start reading level `level`'s window `rect` on the readers' pool.
    /// Should the pool not start, the window never arrives and a frame that
    /// needs it reads it itself.
    fn read_ahead(&self, level: u32, rect: Rect) -> ReadAhead {
        let (send, arrived) = sync_channel(1);
        let (pyramid, hillshade) = (self.pyramid.clone(), self.hillshade);
        let readers = self.readers.get_or_init(|| {
            rayon::ThreadPoolBuilder::new()
                .thread_name(|i| format!("relevo level window {i}"))
                .build()
                .ok()
        });
        if let Some(readers) = readers {
            readers.spawn(move || {
                let _ = send.send(load_level(&pyramid, level, rect, hillshade));
            });
        }
        self.reads
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .ahead += 1;
        ReadAhead { rect, arrived }
    }
}

impl LevelSlot {
    /// A window read ahead that has arrived replaces the one held, when it
    /// covers `wanted` (one that failed is dropped: a frame that needs the
    /// window reads it itself and reports why it cannot).
    fn take_arrived(&mut self, wanted: &Rect) {
        let Some(ahead) = &self.ahead else { return };
        match ahead.arrived.try_recv() {
            Err(TryRecvError::Empty) => {}
            Ok(Ok((terrain, _))) if contains(&ahead.rect, wanted) => {
                self.held = Some(HeldWindow {
                    rect: ahead.rect,
                    terrain: Arc::new(terrain),
                });
                self.ahead = None;
            }
            Ok(_) | Err(TryRecvError::Disconnected) => self.ahead = None,
        }
    }
}

/// `rect` less three quarters of the margin a grown window has on each
/// side: a band whose ground leaves it starts the next window's read.
fn inset(rect: &Rect) -> Rect {
    let fraction = WINDOW_MARGIN / (1.0 + 2.0 * WINDOW_MARGIN) * 0.75;
    let (dc, dr) = (
        (rect.width as f64 * fraction) as usize,
        (rect.height as f64 * fraction) as usize,
    );
    Rect {
        c0: rect.c0 + dc,
        r0: rect.r0 + dr,
        width: rect.width.saturating_sub(2 * dc),
        height: rect.height.saturating_sub(2 * dr),
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
    p: &Arc<Pyramid>,
    camera: &Camera,
    opts: &RenderOptions,
    levels: LevelOptions,
) -> Result<(RaycastFrame, Vec<LevelRead>)> {
    let mut raycaster = Raycaster::default();
    let mut windows = LevelWindows::new(p.clone());
    let read = render_with(&mut raycaster, &mut windows, camera, opts, levels)?;
    Ok((raycaster.into_frame(), read))
}

/// [`render`] of the pyramid of `windows` into `raycaster`'s frame, its
/// buffers and the level windows reused from one frame to the next (as
/// the viewer does); the level windows this frame waited for, nearest
/// first.
pub fn render_with(
    raycaster: &mut Raycaster,
    windows: &mut LevelWindows,
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
    windows.set_hillshade(levels.hillshade);
    let windows = &*windows;
    let p = windows.pyramid();
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
    let read = Mutex::new(Vec::new());
    let load = |level: u32, ground: [f64; 4]| {
        let (terrain, window) = windows.level(level, ground)?;
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
    use std::sync::{Barrier, Condvar};
    use std::time::Duration;

    /// A window read ahead arrives while every worker of rayon's global
    /// pool, on which frames raycast, is blocked waiting: the read needs
    /// none of them. (Read on the frames' pool, its parallel work could
    /// land beneath a frame's wait for it on a worker's stack, and the
    /// flight hung.)
    #[test]
    fn a_window_read_ahead_arrives_while_every_frame_worker_waits() {
        let t = terrains().into_iter().next().unwrap();
        let (_dir, p) = pyramid_of(&t, 32);
        let windows = LevelWindows::new(Arc::new(p));
        let rect = Rect {
            c0: 0,
            r0: 0,
            width: t.h.side,
            height: t.h.side / 2,
        };
        let workers = rayon::current_num_threads();
        let all_blocked = Barrier::new(workers + 1);
        let (give, take) = std::sync::mpsc::channel::<ReadAhead>();
        let take = Mutex::new(take);
        let arrived = (Mutex::new(None::<bool>), Condvar::new());
        std::thread::scope(|s| {
            let frames = s.spawn(|| {
                rayon::broadcast(|worker| {
                    all_blocked.wait();
                    if worker.index() == 0 {
                        let ahead = take.lock().unwrap().recv().unwrap();
                        let window = ahead.arrived.recv_timeout(Duration::from_secs(60));
                        *arrived.0.lock().unwrap() = Some(matches!(window, Ok(Ok(_))));
                        arrived.1.notify_all();
                    } else {
                        let mut got = arrived.0.lock().unwrap();
                        while got.is_none() {
                            got = arrived.1.wait(got).unwrap();
                        }
                    }
                })
            });
            all_blocked.wait();
            give.send(windows.read_ahead(0, rect)).unwrap();
            frames.join().unwrap();
        });
        assert_eq!(
            *arrived.0.lock().unwrap(),
            Some(true),
            "the window read ahead did not arrive within a minute"
        );
    }

    /// A flight low over two crops, forward and turning, four bands deep
    /// (`max_cell_px` 16), with a baked hillshade: the level windows kept
    /// from frame to frame (and read ahead beside them) give the frames
    /// that windows read afresh give, pixel for pixel and depth for depth,
    /// whenever the windows read ahead arrive; the frames wait for under
    /// half as many windows.
    #[test]
    fn kept_level_windows_raycast_as_fresh_ones() {
        let levels = LevelOptions {
            max_cell_px: 16.0,
            hillshade: Some([315.0, 45.0]),
        };
        for t in terrains().into_iter().take(2) {
            let (_dir, p) = pyramid_of(&t, 32);
            let p = Arc::new(p);
            let extent = (t.h.side - 1) as f64 * t.h.cell_size_m;
            let top = t.heights.iter().cloned().fold(f32::MIN, f32::max) as f64;
            let mut kept = LevelWindows::new(p.clone());
            let mut raycaster = Raycaster::default();
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
                let read = render_with(&mut raycaster, &mut kept, &camera, &opts, levels).unwrap();
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
            let reads = kept.reads();
            assert_eq!(reads.waited, kept_reads as u64, "{}", t.name);
            assert!(reads.ahead > 0, "{}: nothing read ahead", t.name);
            assert!(
                2 * kept_reads < fresh_reads,
                "{}: frames waited for {kept_reads} kept windows, for {fresh_reads} fresh ones",
                t.name
            );
        }
    }
}
