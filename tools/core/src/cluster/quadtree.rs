//! The quadtree over the vegetation database (vegetation thesis, §4.2.4.3,
//! fig. 4.11): the terrain's square split into four until a quad holds at
//! most one object (or the depth limit is reached). Every node keeps its
//! quad, member count and the box its members fill, so that a node can
//! stand for all of them at once.
//!
//! Objects are stored in tree order: a node's members are one contiguous
//! run, `objects[first .. first + count]`.

use bytemuck::{Pod, Zeroable};

/// No node (a missing child, an unbaked node's views).
pub const NONE: u32 = u32::MAX;

/// One vegetation object as the clusters see it, in the terrain frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct ClusterObject {
    /// Foot of the object: terrain-frame x, y (metres) and the ground height.
    pub foot: [f32; 3],
    /// Crown diameter and height, metres.
    pub diameter: f32,
    pub height: f32,
    /// Index into the class table.
    pub class: u32,
    /// Row of the object in the vegetation database (0 = first object).
    pub row: u32,
}

impl ClusterObject {
    /// The box the object fills: `[min, max]`.
    pub fn bounds(&self) -> [[f32; 3]; 2] {
        let r = self.diameter / 2.0;
        [
            [self.foot[0] - r, self.foot[1] - r, self.foot[2]],
            [
                self.foot[0] + r,
                self.foot[1] + r,
                self.foot[2] + self.height,
            ],
        ]
    }
}

/// One quad of the tree.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Node {
    /// The box the members fill (crowns included), metres.
    pub min: [f32; 3],
    pub max: [f32; 3],
    /// The quad: south-west corner x, y and side, metres.
    pub quad: [f32; 3],
    /// Depth below the root (root 0).
    pub depth: u32,
    /// Members: `objects[first .. first + count]`.
    pub first: u32,
    pub count: u32,
    /// Children south-west, south-east, north-west, north-east ([`NONE`]
    /// where a quarter is empty or the node is a leaf).
    pub children: [u32; 4],
    /// First of the node's five frames (top, front, back, left, right) in
    /// the frame table, or [`NONE`] when its views were not baked.
    pub frames: u32,
}

impl Node {
    pub fn is_leaf(&self) -> bool {
        self.children.iter().all(|&c| c == NONE)
    }

    pub fn members(&self) -> std::ops::Range<usize> {
        self.first as usize..(self.first + self.count) as usize
    }
}

/// The tree: nodes (root first) and the objects in tree order.
#[derive(Debug, Clone, PartialEq)]
pub struct Quadtree {
    pub nodes: Vec<Node>,
    pub objects: Vec<ClusterObject>,
}

/// Deepest split: 2^24 quads per side, finer than any terrain needs; objects
/// at one spot share a leaf.
pub const MAX_DEPTH: u32 = 24;

impl Quadtree {
    /// Build over `objects` inside the square with south-west corner
    /// `origin` and side `side` (metres), splitting until a quad holds at
    /// most one object or `max_depth` is reached. Objects outside the square
    /// are clamped onto its edge for the split only.
    pub fn build(
        mut objects: Vec<ClusterObject>,
        origin: [f32; 2],
        side: f32,
        max_depth: u32,
    ) -> Quadtree {
        let mut nodes = Vec::new();
        let count = objects.len();
        if count > 0 {
            split(
                &mut objects,
                0,
                [origin[0], origin[1], side],
                0,
                max_depth.min(MAX_DEPTH),
                &mut nodes,
            );
        }
        Quadtree { nodes, objects }
    }

    /// The problem that makes a tree read from a file unsafe to walk, if
    /// any: `classes` is the length of the class table. A tree passes when
    /// the nodes, root first, form one tree in pre-order (every child index
    /// in range and after its parent, every node but the root the child of
    /// exactly one node, so no walk can loop), depths grow by one down to
    /// [`MAX_DEPTH`] (so no recursion goes deeper), each node's members lie
    /// inside its parent's and inside the object table, and every number is
    /// finite. Frames are checked by the store, which knows the frame table.
    pub fn structure_problem(&self, classes: usize) -> Option<String> {
        let (nodes, objects) = (&self.nodes, self.objects.len() as u64);
        let Some(root) = nodes.first() else {
            return (!self.objects.is_empty()).then(|| format!("{objects} objects but no nodes"));
        };
        if root.first != 0 || u64::from(root.count) != objects || root.depth != 0 {
            return Some("the root is not at depth 0 holding every object".into());
        }
        let mut parent = vec![NONE; nodes.len()];
        for (i, n) in nodes.iter().enumerate() {
            if i > 0 && parent[i] == NONE {
                return Some(format!("node {i} is nobody's child"));
            }
            let finite = n
                .min
                .iter()
                .chain(&n.max)
                .chain(&n.quad)
                .all(|v| v.is_finite());
            if !finite || n.depth > MAX_DEPTH {
                return Some(format!(
                    "node {i}: a box that is not finite or depth {}",
                    n.depth
                ));
            }
            // Inside the object table: the root holds it all and every other
            // node was checked to nest in its parent before its turn.
            let end = u64::from(n.first) + u64::from(n.count);
            for &c in n.children.iter().filter(|&&c| c != NONE) {
                let Some(child) = nodes.get(c as usize).filter(|_| c as usize > i) else {
                    return Some(format!("node {i}: child {c} is not a later node"));
                };
                if std::mem::replace(&mut parent[c as usize], i as u32) != NONE {
                    return Some(format!("node {c} is the child of two nodes"));
                }
                let child_end = u64::from(child.first) + u64::from(child.count);
                if child.depth != n.depth + 1 || child.first < n.first || child_end > end {
                    return Some(format!("node {c}: not nested in its parent {i}"));
                }
            }
        }
        self.objects.iter().enumerate().find_map(|(i, o)| {
            let finite = o
                .foot
                .iter()
                .chain([&o.diameter, &o.height])
                .all(|v| v.is_finite());
            let sized = o.diameter >= 0.0 && o.height >= 0.0;
            (!finite || !sized || o.class as usize >= classes).then(|| {
                format!(
                    "object {i}: class {} of {classes}, or a position or size that is \
                     not finite and non-negative",
                    o.class
                )
            })
        })
    }

    /// Nodes per depth.
    pub fn nodes_per_depth(&self) -> Vec<usize> {
        let mut per = Vec::new();
        for n in &self.nodes {
            let d = n.depth as usize;
            if per.len() <= d {
                per.resize(d + 1, 0);
            }
            per[d] += 1;
        }
        per
    }
}

/// Add the node over `objects[..]` (which start at `first` in tree order)
/// and, recursively, its children; return its index.
fn split(
    objects: &mut [ClusterObject],
    first: usize,
    quad: [f32; 3],
    depth: u32,
    max_depth: u32,
    nodes: &mut Vec<Node>,
) -> u32 {
    let (mut min, mut max) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for o in objects.iter() {
        let [lo, hi] = o.bounds();
        for k in 0..3 {
            min[k] = min[k].min(lo[k]);
            max[k] = max[k].max(hi[k]);
        }
    }
    let index = nodes.len() as u32;
    nodes.push(Node {
        min,
        max,
        quad,
        depth,
        first: first as u32,
        count: objects.len() as u32,
        children: [NONE; 4],
        frames: NONE,
    });
    if objects.len() <= 1 || depth >= max_depth {
        return index;
    }
    // Partition into the quarters SW, SE, NW, NE (stable: ties keep the
    // database order, so the tree does not depend on sorting details).
    let half = quad[2] / 2.0;
    let (mx, my) = (quad[0] + half, quad[1] + half);
    let quarter = |o: &ClusterObject| (o.foot[0] >= mx) as usize + 2 * (o.foot[1] >= my) as usize;
    objects.sort_by_key(quarter);
    let mut start = 0;
    let mut children = [NONE; 4];
    for (q, child) in children.iter_mut().enumerate() {
        let end = start
            + objects[start..]
                .iter()
                .take_while(|o| quarter(o) == q)
                .count();
        if end > start {
            let corner = [
                quad[0] + half * (q % 2) as f32,
                quad[1] + half * (q / 2) as f32,
                half,
            ];
            *child = split(
                &mut objects[start..end],
                first + start,
                corner,
                depth + 1,
                max_depth,
                nodes,
            );
        }
        start = end;
    }
    nodes[index as usize].children = children;
    index
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn object(x: f32, y: f32, row: u32) -> ClusterObject {
        ClusterObject {
            foot: [x, y, 10.0],
            diameter: 4.0,
            height: 6.0,
            class: 0,
            row,
        }
    }

    #[test]
    fn leaves_hold_at_most_one_object_and_nodes_nest() {
        let objects: Vec<_> = (0..200)
            .map(|i| {
                let t = i as f32 * 0.618_034;
                object((t * 97.0) % 1000.0, (t * 61.0) % 1000.0, i)
            })
            .collect();
        let tree = Quadtree::build(objects.clone(), [0.0, 0.0], 1024.0, MAX_DEPTH);
        assert_eq!(tree.nodes[0].count, 200);
        let mut rows: Vec<u32> = tree.objects.iter().map(|o| o.row).collect();
        rows.sort_unstable();
        assert_eq!(rows, (0..200).collect::<Vec<_>>(), "every object once");
        for node in &tree.nodes {
            if node.is_leaf() {
                assert!(node.count <= 1);
            } else {
                let children: Vec<&Node> = node
                    .children
                    .iter()
                    .filter(|&&c| c != NONE)
                    .map(|&c| &tree.nodes[c as usize])
                    .collect();
                assert_eq!(children.iter().map(|c| c.count).sum::<u32>(), node.count);
                for c in children {
                    assert_eq!(c.depth, node.depth + 1);
                    assert_eq!(c.quad[2], node.quad[2] / 2.0);
                    assert!(c.members().start >= node.members().start);
                    assert!(c.members().end <= node.members().end);
                    for k in 0..3 {
                        assert!(c.min[k] >= node.min[k] && c.max[k] <= node.max[k]);
                    }
                }
            }
            for o in &tree.objects[node.members()] {
                let (x, y) = (o.foot[0], o.foot[1]);
                assert!(x >= node.quad[0] && x <= node.quad[0] + node.quad[2]);
                assert!(y >= node.quad[1] && y <= node.quad[1] + node.quad[2]);
            }
        }
        // Two objects at one spot stop at the depth limit, sharing a leaf.
        let same = Quadtree::build(
            vec![object(5.0, 5.0, 0), object(5.0, 5.0, 1)],
            [0.0; 2],
            64.0,
            3,
        );
        assert_eq!(same.nodes.last().unwrap().depth, 3);
        assert_eq!(same.nodes.last().unwrap().count, 2);
        assert!(Quadtree::build(Vec::new(), [0.0; 2], 1.0, 4)
            .nodes
            .is_empty());
        assert_eq!(tree.structure_problem(1), None);
        assert_eq!(same.structure_problem(1), None);
    }

    #[test]
    fn trees_that_a_walk_could_loop_on_or_run_out_of_are_refused() {
        let objects: Vec<_> = (0..40)
            .map(|i| object((i * 37 % 100) as f32, (i * 11 % 100) as f32, i))
            .collect();
        let tree = Quadtree::build(objects, [0.0, 0.0], 128.0, MAX_DEPTH);
        let broken = |edit: &dyn Fn(&mut Quadtree)| {
            let mut t = tree.clone();
            edit(&mut t);
            t.structure_problem(1).unwrap_or_default()
        };
        let slot = tree.nodes[0]
            .children
            .iter()
            .position(|&c| c != NONE)
            .unwrap();
        assert!(broken(&|t| t.nodes[0].children[slot] = 0).contains("not a later node"));
        assert!(broken(&|t| t.nodes[0].children[slot] = 9999).contains("not a later node"));
        assert!(broken(&|t| t.nodes[0].children[slot] = NONE).contains("nobody's child"));
        assert!(broken(&|t| t.nodes[0].children = [1; 4]).contains("child of two"));
        assert!(broken(&|t| t.nodes[1].depth = 7).contains("not nested"));
        assert!(broken(&|t| t.nodes[2].count = u32::MAX).contains("not nested"));
        assert!(broken(&|t| t.nodes[0].count = 41).contains("every object"));
        assert!(broken(&|t| t.nodes[3].min[0] = f32::NAN).contains("not finite"));
        assert!(broken(&|t| t.objects[5].class = 1).contains("class 1 of 1"));
        assert!(broken(&|t| t.objects[5].diameter = f32::INFINITY).contains("object 5"));
        assert!(broken(&|t| t.nodes.clear()).contains("no nodes"));
    }
}
