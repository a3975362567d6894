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
    QuantizedMesh(QuantizedMeshArgs),
}

#[derive(clap::Args, Debug)]
pub struct QuantizedMeshArgs {
    /// The bundle (single grid or pyramid).
    pub bundle: PathBuf,
    /// The folder to write (layer.json and one folder per level).
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
    match command {
        ExportCommand::QuantizedMesh(a) => {
            let summary = terrain_export::quantized_mesh(&terrain_export::Request {
                bundle: &a.bundle,
                out: &a.out,
                max_zoom: a.max_zoom,
                vertical: a.vertical,
                force: a.force,
            })?;
            if a.json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!("{}", summary.line());
            }
            Ok(())
        }
    }
}
