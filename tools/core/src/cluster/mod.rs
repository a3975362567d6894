//! Vegetation clusters (vegetation thesis, chapter 4): impostors of each
//! class rendered from 3D models, a quadtree over the vegetation database
//! whose nodes carry baked views of their members, atlases under a memory
//! budget, and the cut that chooses what to draw from a camera.
//!
//! - [`model`]: vegetation models — OBJ files or the procedural trees.
//! - [`views`]: the five orthographic views, rasterised on the CPU.
//! - [`image`]: premultiplied images and their mip levels.
//! - [`quadtree`]: the tree over the objects.
//! - [`bake`]: class impostors, cluster views, atlas packing, the budget.
//! - [`stage`]: the clusters stage on a vegetation database over a terrain.
//! - [`cut`]: selection from a camera — quadtree cut, plain list, blobs.
//! - [`store`]: the `clusters/` folder of a bundle, and its validation.
//! - [`checks`]: properties of bakes and cuts (no fringe, each object
//!   once), shared by the tests and validation.
//!
//! This file holds what the others share: the baked [`Clusters`], each
//! class's [`ClassImpostor`], the [`AtlasFrame`]s and the [`BakeReport`].

pub mod bake;
pub mod checks;
pub mod cut;
pub mod image;
pub mod model;
pub mod quadtree;
pub mod stage;
pub mod store;
pub mod views;

use image::PremulImage;
use model::ModelSource;
use quadtree::Quadtree;

/// The impostor of one vegetation class.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClassImpostor {
    pub name: String,
    /// Where the model came from.
    pub model: ModelSource,
    /// Height over crown diameter: an object of this class with diameter d
    /// stands d × aspect tall.
    pub aspect: f32,
    /// Atlas frames of the top, front, back, left and right views.
    pub frames: [AtlasFrame; 5],
}

/// Everything the clusters stage makes, and what a viewer draws from.
#[derive(Debug, Clone, PartialEq)]
pub struct Clusters {
    pub classes: Vec<ClassImpostor>,
    pub tree: Quadtree,
    /// Frames of the baked nodes, five per node (`Node::frames` indexes it).
    pub frames: Vec<AtlasFrame>,
    /// Atlas pages, level 0 (mip levels are [`image::PremulImage::mip_chain`]).
    pub pages: Vec<PremulImage>,
    pub report: BakeReport,
}

/// An atlas frame: page and texel rectangle (of page level 0).
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    bytemuck::Pod,
    bytemuck::Zeroable,
    serde::Serialize,
    serde::Deserialize,
)]
pub struct AtlasFrame {
    pub page: u16,
    pub x: u16,
    pub y: u16,
    pub width: u16,
    pub height: u16,
}

/// Counts and bytes of one quadtree depth.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LevelReport {
    pub depth: u32,
    pub nodes: usize,
    /// Nodes a cut may draw as clusters (2 to the largest band size members).
    pub clusters: usize,
    /// Clusters whose views were baked; the others were left out because
    /// the budget capped their parent too (the parent serves the same
    /// distances).
    pub baked: usize,
    /// Baked clusters whose texel density the budget reduced (sharp only
    /// from farther than their band starts).
    pub reduced: usize,
    /// Texture bytes of the baked views with their mip levels, estimated
    /// from their frames and gutters.
    pub atlas_bytes: u64,
}

/// What a bake did.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BakeReport {
    pub objects: usize,
    pub levels: Vec<LevelReport>,
    /// Bytes of the class impostors' pages on their own.
    pub class_bytes: u64,
    /// Bytes of the atlas pages as written, with mip levels.
    pub atlas_bytes: u64,
    pub budget_bytes: u64,
    /// When the budget binds: the texel density cluster views were capped
    /// at (texels per metre), and the distance from which capped clusters
    /// are sharp on the reference screen (metres).
    pub density_cap: Option<f64>,
    pub sharp_from_m: Option<f64>,
}

impl BakeReport {
    /// Clusters left out of the atlas.
    pub fn left_out(&self) -> usize {
        self.levels.iter().map(|l| l.clusters - l.baked).sum()
    }
}
