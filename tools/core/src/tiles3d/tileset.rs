//! The tile tree as `tileset.json` (3D Tiles 1.1, §"Tileset JSON"): each
//! tile's region, geometric error, content and children. A deep tree is cut
//! into external tilesets every [`SUBTREE_LEVELS`] levels, so that no JSON
//! file a client reads first grows with the region.

use super::Region;
use serde_json::{json, Value};

/// How a tile's children refine it: replacing its content (terrain) or
/// adding to it (vegetation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refine {
    Add,
    Replace,
}

impl Refine {
    fn name(self) -> &'static str {
        match self {
            Refine::Add => "ADD",
            Refine::Replace => "REPLACE",
        }
    }
}

/// One tile of the tree.
#[derive(Debug, Clone, PartialEq)]
pub struct Tile {
    /// A name unique in the tree (`12/3456/789`), which names its external
    /// tileset if it roots one.
    pub name: String,
    /// Holds the tile's content and every descendant's.
    pub region: Region,
    /// Metres of error if this tile is drawn and its children are not.
    pub geometric_error_m: f64,
    /// The content's path, relative to the tileset's folder.
    pub content: Option<String>,
    pub children: Vec<Tile>,
}

impl Tile {
    /// A tile over `children`: their region's union, and at least the
    /// largest of their errors (a parent's error is never below a child's).
    pub fn over(
        name: String,
        content: Option<(String, Region)>,
        geometric_error_m: f64,
        children: Vec<Tile>,
    ) -> Tile {
        let mut region = content.as_ref().map_or(Region::EMPTY, |c| c.1);
        let mut error = geometric_error_m;
        for c in &children {
            region = region.union(c.region);
            error = error.max(c.geometric_error_m);
        }
        Tile {
            name,
            region,
            geometric_error_m: error,
            content: content.map(|c| c.0),
            children,
        }
    }

    /// Tiles in the tree, this one included (tests).
    #[cfg(test)]
    pub fn count(&self) -> usize {
        1 + self.children.iter().map(Tile::count).sum::<usize>()
    }
}

/// Levels of the tree one JSON file holds before its tiles' children go to
/// external tilesets (4^6 = 4096 tiles at most per file).
pub const SUBTREE_LEVELS: usize = 6;

/// The JSON files of the tree under `root`: `(path, document)`, the root's
/// file first at `root_path`, external tilesets beside it as
/// `subtree_{name}.json` (the name's `/` as `_`). `transform` is the root's
/// (column-major 4 × 4); `unrendered_error_m` the error of drawing none of
/// the tileset, which clients compare with their screen-space error
/// before they draw even the root (CesiumJS skips a tileset whose error is
/// under its threshold).
pub fn files(
    root: &Tile,
    root_path: &str,
    refine: Refine,
    transform: Option<[f64; 16]>,
    unrendered_error_m: f64,
) -> Vec<(String, Value)> {
    let mut out = Vec::new();
    let mut json = tile_json(root, refine, 0, &mut out);
    if let Some(m) = transform {
        json["transform"] = json!(m);
    }
    let error = unrendered_error_m.max(root.geometric_error_m);
    out.insert(0, (root_path.to_string(), document(error, json)));
    out
}

/// A tileset document with `root_json` as its root.
fn document(geometric_error_m: f64, root_json: Value) -> Value {
    json!({
        "asset": {"version": "1.1", "generator": concat!("relevo ", env!("CARGO_PKG_VERSION"))},
        "geometricError": geometric_error_m,
        "root": root_json,
    })
}

/// The file name of the external tileset rooted at `tile`.
pub fn subtree_path(tile: &Tile) -> String {
    format!("subtree_{}.json", tile.name.replace('/', "_"))
}

/// `tile`'s JSON at `depth` below its file's root; external tilesets for
/// the children past [`SUBTREE_LEVELS`] go into `files`.
fn tile_json(tile: &Tile, refine: Refine, depth: usize, files: &mut Vec<(String, Value)>) -> Value {
    let mut json = json!({
        "boundingVolume": tile.region.to_json(),
        "geometricError": tile.geometric_error_m,
        "refine": refine.name(),
    });
    if let Some(uri) = &tile.content {
        json["content"] = json!({ "uri": uri });
    }
    let children: Vec<Value> = tile
        .children
        .iter()
        .map(|c| {
            if depth + 1 < SUBTREE_LEVELS {
                return tile_json(c, refine, depth + 1, files);
            }
            // The child roots an external tileset; this file holds a tile
            // over it with the same volume and error.
            let path = subtree_path(c);
            let root = tile_json(c, refine, 0, files);
            files.push((path.clone(), document(c.geometric_error_m, root)));
            json!({
                "boundingVolume": c.region.to_json(),
                "geometricError": c.geometric_error_m,
                "content": {"uri": path},
            })
        })
        .collect();
    if !children.is_empty() {
        json["children"] = json!(children);
    }
    json
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(depth: usize) -> Tile {
        let region = Region::EMPTY.extend(0.0, 0.0, 0.0).extend(1.0, 1.0, 1.0);
        let mut tile = Tile::over(
            format!("{depth}/0/0"),
            Some((format!("{depth}.glb"), region)),
            0.0,
            vec![],
        );
        for d in (0..depth).rev() {
            tile = Tile::over(
                format!("{d}/0/0"),
                Some((format!("{d}.glb"), region)),
                (depth - d) as f64,
                vec![tile],
            );
        }
        tile
    }

    #[test]
    fn deep_trees_are_cut_into_external_tilesets() {
        let root = chain(14);
        assert_eq!(root.count(), 15);
        let files = files(&root, "tileset.json", Refine::Replace, None, 100.0);
        let names: Vec<&str> = files.iter().map(|f| f.0.as_str()).collect();
        assert_eq!(
            names,
            ["tileset.json", "subtree_12_0_0.json", "subtree_6_0_0.json"]
        );
        // The root file holds levels 0–5 and a tile pointing at level 6.
        let mut t = &files[0].1["root"];
        for d in 0..6 {
            assert_eq!(t["content"]["uri"], format!("{d}.glb"));
            assert_eq!(t["geometricError"], (14 - d) as f64);
            t = &t["children"][0];
        }
        assert_eq!(t["content"]["uri"], "subtree_6_0_0.json");
        assert_eq!(files[2].1["root"]["content"]["uri"], "6.glb");
        assert_eq!(files[2].1["asset"]["version"], "1.1");
        assert_eq!(files[0].1["geometricError"], 100.0);
    }

    #[test]
    fn a_parent_holds_its_children() {
        let child = Tile::over(
            "c".into(),
            Some(("c.glb".into(), Region::EMPTY.extend(2.0, 2.0, 50.0))),
            3.0,
            vec![],
        );
        let parent = Tile::over("p".into(), None, 1.0, vec![child.clone()]);
        assert!(parent.region.contains(&child.region));
        assert_eq!(parent.geometric_error_m, 3.0);
        assert_eq!(parent.content, None);
    }
}
