//! relevo-view: fly over a Relevo bundle as a view-dependent refined mesh
//! or a CPU floating-horizon raycast whose depth lets GPU-drawn objects
//! composite; render the same frames headless to PNG.
//!
//! Depends on relevo-core only (no GDAL): every terrain computation —
//! refinement, raycast, picking, frames, cameras — is core's; this crate
//! owns GPU resources, input and UI.
//!
//! - [`settings`]: what a frame is drawn with, shared by the UI and the GPU.
//! - [`scene`]: the opened bundle and the per-session renderer state.
//! - [`flight`]: the camera being flown and how input moves it.
//! - [`gpu`]: offscreen targets, the mesh and raycast passes.
//! - [`headless`]: `relevo-view render` and the GPU device without a window.
//! - [`mod@bench`]: `relevo-view bench`, frame times of a scripted flight.
//! - [`hud`]: the HUD's readings, painted in the window and headless.
//! - [`samples`]: the samples tab — marking samples, detecting, accepting.
//! - [`keys`]: the key list the handler, the help and the README share.
//! - [`app`]: the window, side panel and keys.

pub mod app;
pub mod bench;
pub mod flight;
pub mod gpu;
pub mod headless;
pub mod hud;
pub mod keys;
pub mod samples;
pub mod scene;
pub mod settings;

/// Mesa's software Vulkan driver (lavapipe): tests and CI draw with it so
/// that reference images come out the same on every machine.
pub const LAVAPIPE_ICD: &str = "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json";
