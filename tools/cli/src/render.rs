//! `relevo render`: the floating-horizon raycast of a bundle to PNG (and its
//! depth buffer), without a GPU.

use anyhow::{bail, Context, Result};
use glam::DVec3;
use relevo_core::bundle::Bundle;
use relevo_core::camera::Camera;
use relevo_core::horizon::{
    render, Arithmetic, Band, ColorSource, Frame, Mode, RenderOptions, Terrain,
};
use std::path::Path;

/// A camera given in the bundle's world coordinates.
#[derive(Debug, Clone, Copy)]
pub struct View {
    /// Easting, northing (CRS units), height (metres).
    pub eye: [f64; 3],
    pub heading_deg: f64,
    pub incl_px: Option<f64>,
    pub fov_x_deg: f64,
    pub size: [u32; 2],
    /// Far plane in grid cells.
    pub far_cells: f64,
}

/// The camera in the bundle's terrain frame (near plane one cell ahead).
pub fn camera(bundle: &Bundle, view: &View) -> Result<Camera> {
    let g = &bundle.manifest.grid;
    let (col, row) = g
        .geotransform
        .invert(view.eye[0], view.eye[1])
        .context("the bundle's geotransform cannot be inverted")?;
    let (c, r) = (col - 0.5, row - 0.5);
    let cell = g.cell_size_m;
    Ok(Camera {
        position: DVec3::new(c * cell, (g.side as f64 - 1.0 - r) * cell, view.eye[2]),
        heading_deg: view.heading_deg,
        pitch_deg: 0.0,
        incl_px: view.incl_px.unwrap_or(view.size[1] as f64 / 2.0),
        fov_x_deg: view.fov_x_deg,
        width: view.size[0],
        height: view.size[1],
        near_m: cell,
        far_m: view.far_cells * cell,
    })
}

/// The raycaster's colour source for a bundle with a drape image.
pub fn color_source(bundle: &Bundle) -> Result<Option<ColorSource>> {
    let m = &bundle.manifest;
    let Some(info) = &m.color else {
        return Ok(None);
    };
    let rgba = bundle.array::<u8>("color")?;
    Ok(ColorSource::new(
        &rgba,
        info.width,
        info.height,
        &info.geotransform,
        &m.grid.geotransform,
        m.grid.side,
        m.grid.cell_size_m,
    ))
}

/// Parse `UNTIL_M:SLICES_PER_CELL[:sub]` bands, comma-separated, e.g.
/// `3000:4:sub,10000:2:sub,inf:1`.
pub fn parse_bands(text: &str) -> Result<Vec<Band>, String> {
    text.split(',')
        .map(|band| {
            let parts: Vec<&str> = band.split(':').collect();
            let bad = || format!("{band:?}: expected UNTIL_M:SLICES_PER_CELL[:sub]");
            if !(2..=3).contains(&parts.len()) {
                return Err(bad());
            }
            let until_m = if parts[0] == "inf" {
                f64::INFINITY
            } else {
                parts[0].parse().map_err(|_| bad())?
            };
            let slices_per_cell: f64 = parts[1].parse().map_err(|_| bad())?;
            if !(slices_per_cell > 0.0 && slices_per_cell <= 64.0) {
                return Err(format!("{band:?}: slices per cell must be in (0, 64]"));
            }
            let subvoxel = match parts.get(2) {
                None => false,
                Some(&"sub") => true,
                Some(_) => return Err(bad()),
            };
            Ok(Band {
                until_m,
                slices_per_cell,
                subvoxel,
            })
        })
        .collect()
}

/// Render a bundle.
pub fn render_bundle(
    bundle: &Bundle,
    view: &View,
    options: &RenderOptions,
    hillshade: Option<[f64; 2]>,
) -> Result<Frame> {
    let m = &bundle.manifest;
    let heights = bundle.array::<f32>("height")?;
    let mask = bundle.array::<u8>("mask")?;
    let mut terrain = Terrain::new(
        m.grid.side,
        m.grid.cell_size_m,
        &heights,
        &mask,
        color_source(bundle)?,
    );
    if let Some([az, el]) = hillshade {
        terrain = terrain.with_hillshade(az, el);
    }
    let cam = camera(bundle, view)?;
    Ok(render(&terrain, &cam, options))
}

/// Write an RGBA8 PNG through a partial file.
pub fn write_png(path: &Path, frame: &Frame) -> Result<()> {
    let bytes = crate::gdalio::encode_png(frame.rgba_bytes(), frame.width, frame.height)?;
    crate::gdalio::write_atomic(path, &bytes)
}

/// Options from the command line.
pub fn options(
    mode: Mode,
    fixed: bool,
    bands: Option<Vec<Band>>,
    prefilter: bool,
) -> Result<RenderOptions> {
    let mut o = RenderOptions {
        mode,
        prefilter,
        ..Default::default()
    };
    if fixed {
        o.arithmetic = Arithmetic::Fixed;
    }
    if let Some(b) = bands {
        if b.is_empty() {
            bail!("--bands needs at least one band");
        }
        o.bands = b;
    }
    Ok(o)
}
