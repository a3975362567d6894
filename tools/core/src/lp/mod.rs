//! Lindstrom–Pascucci view-dependent refinement over the (2^n+1)² grid.
//!
//! Lindstrom and Pascucci, "Terrain Simplification Simplified: A General
//! Framework for View-Dependent Out-of-Core Visualization" (IEEE TVCG 2002),
//! as presented in chapter 3 of the LP seed (pre-processing of errors and
//! radii, `RefinaMalha`/`RefinaSubMalha`/`AnexaStrip`, culling, geomorphing).
//!
//! The mesh hierarchy is longest-edge bisection of right isosceles triangles:
//! every vertex except the four corners is the midpoint of the hypotenuse of
//! one or two triangles (its *diamond*), the triangles' right-angle vertices
//! are its *parents*, and the midpoints of the legs are its *children*.
//! - [`hierarchy`]: per-vertex object-space error δ and bounding-sphere radius
//!   r, nested child → parent; `diamond`: the hierarchy's geometry (scales,
//!   hypotenuses, parents, children); [`metric`]: how a vertex's own error
//!   is measured; [`window`]: both passes over any rectangle of the grid,
//!   exact for the vertices whose descendants it holds (tiles).
//! - [`extract`]: the view-independent mesh for an object-space tolerance.
//! - [`export`]: that mesh as glTF or OBJ, with normals and the drape.
//! - [`refine`]: the view-dependent triangle strip for a camera and a
//!   screen-space tolerance, with frustum culling and geomorphing.
//! - `vertices`: where a vertex lies, the levels of a grid, and the layouts
//!   per-vertex arrays are stored in.
//!
//! Coordinates: vertex (c, r) of the grid (column, row; row 0 is north) sits
//! in the *terrain frame* at x = c·cell (east), y = (side − 1 − r)·cell
//! (north), z = height, all in metres.

mod diamond;
pub mod export;
pub mod extract;
pub mod hierarchy;
pub mod metric;
pub mod refine;
mod vertices;
pub mod window;

pub use diamond::{children, vertex_kind, visit_bottom_up, Diamond, Vertex};
pub use hierarchy::{ErrorMetric, Hierarchy};
pub use vertices::{levels, terrain_position, Layout, TILE};
