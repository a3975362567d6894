use super::files::BundleFiles;
use super::hash::sha256_file;
use super::names;
use super::reader::Bundle;
use crate::grid::pow2_plus_1_at_least;

/// Check a bundle against its manifest: every file present with the recorded
/// size and SHA-256, array shapes consistent with their byte length, and the
/// grid invariants (side 2^n+1, mask of 0/1 agreeing with the manifest,
/// finite heights within the recorded range, nested LP errors and radii),
/// and the vegetation database. Returns one line per problem; empty means
/// valid. The clusters are checked by `cluster::store`; `validation`
/// runs both.
pub fn validate_artifacts(bundle: &Bundle) -> Vec<String> {
    let mut problems = Vec::new();
    let m = &bundle.manifest;
    for (name, a) in m.artifacts.iter().chain(&m.exports) {
        let path = bundle.dir.join(&a.file);
        match sha256_file(&path) {
            Err(e) => problems.push(format!("{name}: {e}")),
            Ok((bytes, sha)) => {
                if bytes != a.bytes {
                    problems.push(format!(
                        "{name}: {} is {bytes} bytes, manifest says {}",
                        a.file, a.bytes
                    ));
                }
                if sha != a.sha256 {
                    problems.push(format!(
                        "{name}: {} has sha256 {sha}, manifest says {}",
                        a.file, a.sha256
                    ));
                }
                if let Some(size) = a.dtype.size() {
                    let expected = a.shape.iter().product::<usize>() * size;
                    if expected as u64 != bytes {
                        problems.push(format!(
                            "{name}: shape {:?} needs {expected} bytes, file has {bytes}",
                            a.shape
                        ));
                    }
                }
            }
        }
    }
    if !problems.is_empty() {
        return problems;
    }

    let side = m.grid.side;
    if side < 3 || pow2_plus_1_at_least(side) != side {
        problems.push(format!("grid side {side} is not 2^n+1"));
    }
    for name in [names::HEIGHT.key, names::MASK.key, names::LP.key] {
        match m.artifacts.get(name) {
            None => problems.push(format!("missing artifact {name:?}")),
            Some(a) if !a.shape.starts_with(&[side, side]) => problems.push(format!(
                "{name}: shape {:?}, expected [{side}, {side}, …]",
                a.shape
            )),
            Some(_) => {}
        }
    }
    if !problems.is_empty() {
        return problems;
    }
    let (heights, mask) = match (bundle.heights(), bundle.mask()) {
        (Ok(h), Ok(k)) => (h, k),
        (Err(e), _) | (_, Err(e)) => return vec![e.to_string()],
    };
    if let Some(bad) = mask.iter().position(|&v| v > 1) {
        problems.push(format!(
            "mask: value {} at vertex {bad}; only 0 and 1 are allowed",
            mask[bad]
        ));
    }
    let valid = mask.iter().filter(|&&v| v == 1).count();
    if valid != m.grid.valid_vertices {
        problems.push(format!(
            "mask: {valid} valid vertices, manifest says {}",
            m.grid.valid_vertices
        ));
    }
    let [lo, hi] = m.grid.height_range_m;
    if let Some(bad) = heights
        .iter()
        .zip(mask.iter())
        .position(|(&h, &k)| k == 1 && !(lo..=hi).contains(&h))
    {
        problems.push(format!(
            "height: {} at vertex {bad} is outside the recorded range [{lo}, {hi}]",
            heights[bad]
        ));
    }
    if let Some(lp) = m.artifacts.get(names::LP.key) {
        if lp.shape != [side, side, 2] {
            problems.push(format!(
                "lp: shape {:?}, expected [{side}, {side}, 2]",
                lp.shape
            ));
        } else {
            match bundle.lp() {
                Err(e) => problems.push(e.to_string()),
                Ok(lp) => {
                    let h = lp.hierarchy();
                    let values: &[f32] = bytemuck::cast_slice(&h.error_radius);
                    if let Some(bad) = values.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
                        problems.push(format!(
                            "lp: value {} at index {bad} is not a finite non-negative number",
                            values[bad]
                        ));
                    } else {
                        problems.extend(
                            h.nesting_violations(&heights, 5)
                                .into_iter()
                                .map(|p| format!("lp: {p}")),
                        );
                    }
                }
            }
        }
    }
    if let Some(color) = &m.color {
        match m.artifacts.get(names::COLOR.key) {
            None => problems
                .push("manifest describes a colour image but has no \"color\" artifact".into()),
            Some(a) if a.shape != [color.height, color.width, 4] => problems.push(format!(
                "color: shape {:?}, expected [{}, {}, 4]",
                a.shape, color.height, color.width
            )),
            Some(_) => {}
        }
    }
    if m.artifacts.contains_key(names::VEGETATION.key) {
        problems.extend(vegetation_problems(bundle));
    }
    problems
}

/// The vegetation database parses, numbers its objects 1, 2, …, and keeps
/// them on the colour image with positive sizes and scores in [0, 1].
fn vegetation_problems(bundle: &Bundle) -> Vec<String> {
    let objects = match bundle.vegetation() {
        Ok(objects) => objects.unwrap_or_default(),
        Err(e) => return vec![format!("vegetation: {e}")],
    };
    let bounds = bundle
        .manifest
        .color
        .as_ref()
        .map(|c| c.geotransform.bounds(c.width, c.height));
    let mut problems = Vec::new();
    for (k, o) in objects.iter().enumerate() {
        // The database keeps millimetres: allow that much rounding.
        let outside = bounds.is_some_and(|[x0, y0, x1, y1]| {
            let e = 1e-3;
            !(x0 - e <= o.x && o.x <= x1 + e && y0 - e <= o.y && o.y <= y1 + e)
        });
        let problem = if o.id != k as u64 + 1 {
            Some(format!("id {} where {} was due", o.id, k + 1))
        } else if outside {
            Some(format!("({}, {}) lies outside the colour image", o.x, o.y))
        } else if !(o.x.is_finite() && o.y.is_finite()) {
            Some(format!("position ({}, {}) is not finite", o.x, o.y))
        } else if !(o.size.is_finite() && o.size > 0.0 && (0.0..=1.0).contains(&o.score)) {
            Some(format!("size {} or score {} out of range", o.size, o.score))
        } else {
            None
        };
        if let Some(p) = problem {
            problems.push(format!("vegetation: object {}: {p}", k + 1));
            break;
        }
    }
    problems
}
