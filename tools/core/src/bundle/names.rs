//! The artifacts Relevo writes into a bundle, each named once: the key it
//! has in the manifest and its file inside the bundle directory.

/// File name of the manifest inside a bundle.
pub const MANIFEST_FILE: &str = "manifest.json";

/// An artifact's manifest key and file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArtifactName {
    /// Key in `manifest.artifacts` (or `manifest.exports`).
    pub key: &'static str,
    /// Path relative to the bundle directory.
    pub file: &'static str,
}

/// Heights in metres, f32, `[side, side]`.
pub const HEIGHT: ArtifactName = ArtifactName {
    key: "height",
    file: "height.f32",
};
/// 1 where the grid has data, 0 on padding and voids, u8, `[side, side]`.
pub const MASK: ArtifactName = ArtifactName {
    key: "mask",
    file: "mask.u8",
};
/// Lindstrom–Pascucci `[error, radius]` per vertex, f32, `[side, side, 2]`.
pub const LP: ArtifactName = ArtifactName {
    key: "lp",
    file: "lp.f32x2",
};
/// The drape image, RGBA8, `[height, width, 4]`.
pub const COLOR: ArtifactName = ArtifactName {
    key: "color",
    file: "color.rgba8",
};
/// The vegetation database (`id;x;y;class;size;score`).
pub const VEGETATION: ArtifactName = ArtifactName {
    key: "vegetation",
    file: "vegetation.csv",
};

/// The samples the vegetation was detected from, written by `prep` from
/// the region's samples and by the viewer's accept
/// (`class;xmin;ymin;xmax;ymax`, pixels of the drape).
pub const VEGETATION_SAMPLES: ArtifactName = ArtifactName {
    key: "vegetation_samples",
    file: "vegetation_samples.csv",
};

/// Folder of the vegetation clusters (see `cluster::store`), and the prefix
/// of their manifest keys (atlas pages are `clusters_atlas_NNN`).
pub const CLUSTERS_DIR: &str = "clusters";
pub const CLUSTERS_PREFIX: &str = "clusters";
/// Manifest keys of the atlas pages: this prefix and the page, `NNN`.
pub const CLUSTER_PAGE_PREFIX: &str = "clusters_atlas_";
/// The cluster index: options, classes, pages, bake report (JSON).
pub const CLUSTER_INDEX: ArtifactName = ArtifactName {
    key: "clusters_index",
    file: "clusters/index.json",
};
/// Quadtree nodes, 68-byte records.
pub const CLUSTER_NODES: ArtifactName = ArtifactName {
    key: "clusters_nodes",
    file: "clusters/nodes.bin",
};
/// Objects in tree order, 28-byte records.
pub const CLUSTER_OBJECTS: ArtifactName = ArtifactName {
    key: "clusters_objects",
    file: "clusters/objects.bin",
};
/// Atlas frames of the baked nodes, 10-byte records.
pub const CLUSTER_FRAMES: ArtifactName = ArtifactName {
    key: "clusters_frames",
    file: "clusters/frames.bin",
};

/// Folder of the interoperability exports.
pub const EXPORTS_DIR: &str = "exports";
/// Heights as a GeoTIFF (no-data outside the mask).
pub const HEIGHT_GEOTIFF: ArtifactName = ArtifactName {
    key: "height_geotiff",
    file: "exports/height.tif",
};
/// The drape as a four-band GeoTIFF.
pub const COLOR_GEOTIFF: ArtifactName = ArtifactName {
    key: "color_geotiff",
    file: "exports/color.tif",
};
/// Vegetation objects as GeoPackage points.
pub const VEGETATION_GEOPACKAGE: ArtifactName = ArtifactName {
    key: "vegetation_geopackage",
    file: "exports/vegetation.gpkg",
};
/// Region and class labels of the drape as a two-band GeoTIFF.
pub const VEGETATION_LABELS: ArtifactName = ArtifactName {
    key: "vegetation_labels",
    file: "exports/vegetation_labels.tif",
};
