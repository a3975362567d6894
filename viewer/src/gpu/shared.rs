//! What the passes share: the sun, the eye-relative projection, builders of
//! pipelines, bind groups, samplers and buffers over the shared targets,
//! and the figures of a frame.

use super::targets::{COLOUR_FORMAT, DEPTH_FORMAT};
use eframe::egui_wgpu::wgpu;
use relevo_core::camera::Camera;
use serde::Serialize;
use wgpu::Device;

/// The sun that shades the height ramp and the objects: azimuth 315°,
/// elevation 45° (a unit vector in the terrain frame), 35 % ambient light.
pub(super) const SUN: [f32; 4] = [-0.5, 0.5, std::f32::consts::FRAC_1_SQRT_2, 0.35];

/// The camera's view-projection with the eye at the origin: vertices are
/// uploaded relative to the eye, so f32 keeps centimetres at any distance
/// from the terrain frame's origin.
pub(super) fn eye_relative_view_projection(camera: &Camera) -> [[f32; 4]; 4] {
    let mut at_origin = *camera;
    at_origin.position = glam::DVec3::ZERO;
    at_origin.view_projection().as_mat4().to_cols_array_2d()
}

/// A render pipeline over the shared targets: `shader`'s `vs_main` and
/// `fs_main` (or `fragment`), depth-tested with `depth_compare`.
#[allow(clippy::too_many_arguments)]
pub(super) fn pipeline(
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
pub(super) fn uniforms(
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
pub(super) fn mipmap_sampler(device: &Device, label: &str) -> wgpu::Sampler {
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
pub(super) fn textured_layout(
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
pub(super) fn textured_bind_group(
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
pub(super) fn uniform_entry() -> wgpu::BindGroupLayoutEntry {
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

/// A vertex buffer of at least `bytes`, `spare` more when the device
/// allows (callers grow it to the next power of two so that it is not
/// remade every frame). Refused, naming `label`, when `bytes` exceed the
/// device's largest buffer.
pub(super) fn vertex_buffer(
    device: &Device,
    label: &str,
    bytes: u64,
    spare: u64,
) -> anyhow::Result<wgpu::Buffer> {
    let largest = device.limits().max_buffer_size;
    if bytes > largest {
        anyhow::bail!(
            "the {label} need {} but this GPU's largest buffer is {}",
            relevo_core::memory::human(bytes),
            relevo_core::memory::human(largest)
        );
    }
    Ok(buffer_of(
        device,
        label,
        bytes.saturating_add(spare).min(largest),
    ))
}

/// Make room for `needed` bytes in `buffer`: when they do not fit, it is
/// replaced by one grown to the next power of two (within the device's
/// limit), so that a pass's buffer is not remade every frame.
pub(super) fn grow(
    device: &Device,
    buffer: &mut wgpu::Buffer,
    label: &str,
    needed: u64,
) -> anyhow::Result<()> {
    if needed > buffer.size() {
        *buffer = vertex_buffer(device, label, needed, needed.next_power_of_two() - needed)?;
    }
    Ok(())
}

/// A vertex buffer of a few bytes, for a pass to grow with [`grow`] when
/// it has something to draw.
pub(super) fn empty_vertex_buffer(device: &Device, label: &str) -> wgpu::Buffer {
    buffer_of(device, label, 4)
}

fn buffer_of(device: &Device, label: &str, bytes: u64) -> wgpu::Buffer {
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
    /// A pyramid's paging after this frame (mesh mode).
    pub paging: Option<relevo_core::pyramid::paging::PagingStats>,
    /// Tiles' drapes uploaded to the GPU this frame.
    pub tile_uploads: u32,
    /// A pyramid's raycast: level windows this frame waited for (the rest
    /// were held, or read ahead beside the frames).
    pub level_windows_waited: usize,
}
