//! The GPU side of the viewer: one offscreen colour + depth target that
//! every mode draws into, so the window and the headless renders share the
//! same code. The terrain comes from relevo-core either as the refined mesh
//! (`mesh`) or as the CPU raycast composited with its depth (`raycast`).

mod mesh;
mod objects;
mod raycast;
mod targets;
mod vegetation;
mod zbuffer;

pub use targets::{Readback, Targets, COLOUR_FORMAT, DEPTH_FORMAT};

use crate::scene::Scene;
use crate::settings::{Settings, TerrainMode};
use eframe::egui_wgpu::wgpu;

use relevo_core::camera::Camera;
use relevo_core::horizon::RenderOptions;
use serde::Serialize;
use std::time::Instant;
/// The GPU device and queue types the viewer draws with.
pub use wgpu::{Device, Queue};

/// The sun that shades the height ramp and the objects: azimuth 315°,
/// elevation 45° (a unit vector in the terrain frame), 35 % ambient light.
const SUN: [f32; 4] = [-0.5, 0.5, std::f32::consts::FRAC_1_SQRT_2, 0.35];

/// The camera's view-projection with the eye at the origin: vertices are
/// uploaded relative to the eye, so f32 keeps centimetres at any distance
/// from the terrain frame's origin.
fn eye_relative_view_projection(camera: &Camera) -> [[f32; 4]; 4] {
    let mut at_origin = *camera;
    at_origin.position = glam::DVec3::ZERO;
    at_origin.view_projection().as_mat4().to_cols_array_2d()
}

/// A render pipeline over the shared targets: `shader`'s `vs_main` and
/// `fs_main` (or `fragment`), depth-tested with `depth_compare`.
#[allow(clippy::too_many_arguments)]
fn pipeline(
    device: &Device,
    label: &str,
    shader: &wgpu::ShaderModule,
    layout: &wgpu::BindGroupLayout,
    vertices: Option<wgpu::VertexBufferLayout<'_>>,
    topology: wgpu::PrimitiveTopology,
    fragment: &str,
    depth: (bool, wgpu::CompareFunction),
) -> wgpu::RenderPipeline {
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module: shader,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[vertices],
        },
        primitive: wgpu::PrimitiveState {
            topology,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(depth.0),
            depth_compare: Some(depth.1),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: shader,
            entry_point: Some(fragment),
            compilation_options: Default::default(),
            targets: &[Some(COLOUR_FORMAT.into())],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A uniform buffer of `size` bytes, its one-binding layout and bind group.
fn uniforms(
    device: &Device,
    label: &str,
    size: u64,
) -> (wgpu::Buffer, wgpu::BindGroupLayout, wgpu::BindGroup) {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &[uniform_entry()],
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: &layout,
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: buffer.as_entire_binding(),
        }],
    });
    (buffer, layout, bind_group)
}

/// A sampler for mip-mapped textures: bilinear within a level, linear
/// between levels, edges clamped.
fn mipmap_sampler(device: &Device, label: &str) -> wgpu::Sampler {
    device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some(label),
        address_mode_u: wgpu::AddressMode::ClampToEdge,
        address_mode_v: wgpu::AddressMode::ClampToEdge,
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        mipmap_filter: wgpu::MipmapFilterMode::Linear,
        ..Default::default()
    })
}

/// The bindings of a textured pass: 0 the uniforms, 1 a filterable texture
/// of `dimension`, 2 its sampler (fragment stage).
fn textured_layout(
    device: &Device,
    label: &str,
    dimension: wgpu::TextureViewDimension,
) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &[
            uniform_entry(),
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: dimension,
                    multisampled: false,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 2,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ],
    })
}

/// A bind group of [`textured_layout`].
fn textured_bind_group(
    device: &Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    uniforms: &wgpu::Buffer,
    texture: &wgpu::TextureView,
    sampler: &wgpu::Sampler,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: uniforms.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::TextureView(texture),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::Sampler(sampler),
            },
        ],
    })
}

/// Binding 0: a uniform buffer seen by both stages.
fn uniform_entry() -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding: 0,
        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A vertex buffer of at least `bytes` (grown by the caller, never per frame).
fn vertex_buffer(device: &Device, label: &str, bytes: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(4),
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// What one frame cost and drew (the HUD's numbers; `--stats` writes them).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct FrameStats {
    pub width: u32,
    pub height: u32,
    /// Terrain triangles submitted to the GPU (points or segments for the
    /// baselines that draw those).
    pub triangles: usize,
    /// Object triangles submitted to the GPU.
    pub object_triangles: usize,
    /// Vegetation objects the impostors stand for, and the impostors drawn
    /// (quadtree clusters and single objects; a view cross-fading into
    /// another counts twice in `impostor_views`).
    pub vegetation_represented: usize,
    pub impostors: usize,
    pub impostor_views: usize,
    /// relevo-core's cut, milliseconds.
    pub cut_ms: f64,
    /// Refinement (mesh mode), milliseconds.
    pub refine_ms: f64,
    /// Building and uploading the vertex buffer (mesh mode).
    pub mesh_upload_ms: f64,
    /// The CPU raycast (raycast mode).
    pub raycast_ms: f64,
    /// Uploading the raycast colour.
    pub colour_upload_ms: f64,
    /// Uploading the raycast depth (skipped for terrain-only frames).
    pub depth_upload_ms: f64,
    /// Recording and submitting the GPU work.
    pub submit_ms: f64,
}

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
        }
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
        if let Some((c, s, o, stats)) = &self.drawn {
            if c == camera && s == settings && *o == objects_key {
                return Ok(*stats);
            }
        }
        let size = [camera.width, camera.height];
        if self.targets.size != size {
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
                    .prepare(device, queue, scene, camera, settings, &mut stats);
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
            pass.prepare(device, queue, objects, camera);
            pass.draw(&mut encoder, &self.targets);
            stats.object_triangles = objects.triangles();
        }
        if let Some(vegetation) = scene.vegetation.as_mut().filter(|_| settings.objects) {
            let start = Instant::now();
            vegetation.select(camera, settings);
            if settings.mode == TerrainMode::Mesh {
                vegetation.stand_on_mesh(&scene.lp, &scene.terrain, camera, settings);
            }
            stats.cut_ms = start.elapsed().as_secs_f64() * 1e3;
            let pass = self.vegetation.get_or_insert_with(|| {
                vegetation::VegetationPass::new(device, queue, &vegetation.clusters)
            });
            pass.prepare(device, queue, vegetation, camera, settings);
            pass.draw(&mut encoder, &self.targets);
            stats.vegetation_represented = vegetation.list.represented;
            stats.impostors = vegetation.list.len();
            stats.impostor_views = pass.drawn();
        }
        let start = Instant::now();
        queue.submit([encoder.finish()]);
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
