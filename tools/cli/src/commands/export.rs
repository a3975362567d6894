//! `relevo export`: a bundle in formats other clients read.

use crate::terrain_export::{self, VerticalDatum};
use anyhow::Result;
use std::path::PathBuf;

#[derive(clap::Subcommand, Debug)]
pub enum ExportCommand {
    /// Cesium quantized-mesh terrain: `layer.json` and `{z}/{x}/{y}.terrain`
    /// in the geodetic tiling (EPSG:4326), each level's triangles chosen by
    /// the LP errors at the level's geometric error, heights above the
    /// WGS84 ellipsoid.
    #[command(after_help = "Examples:
  relevo export quantized-mesh olinda.relevo --out olinda-terrain
  relevo export quantized-mesh alps.relevo --vertical egm2008 --out alps-terrain   # Copernicus DEM heights
  relevo export quantized-mesh olinda.relevo --max-zoom 11 --out coarse --force

Serve the folder over HTTP and point a client at it, e.g. CesiumJS:
  CesiumTerrainProvider.fromUrl(\"http://localhost:8000/olinda-terrain\")")]
    QuantizedMesh(TilesArgs),
    /// 3D Tiles 1.1: the terrain as glb tiles with the drape (JPEG), each
    /// level's triangles chosen by the LP errors as for quantized-mesh, and
    /// the vegetation as instanced glb tiles (`EXT_mesh_gpu_instancing`, a
    /// mesh per class, each object's id, class and score as metadata).
    #[command(
        name = "3dtiles",
        after_help = "Examples:
  relevo export 3dtiles olinda.relevo --out olinda-3dtiles
  relevo export 3dtiles alps.relevo --vertical egm2008 --out alps-3dtiles --force

Writes tileset.json (both), terrain/tileset.json and vegetation/tileset.json;
serve the folder over HTTP and load any of them, e.g. CesiumJS:
  Cesium3DTileset.fromUrl(\"http://localhost:8000/olinda-3dtiles/tileset.json\")"
    )]
    Tiles3d(TilesArgs),
}

#[derive(clap::Args, Debug)]
pub struct TilesArgs {
    /// The bundle (single grid or pyramid).
    pub bundle: PathBuf,
    /// The folder to write.
    #[arg(long)]
    pub out: PathBuf,
    /// The finest level (default: the first whose 64 samples a tile are no
    /// wider than the grid's cells).
    #[arg(long)]
    pub max_zoom: Option<u32>,
    /// What the bundle's heights are measured from: egm96 (SRTM and most
    /// DEMs), egm2008 (Copernicus DEM) or ellipsoid. Converted to heights
    /// above the WGS84 ellipsoid through PROJ; where PROJ lacks the geoid's
    /// grid, the heights are written as they are, with a warning.
    #[arg(long, value_enum, default_value_t = VerticalDatum::Egm96)]
    pub vertical: VerticalDatum,
    /// Replace an existing export.
    #[arg(long)]
    pub force: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(command: ExportCommand) -> Result<()> {
    let (ExportCommand::QuantizedMesh(a) | ExportCommand::Tiles3d(a)) = &command;
    let request = terrain_export::Request {
        bundle: &a.bundle,
        out: &a.out,
        max_zoom: a.max_zoom,
        vertical: a.vertical,
        force: a.force,
    };
    let (json, line) = match &command {
        ExportCommand::QuantizedMesh(_) => {
            let summary = terrain_export::quantized_mesh::export(&request)?;
            (serde_json::to_string_pretty(&summary)?, summary.line())
        }
        ExportCommand::Tiles3d(_) => {
            let summary = terrain_export::tiles3d::export(&request)?;
            (serde_json::to_string_pretty(&summary)?, summary.line())
        }
    };
    println!("{}", if a.json { json } else { line });
    Ok(())
}
