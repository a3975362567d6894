//! `relevo mesh`: the mesh at an object-space tolerance as glTF or OBJ.

use crate::output;
use anyhow::{bail, Context, Result};
use clap::Args;
use relevo_core::bundle::Bundle;
use relevo_core::geo::TerrainFrame;
use relevo_core::lp::export::{self, MeshSource};
use relevo_core::lp::window::Rect;
use relevo_core::lp::ErrorMetric;
use relevo_core::pyramid::mesh::PyramidMesh;
use relevo_core::pyramid::Pyramid;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct MeshArgs {
    /// The bundle to mesh.
    pub bundle: PathBuf,
    /// Largest vertical distance left between the mesh and any grid point
    /// under it, metres (a bound for bundles with the default error metric).
    #[arg(long)]
    pub max_error: f32,
    /// Output format; default: from the output's extension.
    #[arg(long, value_enum)]
    pub format: Option<MeshFormat>,
    /// Output .glb or .obj (with .mtl and .png beside it).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Mesh the padding and voids too (as martini does), ignoring the mask.
    #[arg(long)]
    pub keep_padding: bool,
    /// Mesh only the triangles meeting this rectangle, in the bundle's CRS
    /// (easting and northing of two opposite corners); positions are then
    /// local to its south-west corner and the texture covers it.
    #[arg(long, value_name = "X0,Y0,X1,Y1", allow_hyphen_values = true, value_parser = parse_window)]
    pub window: Option<[f64; 4]>,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq)]
pub enum MeshFormat {
    Glb,
    Obj,
}

pub fn run(a: MeshArgs) -> Result<()> {
    let format = match a.format {
        Some(f) => f,
        None => match a
            .out
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("glb") => MeshFormat::Glb,
            Some("obj") => MeshFormat::Obj,
            _ => bail!(
                "{}: cannot tell the format from the extension; pass --format glb|obj",
                a.out.display()
            ),
        },
    };
    if !(a.max_error.is_finite() && a.max_error >= 0.0) {
        bail!(
            "--max-error must be a non-negative number of metres, got {}",
            a.max_error
        );
    }
    let pyramid = relevo_core::bundle::format_of(&a.bundle).as_deref()
        == Some(relevo_core::bundle::PYRAMID_FORMAT);
    if pyramid {
        let p = Pyramid::open(&a.bundle)?;
        let source = PyramidMesh::new(&p)?;
        let metric = p.manifest.lp_error_metric;
        return write_mesh(&a, format, &source, &p.manifest.crs.wkt, metric);
    }
    let bundle = Bundle::open(&a.bundle)?;
    let (heights, mask, lp, drape) = (
        bundle.heights()?,
        bundle.mask()?,
        bundle.lp()?,
        bundle.drape()?,
    );
    let surface = export::Surface {
        frame: bundle.frame(),
        heights: &heights,
        mask: &mask,
        hierarchy: lp.hierarchy(),
        drape: drape.as_ref().map(|d| export::DrapeImage {
            rgba: std::borrow::Cow::Borrowed(&d.rgba),
            width: d.info.width,
            height: d.info.height,
            geotransform: d.info.geotransform,
        }),
    };
    let metric = bundle.manifest.lp_error_metric;
    write_mesh(&a, format, &surface, &bundle.manifest.crs.wkt, metric)
}

/// `X0,Y0,X1,Y1`: four finite numbers.
fn parse_window(text: &str) -> std::result::Result<[f64; 4], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>().map_err(|e| format!("{v:?}: {e}")))
        .collect::<std::result::Result<_, _>>()?;
    match values[..] {
        [x0, y0, x1, y1] if values.iter().all(|v| v.is_finite()) => Ok([x0, y0, x1, y1]),
        _ => Err(format!(
            "{text:?}: expected four finite numbers X0,Y0,X1,Y1"
        )),
    }
}

/// The grid vertices `--window` covers: the corners' columns and rows
/// rounded outwards, within the grid; an error when it misses the grid.
fn window_rect([x0, y0, x1, y1]: [f64; 4], frame: &TerrainFrame) -> Result<Rect> {
    if x0 == x1 || y0 == y1 {
        bail!("--window {x0},{y0},{x1},{y1}: not a rectangle");
    }
    let corner = |x: f64, y: f64| frame.vertex_from_world(x, y);
    let (Some(a), Some(b)) = (corner(x0, y0), corner(x1, y1)) else {
        bail!("the grid's georeferencing cannot be inverted");
    };
    let last = (frame.side - 1) as f64;
    let (c0, c1) = (a.0.min(b.0).floor().max(0.0), a.0.max(b.0).ceil().min(last));
    let (r0, r1) = (a.1.min(b.1).floor().max(0.0), a.1.max(b.1).ceil().min(last));
    if c0 >= c1 || r0 >= r1 {
        let (w, n) = frame.world_from_vertex(0.0, 0.0);
        let (e, s) = frame.world_from_vertex(last, last);
        bail!(
            "--window {x0},{y0},{x1},{y1} does not meet the grid, which spans east {w:.1} to \
             {e:.1} and north {s:.1} to {n:.1} in its CRS"
        );
    }
    Ok(Rect {
        c0: c0 as usize,
        r0: r0 as usize,
        width: (c1 - c0) as usize + 1,
        height: (r1 - r0) as usize + 1,
    })
}

/// Extract the mesh of `source` at the tolerance and write it (and, for
/// OBJ with a drape, its material and texture), all or nothing.
fn write_mesh(
    a: &MeshArgs,
    format: MeshFormat,
    source: &dyn MeshSource,
    crs_wkt: &str,
    metric: ErrorMetric,
) -> Result<()> {
    // Every file this writes, side files included, checked before any work.
    let stem = a
        .out
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "mesh".into());
    let side_files = match format {
        MeshFormat::Obj if source.has_drape() => vec![
            a.out.with_file_name(format!("{stem}.mtl")),
            a.out.with_file_name(format!("{stem}.png")),
        ],
        _ => Vec::new(),
    };
    let outputs: Vec<&Path> = std::iter::once(&a.out)
        .chain(&side_files)
        .map(PathBuf::as_path)
        .collect();
    output::check(&outputs, a.force)?;
    let window = a
        .window
        .map(|w| window_rect(w, &source.frame()))
        .transpose()?;
    let m = export::build(source, a.max_error, a.keep_padding, window)
        .with_context(|| a.bundle.display().to_string())?;
    match format {
        MeshFormat::Glb => {
            output::write_atomic(&a.out, &export::to_glb(&m, crs_wkt)?)?;
        }
        MeshFormat::Obj => {
            let obj = export::to_obj(&m, m.texture_png.as_ref().map(|_| stem.as_str()));
            let mtl = format!("newmtl drape\nKd 1 1 1\nmap_Kd {stem}.png\n");
            let mut files: Vec<(&Path, &[u8])> = vec![(&a.out, &obj)];
            if let (Some(png), [mtl_path, png_path]) = (&m.texture_png, side_files.as_slice()) {
                files.push((mtl_path, mtl.as_bytes()));
                files.push((png_path, png));
            }
            relevo_core::atomic::write_files(&files)?;
        }
    }
    eprintln!(
        "{}: {} vertices, {} triangles at {} m; no grid point is more than {:.3} m from the mesh",
        a.out.display(),
        m.positions.len(),
        m.triangles.len(),
        a.max_error,
        m.largest_deviation_m
    );
    if metric == ErrorMetric::Midpoint {
        tracing::warn!(
            "{}: errors measured at hypotenuse midpoints (martini's metric), so --max-error is not a bound; \
             prep the bundle again with the default --error-metric bound to make it one",
            a.bundle.display()
        );
    }
    Ok(())
}
