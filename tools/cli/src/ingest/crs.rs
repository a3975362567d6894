//! Coordinate reference systems: parsing what users type, choosing the metric
//! CRS of a bundle, and transforming footprints.

use anyhow::{anyhow, Result};
use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};
use relevo_core::geo::GeoTransform;

/// Parse anything GDAL accepts (`EPSG:32633`, WKT, PROJ strings, a file).
pub fn parse(definition: &str) -> Result<SpatialRef> {
    let mut srs = SpatialRef::from_definition(definition)
        .map_err(|_| anyhow!("{definition:?} is not a coordinate reference system GDAL knows"))?;
    srs.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    Ok(srs)
}

pub fn to_wkt(srs: &SpatialRef) -> Result<String> {
    Ok(srs.to_wkt()?)
}

/// The EPSG code of a CRS, when GDAL can identify one.
pub fn epsg(srs: &SpatialRef) -> Option<u32> {
    let mut srs = srs.clone();
    let _ = srs.auto_identify_epsg();
    match srs.auth_name().as_deref() {
        Some("EPSG") => srs.auth_code().ok().map(|c| c as u32),
        _ => None,
    }
}

/// WGS 84 / UTM zone containing (lon, lat) in degrees: EPSG 326zz north of the
/// equator, 327zz south.
pub fn utm_for(lon: f64, lat: f64) -> Result<SpatialRef> {
    let zone = (((lon + 180.0) / 6.0).floor() as i64).clamp(0, 59) + 1;
    let code = if lat >= 0.0 { 32600 } else { 32700 } + zone as u32;
    let mut srs = SpatialRef::from_epsg(code)?;
    srs.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    Ok(srs)
}

/// Geographic WGS 84 with longitude first.
pub fn wgs84() -> Result<SpatialRef> {
    let mut srs = SpatialRef::from_epsg(4326)?;
    srs.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    Ok(srs)
}

/// Transform points from `from` to `to`; identity when the CRSs are the same.
pub fn transform_points(
    from: &SpatialRef,
    to: &SpatialRef,
    xs: &mut [f64],
    ys: &mut [f64],
) -> Result<()> {
    if from == to {
        return Ok(());
    }
    let t = CoordTransform::new(from, to)?;
    let mut zs = vec![0.0; xs.len()];
    t.transform_coords(xs, ys, &mut zs)
        .map_err(|e| anyhow!("cannot transform coordinates: {e}"))?;
    Ok(())
}

/// Bounding box `[xmin, ymin, xmax, ymax]` in `to` of a `width`×`height`
/// grid georeferenced by `geo` in `from`, from 21 points along each edge (so
/// curved edges of reprojected footprints are covered).
pub fn footprint(
    geo: &GeoTransform,
    width: usize,
    height: usize,
    from: Option<&SpatialRef>,
    to: Option<&SpatialRef>,
) -> Result<[f64; 4]> {
    let (Some(from), Some(to)) = (from, to) else {
        return Ok(geo.bounds(width, height));
    };
    const STEPS: usize = 20;
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    for k in 0..=STEPS {
        let f = k as f64 / STEPS as f64;
        for (c, r) in [
            (f * width as f64, 0.0),
            (f * width as f64, height as f64),
            (0.0, f * height as f64),
            (width as f64, f * height as f64),
        ] {
            let (x, y) = geo.apply(c, r);
            xs.push(x);
            ys.push(y);
        }
    }
    transform_points(from, to, &mut xs, &mut ys)?;
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for (&x, &y) in xs.iter().zip(&ys) {
        if x.is_finite() && y.is_finite() {
            b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
        }
    }
    if !b[0].is_finite() {
        return Err(anyhow!("footprint does not transform into the target CRS"));
    }
    Ok(b)
}

/// Cell size in the target CRS that keeps a source's detail: the shorter of
/// the two transformed edges of the source's centre cell. Reprojecting at
/// this size never merges two source cells into one target cell along
/// either axis.
pub fn detail_preserving_cell(
    geo: &GeoTransform,
    width: usize,
    height: usize,
    from: &SpatialRef,
    to: &SpatialRef,
) -> Result<f64> {
    let (c, r) = ((width / 2) as f64, (height / 2) as f64);
    let corners = [
        geo.apply(c, r),
        geo.apply(c + 1.0, r),
        geo.apply(c, r + 1.0),
    ];
    let mut xs: Vec<f64> = corners.iter().map(|p| p.0).collect();
    let mut ys: Vec<f64> = corners.iter().map(|p| p.1).collect();
    transform_points(from, to, &mut xs, &mut ys)?;
    let along_row = (xs[1] - xs[0]).hypot(ys[1] - ys[0]);
    let along_column = (xs[2] - xs[0]).hypot(ys[2] - ys[0]);
    let cell = along_row.min(along_column);
    if !(cell.is_finite() && cell > 0.0) {
        return Err(anyhow!("cannot derive a cell size in the target CRS"));
    }
    Ok(cell)
}
