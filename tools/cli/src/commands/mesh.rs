//! `relevo mesh`: the mesh at an object-space tolerance as glTF or OBJ.

use crate::output;
use anyhow::{bail, Context, Result};
use clap::Args;
use relevo_core::bundle::Bundle;
use relevo_core::lp::window::Rect;
use relevo_core::lp::{export, ErrorMetric, Hierarchy};
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
        let w = p.level0_window(Rect::whole(p.layout.side))?;
        let side = p.layout.side;
        let surface = export::Surface {
            frame: p.frame(),
            heights: &w.heights,
            mask: &w.mask,
            hierarchy: Hierarchy::borrowed(side, p.manifest.grid.cell_size_m, &w.lp),
            drape: Some(export::DrapeImage {
                rgba: &w.drape,
                width: side,
                height: side,
                geotransform: p.manifest.grid.geotransform,
            }),
        };
        let metric = p.manifest.lp_error_metric;
        return write_mesh(&a, format, &surface, &p.manifest.crs.wkt, metric);
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
            rgba: &d.rgba,
            width: d.info.width,
            height: d.info.height,
            geotransform: d.info.geotransform,
        }),
    };
    let metric = bundle.manifest.lp_error_metric;
    write_mesh(&a, format, &surface, &bundle.manifest.crs.wkt, metric)
}

/// Extract the mesh of `surface` at the tolerance and write it (and, for
/// OBJ with a drape, its material and texture), all or nothing.
fn write_mesh(
    a: &MeshArgs,
    format: MeshFormat,
    surface: &export::Surface,
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
        MeshFormat::Obj if surface.drape.is_some() => vec![
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
    let m = export::build(surface, a.max_error, a.keep_padding)
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
