//! The viewer's vegetation on the GPU found (lavapipe without one), at
//! 1280×720 in mesh mode (τ = 2 px): the analogues of the vegetation
//! thesis's tables 4.1–4.5 on the sample region's real detections, beside
//! the seed's figures, and frame time against the number of objects (1k to
//! 1M) for the plain list, blobs and the quadtree cut. A frame is timed
//! from the start of its CPU work until the GPU has finished it.

use crate::measure::{emit, median};
use anyhow::{Context, Result};
use glam::DVec3;
use relevo::prep::prep;
use relevo::prep::region::RegionSpec;
use relevo_core::bundle::{format_of, names, Bundle, BundleFiles, BundleLock, PYRAMID_FORMAT};
use relevo_core::camera::Camera;
use relevo_core::cluster::bake::BakeOptions;
use relevo_core::cluster::cut::CutOptions;
use relevo_core::cluster::stage::bake_database;
use relevo_core::cluster::store::{self, rewrite_bundle, NewVegetation};
use relevo_core::geo::TerrainFrame;
use relevo_core::pyramid::{self, ground::TiledGround, Pyramid};
use relevo_core::veg::db::VegObject;
use relevo_view::gpu::{Device, FrameStats, Queue, Renderer};
use relevo_view::headless::{device, wait_for_gpu};
use relevo_view::scene::Scene;
use relevo_view::settings::{Settings, TerrainMode, VegetationSelection};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

const SIZE: [u32; 2] = [1280, 720];

/// Seed table 4.1, SJD-Vis3D columns: fps of billboards and sprites for
/// 100–1000 objects (GeForce FX5200).
const SEED_4_1: [(usize, f64, f64); 10] = [
    (100, 50.0, 33.3),
    (200, 39.8, 25.0),
    (300, 28.6, 20.7),
    (400, 25.0, 14.3),
    (500, 20.0, 11.8),
    (600, 18.7, 10.5),
    (700, 16.7, 9.5),
    (800, 14.3, 8.0),
    (900, 13.3, 7.4),
    (1000, 12.1, 6.7),
];

/// Seed table 4.2: fps without and with object culling, and objects
/// discarded, at ten points of a flight over 1000 objects.
const SEED_4_2: [(f64, f64, usize); 10] = [
    (26.9, 27.5, 15),
    (26.8, 31.9, 232),
    (27.3, 34.7, 314),
    (27.5, 38.7, 415),
    (28.1, 44.9, 521),
    (28.9, 53.5, 621),
    (29.2, 61.7, 708),
    (30.3, 81.5, 806),
    (31.0, 117.3, 900),
    (32.0, 156.7, 943),
];

/// Seed table 4.3: fps by billboard texture size 32², 64², 128², 256².
const SEED_4_3: [(usize, [f64; 4]); 4] = [
    (100, [80.8, 66.5, 45.0, 11.2]),
    (200, [71.3, 57.5, 31.2, 5.8]),
    (300, [62.3, 48.6, 23.3, 4.3]),
    (400, [55.6, 40.2, 19.2, 3.1]),
];

/// Seed table 4.4: fps of the list, blobs and quadtree configurations 1–3.
const SEED_4_4: [(usize, [f64; 5]); 10] = [
    (100, [85.9, 84.6, 98.8, 90.3, 90.9]),
    (200, [69.3, 68.9, 92.7, 75.9, 71.8]),
    (300, [58.5, 58.5, 87.3, 67.6, 62.9]),
    (400, [50.7, 50.5, 77.1, 60.9, 54.8]),
    (500, [45.0, 44.6, 71.3, 55.7, 45.1]),
    (600, [39.9, 40.0, 68.9, 49.4, 40.2]),
    (700, [36.2, 36.2, 67.0, 45.0, 37.2]),
    (800, [33.0, 33.0, 63.1, 40.0, 35.0]),
    (900, [30.3, 30.4, 62.9, 36.9, 32.2]),
    (1000, [27.9, 28.3, 62.8, 33.0, 30.8]),
];

/// Seed table 4.5: configuration, fps, billboards drawn, objects
/// represented, for its eight views of Itaoca and Macaé.
const SEED_4_5: [(u8, f64, usize, usize); 8] = [
    (1, 25.0, 486, 2050),
    (1, 18.2, 1660, 6762),
    (2, 22.2, 817, 2010),
    (2, 12.5, 3721, 9277),
    (2, 10.5, 5726, 14219),
    (2, 11.1, 4139, 10385),
    (3, 5.9, 10056, 17012),
    (3, 10.5, 4690, 7715),
];

/// A camera at `position` (terrain frame, metres) looking along
/// `heading_deg`, `pitch_deg` above the horizon, with a horizontal field of
/// view of `fov_x_deg`, at the benchmark's size.
fn camera(position: DVec3, heading_deg: f64, pitch_deg: f64, fov_x_deg: f64) -> Camera {
    Camera {
        position,
        heading_deg,
        pitch_deg,
        incl_px: SIZE[1] as f64 / 2.0,
        fov_x_deg,
        width: SIZE[0],
        height: SIZE[1],
        near_m: 1.0,
        far_m: 100_000.0,
    }
}

/// The GPU, the sample region's bundle (rewritten with each test's
/// vegetation) and its real detections.
struct Bench {
    device: Device,
    queue: Queue,
    bundle: PathBuf,
    frame: TerrainFrame,
    /// The colour image's extent on the terrain (lowest and highest
    /// terrain coordinates, metres): where objects may stand.
    drape_area: [[f64; 2]; 2],
    database: Vec<VegObject>,
    runs: usize,
    json: bool,
}

pub fn run(repo: &Path, runs: usize, max_objects: usize, json: bool) -> Result<()> {
    let scratch = crate::measure::tempfile_dir()?;
    let (device, queue, adapter) = device()?;
    emit(
        json,
        json!({"bench": "view-adapter", "adapter": adapter}),
        format!("adapter: {adapter}"),
    );
    let bundle = scratch.join("olinda.relevo");
    prep(
        &RegionSpec::load(&repo.join("data/olinda/REGION.toml"))?,
        &bundle,
        true,
    )?;
    let opened = Bundle::open(&bundle)?;
    let frame = opened.frame();
    let drape_area = drape_area(&opened)?;
    let database = opened
        .vegetation()?
        .context("the sample region has no vegetation")?;
    drop(opened);
    let bench = Bench {
        device,
        queue,
        bundle,
        frame,
        drape_area,
        database,
        runs,
        json,
    };
    bench.billboards_sprites_and_structures()?;
    bench.culling_along_a_flight()?;
    bench.texture_sizes()?;
    bench.large_scenes()?;
    bench.object_counts(max_objects)?;
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// The extent of `bundle`'s colour image on its terrain (lowest and highest
/// terrain coordinates, metres, half a metre inside, clear of the
/// database's rounding): where its objects may stand.
fn drape_area(bundle: &Bundle) -> Result<[[f64; 2]; 2]> {
    let frame = bundle.frame();
    let colour = bundle
        .manifest
        .color
        .as_ref()
        .context("the bundle has no colour image")?;
    terrain_area(
        &frame,
        colour.geotransform.bounds(colour.width, colour.height),
    )
    .context("the colour image lies off the terrain")
}

/// World bounds `[x0, y0, x1, y1]` on `frame`'s terrain, half a metre
/// inside; `None` when a corner lies off it.
fn terrain_area(frame: &TerrainFrame, [x0, y0, x1, y1]: [f64; 4]) -> Option<[[f64; 2]; 2]> {
    let a = frame.terrain_from_world(x0, y0)?;
    let b = frame.terrain_from_world(x1, y1)?;
    Some([
        [a.0.min(b.0) + 0.5, a.1.min(b.1) + 0.5],
        [a.0.max(b.0) - 0.5, a.1.max(b.1) - 0.5],
    ])
}

/// Rewrite the bundle at `path` with `objects` (numbered afresh, as a
/// database's ids are) baked with `options`.
fn rewrite_vegetation(path: &Path, objects: &[VegObject], options: &BakeOptions) -> Result<()> {
    let numbered = numbered(objects);
    let lock = BundleLock::acquire(path)?;
    let bundle = Bundle::open(path)?;
    let new = NewVegetation {
        database: Some(&numbered),
        samples_csv: None,
    };
    rewrite_bundle(
        lock,
        &bundle,
        &new,
        &Default::default(),
        options,
        &|_, _| {},
    )?;
    Ok(())
}

/// `objects` numbered afresh from 1, as a database's ids are.
fn numbered(objects: &[VegObject]) -> Vec<VegObject> {
    objects
        .iter()
        .enumerate()
        .map(|(k, o)| VegObject {
            id: k as u64 + 1,
            ..o.clone()
        })
        .collect()
}

/// Rewrite the bundle at `path` with `count` objects tiled from its own
/// detections over its colour image, default bake: the dense scenes of
/// [`Bench::object_counts`], for `relevo-view bench`. A pyramid's objects
/// are tiled over its data's extent and stand on its tiles.
pub fn densify(path: &Path, count: usize) -> Result<()> {
    if format_of(path).as_deref() == Some(PYRAMID_FORMAT) {
        return densify_pyramid(path, count);
    }
    let bundle = Bundle::open(path)?;
    let frame = bundle.frame();
    let area = drape_area(&bundle)?;
    let database = bundle
        .vegetation()?
        .context("the bundle has no vegetation")?;
    drop(bundle);
    let objects = crate::clusters::tiled_detections(&database, &frame, &frame, area, count);
    rewrite_vegetation(path, &objects, &BakeOptions::default())
}

/// [`densify`] of the pyramid at `path`: its database and clusters
/// replaced in place (`pyramid::rewrite`), the clusters baked on its tiles.
fn densify_pyramid(path: &Path, count: usize) -> Result<()> {
    let lock = BundleLock::acquire(path)?;
    let p = Pyramid::open(path)?;
    let frame = p.frame();
    let database = p.vegetation()?.context("the pyramid has no vegetation")?;
    let area = terrain_area(&frame, p.manifest.grid.valid_extent)
        .context("the pyramid's data lies off its terrain")?;
    let objects = crate::clusters::tiled_detections(&database, &frame, &frame, area, count);
    let objects = numbered(&objects);
    let options = BakeOptions::default();
    let ground = TiledGround::new(&p, p.layout, p.manifest.grid.cell_size_m);
    let (clusters, off_terrain) = bake_database(
        &objects,
        &frame,
        &ground,
        &Default::default(),
        &options,
        &|_, _| {},
    )?;
    let replaced = |key: &str| key == names::VEGETATION.key || store::is_cluster_artifact(key);
    pyramid::rewrite(
        lock,
        &p,
        &replaced,
        |files| {
            files.write_vegetation(&objects)?;
            store::write(files, &clusters, &options, off_terrain)
        },
        &|staged| store::validate(staged),
    )?;
    Ok(())
}

impl Bench {
    /// Rewrite the bundle with `objects` baked with `options`, and open it.
    fn scene(&self, objects: &[VegObject], options: &BakeOptions) -> Result<Scene> {
        rewrite_vegetation(&self.bundle, objects, options)?;
        Scene::open(&self.bundle)
    }

    /// Every k-th real detection, `count` of them.
    fn every_kth(&self, count: usize) -> Vec<VegObject> {
        let step = (self.database.len() / count).max(1);
        self.database
            .iter()
            .step_by(step)
            .take(count)
            .cloned()
            .collect()
    }

    /// Median frame time over `cameras`, `runs` rounds after a warm-up
    /// round, and the figures of each camera's last frame.
    fn time(
        &self,
        scene: &mut Scene,
        cameras: &[Camera],
        settings: &Settings,
    ) -> Result<(f64, Vec<FrameStats>)> {
        let mut renderer = Renderer::new(&self.device, &self.queue, scene, SIZE);
        let (mut times, mut stats) = (Vec::new(), vec![FrameStats::default(); cameras.len()]);
        for round in 0..=self.runs {
            for (camera, stats) in cameras.iter().zip(&mut stats) {
                // A frame differs from the last: the renderer would skip it.
                renderer.forget_last_frame();
                let start = Instant::now();
                *stats = renderer.render(&self.device, &self.queue, scene, camera, settings)?;
                wait_for_gpu(&self.device)?;
                if round > 0 {
                    times.push(start.elapsed().as_secs_f64() * 1e3);
                }
            }
        }
        Ok((median(&times), stats))
    }

    /// Tables 4.1 and 4.4 under the seed's conditions for 4.4: 100–1000
    /// detections (every k-th), one camera 3 km south of the region and
    /// 4 km up, looking north 35° down with a 100° field of view, so that
    /// every object is in view; 64-texel views; d₃ beyond the diagonal.
    /// 4.1 draws the plain list without alpha or blur (as the seed did);
    /// 4.4 the list, blobs of 3 km and configurations 1–3, with both.
    fn billboards_sprites_and_structures(&self) -> Result<()> {
        let frame = &self.frame;
        let side_m = (frame.side - 1) as f64 * frame.cell_size_m;
        let camera = camera(
            DVec3::new(side_m / 2.0, -3_000.0, 4_000.0),
            0.0,
            -35.0,
            100.0,
        );
        let diagonal = side_m * std::f64::consts::SQRT_2;
        for ((count, seed_billboard, seed_sprite), (_, seed_4_4)) in
            SEED_4_1.into_iter().zip(SEED_4_4)
        {
            let objects = self.every_kth(count);
            let mut fps_4_4 = Vec::new();
            let mut draws = Vec::new();
            for config in 1..=3u8 {
                let cut =
                    CutOptions::seed_configuration(config, diagonal).context("configuration")?;
                let options = BakeOptions {
                    cut,
                    class_frame_px: 64,
                    max_frame_px: 64,
                    ..BakeOptions::default()
                };
                let mut scene = self.scene(&objects, &options)?;
                let mut selections = vec![VegetationSelection::Quadtree];
                if config == 1 {
                    let plain = |sprites| Settings {
                        mode: TerrainMode::Mesh,
                        vegetation: VegetationSelection::List,
                        sprites,
                        alpha: false,
                        blur: false,
                        ..Default::default()
                    };
                    let (billboards, _) = self.time(&mut scene, &[camera], &plain(false))?;
                    let (sprites, _) = self.time(&mut scene, &[camera], &plain(true))?;
                    emit(
                        self.json,
                        json!({"bench": "view-vegetation-table-4.1", "objects": count,
                               "billboard_ms": billboards, "sprite_ms": sprites,
                               "billboard_fps": 1e3 / billboards, "sprite_fps": 1e3 / sprites,
                               "seed_fps": [seed_billboard, seed_sprite], "runs": self.runs}),
                        format!(
                            "table 4.1 | {count} | {:.1} ({seed_billboard}) | {:.1} ({seed_sprite})",
                            1e3 / billboards,
                            1e3 / sprites
                        ),
                    );
                    selections = vec![
                        VegetationSelection::List,
                        VegetationSelection::Blobs { side_m: 3_000.0 },
                        VegetationSelection::Quadtree,
                    ];
                }
                for vegetation in selections {
                    let settings = Settings {
                        mode: TerrainMode::Mesh,
                        vegetation,
                        ..Default::default()
                    };
                    let (ms, stats) = self.time(&mut scene, &[camera], &settings)?;
                    fps_4_4.push(1e3 / ms);
                    draws.push(stats[0].impostors);
                }
            }
            let cells: Vec<String> = (0..5)
                .map(|k| format!("{:.1} ({})", fps_4_4[k], seed_4_4[k]))
                .collect();
            emit(
                self.json,
                json!({"bench": "view-vegetation-table-4.4", "objects": count,
                       "fps": {"list": fps_4_4[0], "blobs": fps_4_4[1], "quadtree": &fps_4_4[2..]},
                       "draws": {"list": draws[0], "blobs": draws[1], "quadtree": &draws[2..]},
                       "seed_fps": seed_4_4, "runs": self.runs}),
                format!(
                    "table 4.4 | {count} | {} | draws {:?}",
                    cells.join(" | "),
                    draws
                ),
            );
        }
        Ok(())
    }

    /// Table 4.2: 1000 detections (every k-th); ten points on a flight
    /// due north across the region, 300 m above its highest point, 15°
    /// down; the plain list with object culling off and on.
    fn culling_along_a_flight(&self) -> Result<()> {
        let objects = self.every_kth(1000);
        let mut scene = self.scene(&objects, &BakeOptions::default())?;
        let side_m = scene.extent_m();
        let top = scene
            .terrain
            .heights()
            .iter()
            .copied()
            .fold(f32::MIN, f32::max) as f64;
        for (k, (seed_off, seed_on, seed_discarded)) in SEED_4_2.into_iter().enumerate() {
            let camera = camera(
                DVec3::new(side_m / 2.0, side_m * (k as f64 / 9.0 - 0.1), top + 300.0),
                0.0,
                -15.0,
                60.0,
            );
            let list = |culling| Settings {
                mode: TerrainMode::Mesh,
                vegetation: VegetationSelection::List,
                vegetation_culling: culling,
                ..Default::default()
            };
            let (off, all) = self.time(&mut scene, &[camera], &list(false))?;
            let (on, culled) = self.time(&mut scene, &[camera], &list(true))?;
            let discarded = all[0].impostors - culled[0].impostors;
            emit(
                self.json,
                json!({"bench": "view-vegetation-table-4.2", "point": k, "y_m": camera.position.y,
                       "without_culling_fps": 1e3 / off, "with_culling_fps": 1e3 / on,
                       "discarded": discarded, "seed": [seed_off, seed_on, seed_discarded as f64],
                       "runs": self.runs}),
                format!(
                    "table 4.2 | {k} | {:.1} ({seed_off}) | {:.1} ({seed_on}) | {discarded} ({seed_discarded})",
                    1e3 / off,
                    1e3 / on
                ),
            );
        }
        Ok(())
    }

    /// Table 4.3: the 100–400 detections nearest their centroid, seen from
    /// 150 m above the ground, back from the group by 1.2 times its radius
    /// plus 100 m, looking at it with a 90° field of view; with
    /// class views baked at 32² to 256²; plain list, alpha on, sampled
    /// without filtering (the full-size texture, as the seed) and with the
    /// mip-mapped filtering that picks the level by distance.
    fn texture_sizes(&self) -> Result<()> {
        // The detections' centroid, in the forest.
        let placed: Vec<[f64; 2]> = self
            .database
            .iter()
            .filter_map(|o| self.world_to_terrain(o.x, o.y).ok())
            .collect();
        let n = placed.len().max(1) as f64;
        let target = [
            placed.iter().map(|p| p[0]).sum::<f64>() / n,
            placed.iter().map(|p| p[1]).sum::<f64>() / n,
        ];
        let heading = 30f64.to_radians();
        for (count, seed) in SEED_4_3 {
            let mut nearest: Vec<(f64, VegObject)> = self
                .database
                .iter()
                .zip(&placed)
                .map(|(o, p)| ((p[0] - target[0]).hypot(p[1] - target[1]), o.clone()))
                .collect();
            nearest.sort_by(|a, b| a.0.total_cmp(&b.0));
            nearest.truncate(count);
            // Back from the group by its radius and a margin, looking at it.
            let back = 1.2 * nearest.last().map_or(0.0, |n| n.0) + 100.0;
            let objects: Vec<VegObject> = nearest.into_iter().map(|(_, o)| o).collect();
            let eye = [
                target[0] - back * heading.sin(),
                target[1] - back * heading.cos(),
            ];
            let mut cells = Vec::new();
            let mut record = Vec::new();
            for (k, texels) in [32u32, 64, 128, 256].into_iter().enumerate() {
                let options = BakeOptions {
                    class_frame_px: texels,
                    max_frame_px: texels,
                    ..BakeOptions::default()
                };
                let mut scene = self.scene(&objects, &options)?;
                let ground = scene.ground_height(eye[0], eye[1]).unwrap_or(0.0);
                let camera = camera(
                    DVec3::new(eye[0], eye[1], ground + 150.0),
                    30.0,
                    -(150f64.atan2(back).to_degrees()),
                    90.0,
                );
                let list = |blur| Settings {
                    mode: TerrainMode::Mesh,
                    vegetation: VegetationSelection::List,
                    blur,
                    ..Default::default()
                };
                let (sharp, stats) = self.time(&mut scene, &[camera], &list(false))?;
                let (filtered, _) = self.time(&mut scene, &[camera], &list(true))?;
                cells.push(format!(
                    "{:.1} / {:.1} ({})",
                    1e3 / sharp,
                    1e3 / filtered,
                    seed[k]
                ));
                record.push(json!({"texels": texels, "unfiltered_fps": 1e3 / sharp,
                                   "filtered_fps": 1e3 / filtered, "impostors": stats[0].impostors}));
            }
            emit(
                self.json,
                json!({"bench": "view-vegetation-table-4.3", "objects": count, "sizes": record,
                       "seed_fps": seed, "runs": self.runs}),
                format!("table 4.3 | {count} | {}", cells.join(" | ")),
            );
        }
        Ok(())
    }

    /// Table 4.5: all the sample region's detections under configurations
    /// 1–3 and the default bands, from four views (the HUD test's): fps,
    /// impostors drawn and objects represented.
    fn large_scenes(&self) -> Result<()> {
        let frame = &self.frame;
        let diagonal = (frame.side - 1) as f64 * frame.cell_size_m * std::f64::consts::SQRT_2;
        let views = [
            (292_000.0, 9_113_000.0, 30.0, 120.0),
            (290_000.0, 9_112_000.0, 70.0, 400.0),
            (294_500.0, 9_116_500.0, 210.0, 60.0),
            (291_000.0, 9_119_000.0, 150.0, 1500.0),
        ];
        for config in [1u8, 2, 3, 0] {
            let cut = match config {
                0 => CutOptions::default(),
                c => CutOptions::seed_configuration(c, diagonal).context("configuration")?,
            };
            let options = BakeOptions {
                cut,
                ..BakeOptions::default()
            };
            let mut scene = self.scene(&self.database, &options)?;
            for (view, &(east, north, heading, above)) in views.iter().enumerate() {
                let [x, y] = self.world_to_terrain(east, north)?;
                let ground = scene.ground_height(x, y).unwrap_or(0.0);
                let camera = camera(DVec3::new(x, y, ground + above), heading, -15.0, 60.0);
                let settings = Settings {
                    mode: TerrainMode::Mesh,
                    ..Default::default()
                };
                let (ms, stats) = self.time(&mut scene, &[camera], &settings)?;
                let name = if config == 0 {
                    "default bands".to_string()
                } else {
                    format!("configuration {config}")
                };
                emit(
                    self.json,
                    json!({"bench": "view-vegetation-table-4.5", "cut": name, "view": view,
                           "fps": 1e3 / ms, "impostors": stats[0].impostors,
                           "represented": stats[0].vegetation_represented, "runs": self.runs}),
                    format!(
                        "table 4.5 | {name} | view {view} | {:.1} fps | {} impostors | {} objects",
                        1e3 / ms,
                        stats[0].impostors,
                        stats[0].vegetation_represented
                    ),
                );
            }
        }
        let seed: Vec<String> = SEED_4_5
            .iter()
            .map(|(c, fps, drawn, represented)| {
                format!("config {c}: {fps} fps, {drawn}/{represented}")
            })
            .collect();
        emit(
            self.json,
            json!({"bench": "view-vegetation-table-4.5-seed", "rows": SEED_4_5.to_vec()}),
            format!("table 4.5, the seed's: {}", seed.join("; ")),
        );
        Ok(())
    }

    /// Frame time against the number of objects: the real detections tiled
    /// k×k over the sample region itself (1k to 1M: 0.1 to 8.5 times their
    /// own count per tile), default bake, the home view over eight
    /// headings; terrain alone, then the quadtree cut, blobs of 3 km and the
    /// plain list.
    fn object_counts(&self, max_objects: usize) -> Result<()> {
        let frame = &self.frame;
        for count in [1_000usize, 10_000, 100_000, 1_000_000]
            .into_iter()
            .filter(|&n| n <= max_objects)
        {
            let objects = crate::clusters::tiled_detections(
                &self.database,
                frame,
                frame,
                self.drape_area,
                count,
            );
            // At 100k, also with a 1 GiB atlas: what sharper clusters buy.
            let budgets: &[u64] = if count == 100_000 {
                &[256 << 20, 1 << 30]
            } else {
                &[256 << 20]
            };
            for &budget_bytes in budgets {
                self.count_row(&objects, budget_bytes)?;
            }
        }
        Ok(())
    }

    /// One row of [`Bench::object_counts`]: `objects` baked into an atlas
    /// of at most `budget_bytes`.
    fn count_row(&self, objects: &[VegObject], budget_bytes: u64) -> Result<()> {
        let count = objects.len();
        let options = BakeOptions {
            budget_bytes,
            ..BakeOptions::default()
        };
        let mut scene = self.scene(objects, &options)?;
        let home = relevo_view::flight::Flight::home(&scene);
        let cameras: Vec<Camera> = crate::view::HEADINGS
            .iter()
            .map(|&heading_deg| {
                relevo_view::flight::Flight {
                    heading_deg,
                    ..home
                }
                .camera(&scene, SIZE)
            })
            .collect();
        let terrain_only = Settings {
            mode: TerrainMode::Mesh,
            objects: false,
            ..Default::default()
        };
        let (terrain_ms, _) = self.time(&mut scene, &cameras, &terrain_only)?;
        for selection in [
            VegetationSelection::Quadtree,
            VegetationSelection::Blobs { side_m: 3000.0 },
            VegetationSelection::List,
        ] {
            let settings = Settings {
                mode: TerrainMode::Mesh,
                vegetation: selection,
                ..Default::default()
            };
            let (ms, stats) = self.time(&mut scene, &cameras, &settings)?;
            let middle =
                |f: fn(&FrameStats) -> f64| median(&stats.iter().map(f).collect::<Vec<f64>>());
            let impostors = middle(|s| s.impostors as f64);
            let represented = middle(|s| s.vegetation_represented as f64);
            let cut_ms = middle(|s| s.cut_ms);
            emit(
                    self.json,
                    json!({"bench": "view-vegetation", "objects": count, "budget_mib": budget_bytes >> 20,
                           "selection": selection.to_string(),
                           "frame_ms": ms, "fps": 1e3 / ms, "terrain_ms": terrain_ms,
                           "vegetation_ms": ms - terrain_ms, "impostors": impostors,
                           "represented": represented, "cut_ms": cut_ms, "runs": self.runs}),
                    format!(
                        "{count} objects ({} MiB atlas), {selection}: {ms:.1} ms ({:.0} fps; terrain alone {terrain_ms:.1} ms, vegetation {:.1} ms), {impostors} impostors for {represented} objects in view, selection {cut_ms:.2} ms",
                        budget_bytes >> 20,
                        1e3 / ms,
                        ms - terrain_ms
                    ),
                );
        }
        Ok(())
    }

    /// World (the bundle's CRS) to terrain frame, metres.
    fn world_to_terrain(&self, east: f64, north: f64) -> Result<[f64; 2]> {
        let (x, y) = self
            .frame
            .terrain_from_world(east, north)
            .context("the point lies off the sample region")?;
        Ok([x, y])
    }
}
