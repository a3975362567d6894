//! The GPU side of the viewer: one offscreen colour + depth target that
//! every mode draws into, so the window and the headless renders share the
//! same code. The terrain comes from relevo-core either as the refined mesh
//! (`mesh`) or as the CPU raycast composited with its depth (`raycast`).

mod mesh;
mod objects;
mod raycast;
mod shared;
mod targets;
mod vegetation;
mod zbuffer;

pub use shared::FrameStats;
pub use targets::{frame_bytes_per_pixel, Readback, Targets, COLOUR_FORMAT, DEPTH_FORMAT};

use crate::scene::Scene;
use crate::settings::{Settings, TerrainMode};
use eframe::egui_wgpu::wgpu;

use relevo_core::camera::Camera;
use relevo_core::horizon::RenderOptions;
use relevo_core::lp::refine::GridArrays;
use std::time::Instant;
/// The GPU device and queue types the viewer draws with.
pub use wgpu::{Device, Queue};

/// The viewer's GPU resources for one scene.
pub struct Renderer {
    pub targets: Targets,
    mesh: mesh::MeshPass,
    raycast: raycast::RaycastPass,
    zbuffer: zbuffer::ZBufferPass,
    /// Built on the first frame that draws objects.
    objects: Option<objects::ObjectPass>,
    /// Built on the first frame that draws vegetation.
    vegetation: Option<vegetation::VegetationPass>,
    /// What the targets hold: the camera, settings and objects (vertex
    /// count) of the last frame and its figures. A frame asking for the
    /// same is already drawn.
    drawn: Option<(Camera, Settings, Option<usize>, FrameStats)>,
    /// The last frame's submission to the GPU.
    submitted: Option<wgpu::SubmissionIndex>,
}

/// The sky: the raycaster's colour for pixels without terrain.
pub fn sky_colour(options: &RenderOptions) -> wgpu::Color {
    let [r, g, b, a] = options.sky.map(|c| c as f64 / 255.0);
    wgpu::Color { r, g, b, a }
}

impl Renderer {
    /// Resources for `scene` drawing into a `size` target.
    pub fn new(device: &Device, queue: &Queue, scene: &Scene, size: [u32; 2]) -> Self {
        Renderer {
            targets: Targets::new(device, size),
            mesh: mesh::MeshPass::new(device, queue, scene),
            raycast: raycast::RaycastPass::new(device),
            zbuffer: zbuffer::ZBufferPass::new(device),
            objects: None,
            vegetation: None,
            drawn: None,
            submitted: None,
        }
    }

    /// The last frame drawn, as submitted to the GPU (to wait for it
    /// alone while the next frame is prepared).
    pub fn last_submission(&self) -> Option<wgpu::SubmissionIndex> {
        self.submitted.clone()
    }

    /// Wait for every tile of a pyramid a frame needs, and upload all
    /// their drapes, instead of drawing what has arrived (a headless
    /// render: the picture does not depend on the loader's timing).
    pub fn settle_tiles(&mut self) {
        self.mesh.settle = true;
    }

    /// Draw the next frame even if nothing changed (benchmarks timing the
    /// same view again).
    pub fn forget_last_frame(&mut self) {
        self.drawn = None;
    }

    /// Draw `scene` seen by `camera` into the targets (resized to the
    /// camera's viewport when needed): the terrain, then its objects
    /// depth-tested against it. When nothing changed since the last frame
    /// the targets already hold it, and its figures are returned without
    /// any work. Fails only when a Z-buffer baseline is asked of a grid too
    /// large for it.
    pub fn render(
        &mut self,
        device: &Device,
        queue: &Queue,
        scene: &mut Scene,
        camera: &Camera,
        settings: &Settings,
    ) -> anyhow::Result<FrameStats> {
        let objects_key = scene.objects.as_ref().map(|o| o.positions.len());
        // A pyramid still loading tiles draws again: finer tiles may have come.
        let settled = scene.paged.as_ref().is_none_or(|p| p.stats().loading == 0);
        if let Some((c, s, o, stats)) = &self.drawn {
            if c == camera && s == settings && *o == objects_key && settled {
                return Ok(*stats);
            }
        }
        let size = [camera.width, camera.height];
        if self.targets.size != size {
            let largest = device.limits().max_texture_dimension_2d;
            if size.iter().any(|&side| side > largest) {
                anyhow::bail!(
                    "a {}×{} frame: this GPU draws at most {largest} pixels a side",
                    size[0],
                    size[1]
                );
            }
            self.targets = Targets::new(device, size);
        }
        let mut stats = FrameStats {
            width: size[0],
            height: size[1],
            ..Default::default()
        };
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("relevo-view frame"),
        });
        let objects_drawn = settings.objects && scene.has_objects();
        // Set again by a pyramid's mesh drawn this frame: vegetation stands
        // only on a mesh that is drawn.
        scene.mesh_cut = None;
        match settings.mode {
            _ if !settings.terrain => {
                self.targets
                    .begin(&mut encoder, Some(sky_colour(&settings.raycast)), "clear");
            }
            TerrainMode::ZBuffer(representation) => {
                self.zbuffer
                    .prepare(device, queue, scene, camera, representation, &mut stats)?;
                self.zbuffer
                    .draw(&mut encoder, &self.targets, sky_colour(&settings.raycast));
            }
            TerrainMode::Mesh => {
                self.mesh
                    .prepare(device, queue, scene, camera, settings, &mut stats)?;
                self.mesh
                    .draw(&mut encoder, &self.targets, sky_colour(&settings.raycast));
            }
            TerrainMode::Raycast => {
                self.raycast.prepare(
                    device,
                    queue,
                    scene,
                    camera,
                    settings,
                    objects_drawn,
                    &mut stats,
                )?;
                self.raycast.draw(&mut encoder, &self.targets);
            }
        }
        if let Some(objects) = scene.objects.as_ref().filter(|_| settings.objects) {
            let pass = self
                .objects
                .get_or_insert_with(|| objects::ObjectPass::new(device, objects));
            pass.prepare(device, queue, objects, camera)?;
            pass.draw(&mut encoder, &self.targets);
            stats.object_triangles = objects.triangles();
        }
        if let Some(vegetation) = scene.vegetation.as_mut().filter(|_| settings.objects) {
            let start = Instant::now();
            vegetation.select(camera, settings);
            if settings.mode == TerrainMode::Mesh {
                if let Some(lp) = &scene.lp {
                    let hierarchy = lp.hierarchy();
                    let mesh = GridArrays::new(&hierarchy, scene.terrain.heights());
                    vegetation.stand_on_mesh(&mesh, &scene.terrain, camera, settings);
                } else if let Some(cut) = &scene.mesh_cut {
                    vegetation.stand_on_mesh(cut, &scene.terrain, camera, settings);
                }
            }
            stats.cut_ms = start.elapsed().as_secs_f64() * 1e3;
            let pass = match &mut self.vegetation {
                Some(pass) => pass,
                empty => empty.insert(vegetation::VegetationPass::new(
                    device,
                    queue,
                    &vegetation.clusters,
                )?),
            };
            pass.prepare(device, queue, vegetation, camera, settings)?;
            pass.draw(&mut encoder, &self.targets);
            stats.vegetation_represented = vegetation.list.represented;
            stats.impostors = vegetation.list.len();
            stats.impostor_views = pass.drawn();
        }
        let start = Instant::now();
        self.submitted = Some(queue.submit([encoder.finish()]));
        stats.submit_ms = start.elapsed().as_secs_f64() * 1e3;
        self.drawn = Some((*camera, settings.clone(), objects_key, stats));
        Ok(stats)
    }

    /// The depth of the last frame, row-major, when it was a terrain-only
    /// raycast: exactly the CPU depth buffer (not uploaded for such frames).
    pub fn raycast_depth(&self, scene: &Scene, settings: &Settings) -> Option<Vec<f32>> {
        let objects_drawn = settings.objects && scene.has_objects();
        (settings.mode == TerrainMode::Raycast && settings.terrain && !objects_drawn)
            .then(|| scene.raycaster.frame().depth_rows())
    }
}
