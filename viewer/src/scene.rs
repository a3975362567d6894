//! The bundle the viewer shows, opened once through relevo-core: its frame,
//! mapped heights and mask, the LP hierarchy over the mapped array, the
//! raycaster's terrain (owned for the session), the drape and the
//! vegetation clusters. A pyramid (`relevo prep --tiled`) is paged instead:
//! the mesh reads the tiles core's `PagedPyramid` loads in the background
//! for the camera, and the other renderers one coarser level of it that
//! fits in memory; its vegetation clusters are read as a single grid's and
//! stand on the mesh drawn through the tiles. Everything the viewer computes about terrain goes
//! through these core types.

use crate::settings::{Settings, VegetationSelection};
use anyhow::{Context, Result};
use relevo_core::bundle::{Array, Bundle, BundleFiles, GridInfo, LpArray, PYRAMID_FORMAT};
use relevo_core::camera::Camera;
use relevo_core::cluster::cut::{
    group_blobs, Blob, Blobs, CutOptions, DrawList, ObjectList, QuadtreeCut, Selection,
};
use relevo_core::cluster::{store, Clusters};
use relevo_core::geo::TerrainFrame;
use relevo_core::horizon::{self, Terrain};
use relevo_core::lp::refine::{mesh_height, Refiner, VertexSource};
use relevo_core::lp::window::Rect;
use relevo_core::objects::{read_placement, ObjectMesh};
use relevo_core::pyramid::paging::{Cut, PagedPyramid};
use relevo_core::pyramid::render::LevelWindows;
use relevo_core::pyramid::Pyramid;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Memory a pyramid's tile cache may hold, bytes (`--tile-cache`).
static TILE_CACHE_BYTES: AtomicU64 = AtomicU64::new(1 << 30);

/// Set the memory a pyramid's tile cache may hold (the tiles the camera
/// needs are kept even above it).
pub fn set_tile_cache(bytes: u64) {
    TILE_CACHE_BYTES.store(bytes, Ordering::Relaxed);
}

/// The largest side of the pyramid level other renderers than the mesh
/// read whole (the raycast, the baselines, ground heights): 2049² is
/// about 60 MB with its colour.
const OVERVIEW_SIDE: usize = 2049;

/// The drape image and the affine map from the terrain frame to its
/// texture coordinates (u right, v down, both 0..1).
pub struct DrapeImage {
    pub width: u32,
    pub height: u32,
    pub rgba: Array<u8>,
    /// u = a₀ + a₁x + a₂y, v = a₃ + a₄x + a₅y for terrain (x, y) in metres.
    pub terrain_to_uv: [f64; 6],
}

/// An opened bundle with the per-session state of both renderers.
pub struct Scene {
    pub path: PathBuf,
    /// The level-0 grid.
    pub grid: GridInfo,
    /// The frame of `terrain` (of a pyramid: its overview level's, whose
    /// terrain coordinates are level 0's).
    pub frame: TerrainFrame,
    /// A single grid's errors and radii (a pyramid's are in its tiles).
    pub lp: Option<LpArray>,
    /// A single grid's drape (a pyramid's is in its tiles).
    pub drape: Option<DrapeImage>,
    /// The heights and mask, read once, with the raycaster's colour
    /// pyramid: every renderer but a pyramid's mesh reads the grid from
    /// here (of a pyramid: the finest level of at most 2049² vertices).
    pub terrain: Terrain<'static>,
    /// A pyramid's tiles, paged for the mesh.
    pub paged: Option<PagedPyramid>,
    /// The cut of a pyramid's tiles the last mesh frame was refined
    /// through: what its vegetation stands on.
    pub mesh_cut: Option<Cut>,
    /// Reusable refinement and raycast buffers: nothing allocated per frame
    /// once warm.
    pub refiner: Refiner,
    pub raycaster: horizon::Raycaster,
    /// A pyramid's level windows the raycast reads, kept for the next
    /// frame and read ahead.
    pub level_windows: Option<LevelWindows>,
    /// Objects placed on the terrain, when a placement file was loaded.
    pub objects: Option<ObjectMesh>,
    /// The bundle's vegetation clusters with the cut they were baked for,
    /// and the draw list the cut refills each frame.
    pub vegetation: Option<Vegetation>,
}

/// Vegetation to draw: relevo-core's clusters, the cut's options, the draw
/// list reused across frames, and the blobs of the last blob baseline.
pub struct Vegetation {
    pub clusters: Clusters,
    pub cut: CutOptions,
    pub list: DrawList,
    blobs: Option<(f64, Vec<Blob>)>,
}

impl Vegetation {
    /// The clusters of a bundle of either kind, when it has them.
    fn of(bundle: &dyn BundleFiles) -> Result<Option<Vegetation>> {
        Ok(store::read(bundle)?.map(|(index, clusters)| Vegetation {
            clusters,
            cut: index.options.cut,
            list: DrawList::default(),
            blobs: None,
        }))
    }

    /// Choose what to draw from `camera` with the selection and view angle
    /// of `settings` (relevo-core's selections; blobs are grouped once per
    /// side).
    pub fn select(&mut self, camera: &Camera, settings: &Settings) {
        self.cut.view_angle_deg = settings.view_angle_deg;
        self.cut.automatic_view_angle = settings.automatic_view_angle;
        self.cut.level_fade = settings.level_fade;
        self.cut.cull = settings.vegetation_culling;
        match settings.vegetation {
            VegetationSelection::Quadtree => {
                QuadtreeCut(&self.clusters).select(camera, &self.cut, &mut self.list);
            }
            VegetationSelection::List => {
                ObjectList(&self.clusters).select(camera, &self.cut, &mut self.list);
            }
            VegetationSelection::Blobs { side_m } => {
                if self.blobs.as_ref().is_none_or(|(k, _)| *k != side_m) {
                    self.blobs = Some((side_m, group_blobs(&self.clusters, side_m as f32)));
                }
                let blobs = self.blobs.as_ref().map_or(&[][..], |(_, b)| b.as_slice());
                Blobs::from_groups(&self.clusters, blobs).select(camera, &self.cut, &mut self.list);
            }
        }
    }

    /// Move the selected impostors from the grid's surface, on which the
    /// bake placed them, onto the mesh refined for `camera` through
    /// `mesh` (a grid's arrays or a pyramid's cut): in mesh mode they stand
    /// on the surface drawn (relevo-core's `mesh_height`). `ground` is the
    /// surface the bake stood them on — exactly for a single grid and a
    /// pyramid whose overview is its level 0 (at most 2049² vertices); a
    /// larger pyramid's overview is coarser, and its objects stand on the
    /// mesh within the overview's error.
    pub fn stand_on_mesh(
        &mut self,
        mesh: &(impl VertexSource + Sync),
        ground: &Terrain,
        camera: &Camera,
        settings: &Settings,
    ) {
        let params = settings.refine_params(camera);
        self.list.lift(&|x, y| {
            mesh_height(mesh, &params, x, y)
                .zip(ground.surface(x, y))
                .map_or(0.0, |(mesh, grid)| mesh - grid)
        });
    }
}

impl Scene {
    /// Open the bundle or pyramid at `path`; errors name it and the
    /// problem.
    pub fn open(path: &Path) -> Result<Scene> {
        if relevo_core::bundle::format_of(path).as_deref() == Some(PYRAMID_FORMAT) {
            return Scene::open_pyramid(path);
        }
        let bundle = Bundle::open(path)?;
        let frame = bundle.frame();
        // The raycaster's copy, and the mesh mode's mip-mapped drape
        // (4/3 × 4 bytes a pixel, counted once more).
        let drape_pixels = bundle
            .manifest
            .color
            .as_ref()
            .map_or(0, |c| c.width as u64 * c.height as u64);
        Terrain::check_size(frame.side, drape_pixels.saturating_mul(2))
            .with_context(|| path.display().to_string())?;
        let lp = bundle.lp()?;
        let drape = bundle.drape()?;
        let vegetation = Vegetation::of(&bundle)?;
        let color = drape.as_ref().and_then(|d| d.color_source(&frame));
        let terrain = Terrain::new(
            frame.side,
            frame.cell_size_m,
            bundle.heights()?.to_vec(),
            bundle.mask()?.to_vec(),
            color,
        );
        let drape = match drape {
            None => None,
            Some(d) => {
                let pixel = frame
                    .terrain_to_pixel(&d.info.geotransform)
                    .with_context(|| {
                        format!(
                            "{}: the drape's geotransform cannot be inverted",
                            path.display()
                        )
                    })?;
                let (w, h) = (d.info.width as f64, d.info.height as f64);
                let terrain_to_uv = [
                    pixel[0] / w,
                    pixel[1] / w,
                    pixel[2] / w,
                    pixel[3] / h,
                    pixel[4] / h,
                    pixel[5] / h,
                ];
                Some(DrapeImage {
                    width: d.info.width as u32,
                    height: d.info.height as u32,
                    rgba: d.rgba,
                    terrain_to_uv,
                })
            }
        };
        Ok(Scene {
            path: path.to_path_buf(),
            grid: bundle.manifest.grid.clone(),
            frame,
            lp: Some(lp),
            drape,
            terrain,
            paged: None,
            mesh_cut: None,
            refiner: Refiner::new(),
            raycaster: horizon::Raycaster::default(),
            level_windows: None,
            objects: None,
            vegetation,
        })
    }

    /// Open the pyramid at `path`: its tiles paged for the mesh, its
    /// overview level read whole for the other renderers.
    fn open_pyramid(path: &Path) -> Result<Scene> {
        let pyramid = Pyramid::open(path)?;
        let grid = pyramid.manifest.grid.clone();
        let levels = pyramid.layout.levels();
        let level = (0..levels)
            .find(|&l| (grid.side - 1) >> l < OVERVIEW_SIDE)
            .unwrap_or(levels - 1);
        let side = ((grid.side - 1) >> level) + 1;
        let rect = Rect {
            c0: 0,
            r0: 0,
            width: side,
            height: side,
        };
        let (heights, mask) = pyramid.lattice_heights(level, rect)?;
        let (rgba, geotransform) = pyramid.lattice_drape(level, rect)?;
        let frame = TerrainFrame {
            side,
            cell_size_m: grid.cell_size_m * (1u64 << level) as f64,
            geotransform,
        };
        let color = horizon::ColorSource::new(&rgba, side, side, &geotransform, &frame);
        let terrain = Terrain::new(side, frame.cell_size_m, heights, mask, color);
        let paged = PagedPyramid::new(pyramid, TILE_CACHE_BYTES.load(Ordering::Relaxed) as usize)
            .with_context(|| path.display().to_string())?;
        let vegetation = Vegetation::of(paged.pyramid.as_ref())?;
        let level_windows = Some(LevelWindows::new(paged.pyramid.clone()));
        Ok(Scene {
            path: path.to_path_buf(),
            grid,
            frame,
            lp: None,
            drape: None,
            terrain,
            paged: Some(paged),
            mesh_cut: None,
            refiner: Refiner::new(),
            raycaster: horizon::Raycaster::default(),
            level_windows,
            objects: None,
            vegetation,
        })
    }

    /// Place the objects of a GeoJSON placement file on the terrain.
    pub fn load_objects(&mut self, path: &Path) -> Result<()> {
        let terrain = &self.terrain;
        let mesh = read_placement(path, &self.frame, &|x, y| terrain.surface(x, y))?;
        self.objects = Some(mesh);
        Ok(())
    }

    /// Whether there is anything to draw over the terrain: placed objects
    /// or vegetation.
    pub fn has_objects(&self) -> bool {
        self.objects.is_some() || self.vegetation.is_some()
    }

    /// A pyramid's level the mesh under world point (east, north) was
    /// last refined from.
    pub fn tile_level_at(&self, east: f64, north: f64) -> Option<u32> {
        let frame = TerrainFrame {
            side: self.grid.side,
            cell_size_m: self.grid.cell_size_m,
            geotransform: self.grid.geotransform,
        };
        let (c, r) = frame.vertex_from_world(east, north)?;
        self.paged.as_ref()?.level_at(c, r)
    }

    /// Side of the terrain frame's square, metres.
    pub fn extent_m(&self) -> f64 {
        (self.frame.side - 1) as f64 * self.frame.cell_size_m
    }

    /// Ground height (bilinear) under terrain point (x, y), metres; `None`
    /// off the data.
    pub fn ground_height(&self, x: f64, y: f64) -> Option<f64> {
        self.terrain.surface(x, y)
    }
}
