//! What a frame is drawn with besides the camera: the mode, the mesh's
//! tolerance, the raycast's options, what vegetation is chosen and how it
//! is shown. The window's keys and side panel set it, the headless render
//! reads it from flags, and the GPU passes draw by it.

use relevo_core::camera::Camera;
use relevo_core::horizon::{DistanceBand, RenderOptions};
use relevo_core::lp::refine::RefineParams;
use relevo_core::zbuffer::Representation;
use serde::Serialize;

/// How the terrain is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TerrainMode {
    /// relevo-core's view-dependent refinement, drawn as triangles.
    #[default]
    Mesh,
    /// relevo-core's floating-horizon raycast, composited with its depth.
    Raycast,
    /// A Z-buffer baseline of the whole grid (Szenberg 1997, ch. 3).
    ZBuffer(Representation),
}

impl TerrainMode {
    /// Parse `mesh`, `raycast` or `zbuffer:a` … `zbuffer:g`.
    pub fn parse(text: &str) -> Result<TerrainMode, String> {
        match text {
            "mesh" => Ok(TerrainMode::Mesh),
            "raycast" => Ok(TerrainMode::Raycast),
            _ => text
                .strip_prefix("zbuffer:")
                .and_then(|l| l.chars().next().filter(|_| l.len() == 1))
                .and_then(Representation::from_letter)
                .map(TerrainMode::ZBuffer)
                .ok_or_else(|| {
                    format!("{text:?}: expected mesh, raycast or zbuffer:a … zbuffer:g")
                }),
        }
    }
}

impl std::fmt::Display for TerrainMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TerrainMode::Mesh => write!(f, "mesh"),
            TerrainMode::Raycast => write!(f, "raycast"),
            TerrainMode::ZBuffer(r) => write!(f, "zbuffer:{}", r.letter()),
        }
    }
}

impl Serialize for TerrainMode {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

/// The raycast's detailed bands (the side panel's and the benchmarks'):
/// four slices per cell with sub-voxels to 3 km, one slice per cell beyond.
pub fn detailed_bands() -> Vec<DistanceBand> {
    vec![
        DistanceBand {
            until_m: 3000.0,
            slices_per_cell: 4.0,
            subvoxel: true,
        },
        DistanceBand {
            until_m: f64::INFINITY,
            slices_per_cell: 1.0,
            subvoxel: false,
        },
    ]
}

/// Everything a frame is drawn with besides the camera.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub mode: TerrainMode,
    /// Screen-space tolerance τ of the refinement, pixels.
    pub tau_px: f64,
    /// Geomorphing band: vertices blend in between τ and this many pixels.
    pub morph: bool,
    /// Frustum culling in the refinement.
    pub cull: bool,
    pub wireframe: bool,
    /// The drape as texture (else a shaded height ramp).
    pub texture: bool,
    /// The raycaster's options (bands, fixed point, prefilter).
    pub raycast: RenderOptions,
    /// Draw the scene's objects and vegetation (the seed's F1).
    pub objects: bool,
    /// Draw the terrain (off: objects alone, to check composition).
    pub terrain: bool,
    /// What chooses the vegetation drawn: relevo-core's quadtree cut, or a
    /// baseline.
    pub vegetation: VegetationSelection,
    /// Sprites — two crossed quads showing the front and left views —
    /// instead of billboards turned to the eye (the seed's F12).
    pub sprites: bool,
    /// Impostors cut out by their alpha (off: whole quads, as the seed's
    /// tests drew them).
    pub alpha: bool,
    /// Impostor textures filtered and mip-mapped (off: the nearest texel
    /// of the full-size level; the seed's blur toggle).
    pub blur: bool,
    /// Elevation of the line of sight above which impostors show their top
    /// view, degrees (the seed's θ).
    pub view_angle_deg: f64,
    /// Instead, each impostor's own threshold: where its top view shows
    /// more than its side (relevo-core's automatic choice).
    pub automatic_view_angle: bool,
    /// Margin over which a cluster dithers into its children instead of
    /// switching (relevo-core's `CutOptions::level_fade`; 0: it switches).
    pub level_fade: f64,
    /// Vegetation outside the view frustum left out (off only to measure
    /// what the culling saves, as the seed's table 4.2).
    pub vegetation_culling: bool,
}

/// What chooses the vegetation drawn each frame (relevo-core's
/// `cluster::cut` selections).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VegetationSelection {
    /// The quadtree cut: clusters far away, objects near.
    Quadtree,
    /// Every object in view, one by one.
    List,
    /// The seed's blobs of `side_m` metres.
    Blobs { side_m: f64 },
}

impl VegetationSelection {
    /// Parse `quadtree`, `list` or `blobs[:SIDE_M]` (3000 m by default).
    pub fn parse(text: &str) -> Result<Self, String> {
        match text {
            "quadtree" => Ok(Self::Quadtree),
            "list" => Ok(Self::List),
            "blobs" => Ok(Self::Blobs { side_m: 3000.0 }),
            _ => text
                .strip_prefix("blobs:")
                .and_then(|k| k.parse::<f64>().ok())
                .filter(|k| k.is_finite() && *k > 0.0)
                .map(|side_m| Self::Blobs { side_m })
                .ok_or_else(|| format!("{text:?}: expected quadtree, list or blobs[:SIDE_M]")),
        }
    }
}

impl std::fmt::Display for VegetationSelection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Quadtree => write!(f, "quadtree"),
            Self::List => write!(f, "list"),
            Self::Blobs { side_m } => write!(f, "blobs:{side_m}"),
        }
    }
}

/// Geomorphing band: a vertex blends in between τ and this multiple of τ.
const MORPH_BAND: f64 = 3.0;

impl Settings {
    /// What mesh mode refines for from `camera`.
    pub fn refine_params(&self, camera: &Camera) -> RefineParams {
        RefineParams::for_camera(
            camera,
            self.tau_px,
            self.morph.then_some(self.tau_px * MORPH_BAND),
            self.cull,
        )
    }
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            mode: TerrainMode::Mesh,
            tau_px: 2.0,
            morph: true,
            cull: true,
            wireframe: false,
            texture: true,
            raycast: RenderOptions::default(),
            objects: true,
            terrain: true,
            vegetation: VegetationSelection::Quadtree,
            sprites: false,
            alpha: true,
            blur: true,
            view_angle_deg: 45.0,
            automatic_view_angle: false,
            level_fade: relevo_core::cluster::cut::CutOptions::default().level_fade,
            vegetation_culling: true,
        }
    }
}
