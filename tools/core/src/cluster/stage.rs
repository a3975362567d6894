//! The clusters stage on a vegetation database over a terrain, the one path
//! `prep`, `bake`, the tests and the benchmarks take: the classes and their
//! models, the objects standing on the ground, the bake.

use super::bake::{self, BakeOptions, ClassSource};
use super::model::{ModelSource, TreeKind};
use super::quadtree::ClusterObject;
use super::Clusters;
use crate::geo::TerrainFrame;
use crate::horizon::Terrain;
use crate::veg::db::VegObject;
use crate::{Error, Result};
use std::collections::BTreeMap;

/// The classes of a database, sorted by name: what [`ClusterObject::class`]
/// indexes.
pub fn class_names(database: &[VegObject]) -> Vec<String> {
    let set: std::collections::BTreeSet<&str> = database.iter().map(|o| o.class.as_str()).collect();
    set.into_iter().map(str::to_string).collect()
}

/// What the objects stand on: the terrain's height under points of the
/// terrain frame. A single grid's [`Terrain`] and a pyramid's tiles
/// (`pyramid::ground`) give the same heights.
pub trait Ground: Sync {
    /// The height under each of `points` (terrain frame, metres), `None`
    /// off the terrain or where it has no data; errors name what could not
    /// be read.
    fn heights_under(&self, points: &[[f64; 2]]) -> Result<Vec<Option<f64>>>;
}

impl Ground for Terrain<'_> {
    fn heights_under(&self, points: &[[f64; 2]]) -> Result<Vec<Option<f64>>> {
        Ok(points.iter().map(|&[x, y]| self.surface(x, y)).collect())
    }
}

/// The database's objects in the terrain frame, standing on `ground`;
/// `aspect[class]` is the height-to-diameter ratio of each class of
/// `classes`. Returns the objects and how many were off the terrain (left
/// out).
pub fn objects_on_terrain(
    database: &[VegObject],
    classes: &[String],
    aspect: &[f32],
    frame: &TerrainFrame,
    ground: &dyn Ground,
) -> Result<(Vec<ClusterObject>, usize)> {
    let at: Vec<Option<[f64; 2]>> = database
        .iter()
        .map(|o| frame.terrain_from_world(o.x, o.y).map(|(x, y)| [x, y]))
        .collect();
    let points: Vec<[f64; 2]> = at.iter().flatten().copied().collect();
    let mut heights = ground.heights_under(&points)?.into_iter();
    let mut off = 0;
    let mut objects = Vec::with_capacity(database.len());
    for (row, (o, at)) in database.iter().zip(at).enumerate() {
        let z = at.and_then(|_| heights.next().flatten());
        let class = classes.iter().position(|c| *c == o.class);
        let placed = class
            .zip(at)
            .zip(z)
            .map(|((class, [x, y]), z)| ClusterObject {
                foot: [x as f32, y as f32, z as f32],
                diameter: o.size as f32,
                height: o.size as f32 * aspect[class],
                class: class as u32,
                row: row as u32,
            });
        match placed {
            Some(p) if p.diameter > 0.0 => objects.push(p),
            _ => off += 1,
        }
    }
    Ok((objects, off))
}

/// The model of each class: `models` maps a class name to a built-in kind
/// or an OBJ file; a class not named gets the kind its name suggests
/// ([`TreeKind::for_class`]).
pub fn class_sources(
    classes: &[String],
    models: &BTreeMap<String, ModelSource>,
) -> Result<Vec<ClassSource>> {
    classes
        .iter()
        .map(|name| {
            let source = models
                .get(name)
                .cloned()
                .unwrap_or_else(|| ModelSource::Procedural(TreeKind::for_class(name)));
            Ok(ClassSource {
                name: name.clone(),
                model: source.load()?,
                source,
            })
        })
        .collect()
}

/// The whole clusters stage on a vegetation database over a terrain (the
/// one path `prep`, `bake`, the tests and the benchmarks take): models per
/// class, objects on `ground` (a single grid's [`Terrain`] or a pyramid's
/// tiles), the bake. Returns the clusters and the number of objects left
/// out off the terrain.
pub fn bake_database(
    database: &[VegObject],
    frame: &TerrainFrame,
    ground: &dyn Ground,
    models: &BTreeMap<String, ModelSource>,
    options: &BakeOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<(Clusters, usize)> {
    if database.is_empty() {
        return Err(Error::Input(
            "the vegetation database is empty: there is nothing to cluster".into(),
        ));
    }
    // The atlases with their mip levels and the views composed before
    // packing (measured: a peak of 1.3× a 256 MiB budget on the sample
    // region), and per object its record, its share of the quadtree's
    // nodes (1.6 per object at 1M) and the work lists.
    crate::memory::check(
        &format!(
            "the cluster bake of {} objects with a {} atlas budget",
            database.len(),
            crate::memory::human(options.budget_bytes)
        ),
        1,
        (options.budget_bytes / 2 * 3).saturating_add(512 * database.len() as u64),
        "lower the atlas budget (--budget-mib, or budget_bytes under [clusters])",
    )?;
    let classes = class_names(database);
    let sources = class_sources(&classes, models)?;
    let aspect: Vec<f32> = sources.iter().map(|c| c.model.aspect()).collect();
    let (objects, off_terrain) = objects_on_terrain(database, &classes, &aspect, frame, ground)?;
    if objects.is_empty() {
        return Err(Error::Input(format!(
            "none of the {} vegetation objects stands on the terrain",
            database.len()
        )));
    }
    let side_m = ((frame.side - 1) as f64 * frame.cell_size_m) as f32;
    let clusters = bake::bake(sources, objects, [0.0, 0.0], side_m, options, progress)?;
    Ok((clusters, off_terrain))
}
