//! The vegetation database summarised for a golden record (per class: the
//! count, and per block of the grid the count and mean position), and two
//! databases matched object to object for `relevo diff` (kept, moved,
//! added, removed).

use super::blocks::BlockLayout;
use crate::geo::GeoTransform;
use crate::veg::db::VegObject;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One class of the database as recorded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClassDigest {
    pub count: usize,
    /// One line per block holding objects of the class:
    /// `BX BY COUNT MEAN_X MEAN_Y` (map units, 3 decimals).
    pub blocks: Vec<String>,
}

/// Per class, its digest.
pub type VegetationDigest = BTreeMap<String, ClassDigest>;

/// One block of a class, read back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassBlock {
    pub block: [usize; 2],
    pub count: usize,
    pub mean: [f64; 2],
}

/// The block of `layout` (over the grid georeferenced by `geo`) that map
/// point (`x`, `y`) falls in, clamped to the grid.
pub fn block_of(layout: &BlockLayout, geo: &GeoTransform, x: f64, y: f64) -> [usize; 2] {
    let (c, r) = geo.invert(x, y).unwrap_or((0.0, 0.0));
    let [across, down] = layout.blocks();
    let at = |v: f64, n: usize| ((v.max(0.0) as usize) / layout.cells).min(n.saturating_sub(1));
    [at(c, across), at(r, down)]
}

/// Summarise `objects` by class and block.
pub fn digest(objects: &[VegObject], layout: &BlockLayout, geo: &GeoTransform) -> VegetationDigest {
    // Per class, per block (row first, so lines run row by row): the
    // count and the sum of positions.
    type Sums = BTreeMap<[usize; 2], (usize, [f64; 2])>;
    let mut by_class: BTreeMap<String, Sums> = BTreeMap::new();
    for o in objects {
        let [bx, by] = block_of(layout, geo, o.x, o.y);
        let cell = by_class
            .entry(o.class.clone())
            .or_default()
            .entry([by, bx])
            .or_insert((0, [0.0; 2]));
        cell.0 += 1;
        cell.1[0] += o.x;
        cell.1[1] += o.y;
    }
    by_class
        .into_iter()
        .map(|(class, blocks)| {
            let count = blocks.values().map(|b| b.0).sum();
            let blocks = blocks
                .into_iter()
                .map(|([by, bx], (n, sum))| {
                    let n_f = n as f64;
                    format!("{bx} {by} {n} {:.3} {:.3}", sum[0] / n_f, sum[1] / n_f)
                })
                .collect();
            (class, ClassDigest { count, blocks })
        })
        .collect()
}

impl ClassDigest {
    /// The blocks, read back; a malformed line is an error naming it.
    pub fn parse(&self) -> Result<Vec<ClassBlock>, String> {
        self.blocks
            .iter()
            .map(|line| {
                let f: Vec<&str> = line.split(' ').collect();
                let parsed = (f.len() == 5)
                    .then(|| {
                        Some(ClassBlock {
                            block: [f[0].parse().ok()?, f[1].parse().ok()?],
                            count: f[2].parse().ok()?,
                            mean: [f[3].parse().ok()?, f[4].parse().ok()?],
                        })
                    })
                    .flatten()
                    .filter(|b| b.mean.iter().all(|v| v.is_finite()));
                parsed.ok_or_else(|| format!("{line:?} is not BX BY COUNT MEAN_X MEAN_Y"))
            })
            .collect()
    }
}

/// How the objects of one class changed between two databases.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ClassChanges {
    pub before: usize,
    pub after: usize,
    /// Objects at the same place with the same size.
    pub kept: usize,
    /// Matched objects that moved or changed size: (before, after).
    pub moved: Vec<(VegObject, VegObject)>,
    pub added: Vec<VegObject>,
    pub removed: Vec<VegObject>,
}

/// Match each class's objects of `before` and `after`: identical objects
/// are kept; of the rest, the closest pairs within `radius_m` (greedy,
/// nearest first) have moved; what is left was added or removed.
///
/// ```
/// use relevo_core::golden::vegetation::match_objects;
/// use relevo_core::veg::db::VegObject;
/// let tree = |id, x: f64| VegObject { id, x, y: 0.0, class: "forest".into(), size: 5.0, score: 1.0 };
/// let changes = match_objects(&[tree(1, 0.0), tree(2, 100.0)], &[tree(1, 0.0), tree(2, 103.0), tree(3, 500.0)], 10.0);
/// let forest = &changes["forest"];
/// assert_eq!((forest.kept, forest.moved.len(), forest.added.len(), forest.removed.len()), (1, 1, 1, 0));
/// ```
pub fn match_objects(
    before: &[VegObject],
    after: &[VegObject],
    radius_m: f64,
) -> BTreeMap<String, ClassChanges> {
    let mut classes: BTreeMap<String, (Vec<&VegObject>, Vec<&VegObject>)> = BTreeMap::new();
    for o in before {
        classes.entry(o.class.clone()).or_default().0.push(o);
    }
    for o in after {
        classes.entry(o.class.clone()).or_default().1.push(o);
    }
    classes
        .into_iter()
        .map(|(class, (b, a))| (class, match_class(&b, &a, radius_m)))
        .collect()
}

/// Key of an object for exact matching: position and size as stored (mm).
fn exact_key(o: &VegObject) -> (i64, i64, i64) {
    let mm = |v: f64| (v * 1000.0).round() as i64;
    (mm(o.x), mm(o.y), mm(o.size))
}

fn match_class(before: &[&VegObject], after: &[&VegObject], radius_m: f64) -> ClassChanges {
    let mut changes = ClassChanges {
        before: before.len(),
        after: after.len(),
        ..Default::default()
    };
    // Identical objects first.
    let mut unmatched_after: BTreeMap<(i64, i64, i64), Vec<&VegObject>> = BTreeMap::new();
    for o in after {
        unmatched_after.entry(exact_key(o)).or_default().push(o);
    }
    let mut left_before = Vec::new();
    for o in before {
        match unmatched_after.get_mut(&exact_key(o)).and_then(Vec::pop) {
            Some(_) => changes.kept += 1,
            None => left_before.push(*o),
        }
    }
    let left_after: Vec<&VegObject> = unmatched_after.into_values().flatten().collect();
    // Then the nearest pairs within the radius, through a grid of buckets.
    let bucket = radius_m.max(1e-3);
    let key = |o: &VegObject| ((o.x / bucket).floor() as i64, (o.y / bucket).floor() as i64);
    let mut buckets: BTreeMap<(i64, i64), Vec<usize>> = BTreeMap::new();
    for (j, o) in left_after.iter().enumerate() {
        buckets.entry(key(o)).or_default().push(j);
    }
    let mut pairs = Vec::new();
    for (i, o) in left_before.iter().enumerate() {
        let (kx, ky) = key(o);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for &j in buckets.get(&(kx + dx, ky + dy)).into_iter().flatten() {
                    let d = (o.x - left_after[j].x).hypot(o.y - left_after[j].y);
                    if d <= radius_m {
                        pairs.push((d, i, j));
                    }
                }
            }
        }
    }
    pairs.sort_by(|p, q| p.0.total_cmp(&q.0).then(p.1.cmp(&q.1)).then(p.2.cmp(&q.2)));
    let (mut used_before, mut used_after) = (
        vec![false; left_before.len()],
        vec![false; left_after.len()],
    );
    for (_, i, j) in pairs {
        if !used_before[i] && !used_after[j] {
            used_before[i] = true;
            used_after[j] = true;
            changes
                .moved
                .push((left_before[i].clone(), left_after[j].clone()));
        }
    }
    changes.removed = left_before
        .iter()
        .zip(&used_before)
        .filter(|(_, &u)| !u)
        .map(|(o, _)| (*o).clone())
        .collect();
    changes.added = left_after
        .iter()
        .zip(&used_after)
        .filter(|(_, &u)| !u)
        .map(|(o, _)| (*o).clone())
        .collect();
    changes
}
