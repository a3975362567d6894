//! The objects pass: relevo-core's object triangles drawn into the shared
//! targets after the terrain, depth-tested against whatever the terrain
//! wrote — the refined mesh's depth or the raycast's uploaded depth.

use super::targets::{Targets, COLOUR_FORMAT, DEPTH_FORMAT};
use super::{eye_relative_view_projection, SUN};
use bytemuck::{Pod, Zeroable};
use eframe::egui_wgpu::wgpu;
use glam::DVec3;
use relevo_core::camera::Camera;
use relevo_core::objects::ObjectMesh;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Vertex {
    /// Terrain-frame position minus the eye, metres.
    position: [f32; 3],
    normal: [f32; 3],
    colour: [u8; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Uniforms {
    view_proj: [[f32; 4]; 4],
    sun: [f32; 4],
}

pub struct ObjectPass {
    pipeline: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    uniforms: wgpu::Buffer,
    vertex_buffer: wgpu::Buffer,
    vertices: Vec<Vertex>,
    count: u32,
}

impl ObjectPass {
    pub fn new(device: &wgpu::Device, objects: &ObjectMesh) -> Self {
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("object uniforms"),
            size: size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("object bindings"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("object bindings"),
            layout: &layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniforms.as_entire_binding(),
            }],
        });
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("objects.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("objects.wgsl").into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("objects"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Unorm8x4];
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("objects"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: size_of::<Vertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &attributes,
                })],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(COLOUR_FORMAT.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let bytes = (objects.positions.len().max(1) * size_of::<Vertex>()) as u64;
        ObjectPass {
            pipeline,
            bind_group,
            uniforms,
            vertex_buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("object vertices"),
                size: bytes,
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            vertices: Vec::with_capacity(objects.positions.len()),
            count: objects.positions.len() as u32,
        }
    }

    /// Upload the objects relative to the eye and the camera's projection.
    pub fn prepare(&mut self, queue: &wgpu::Queue, objects: &ObjectMesh, camera: &Camera) {
        let eye = camera.position;
        self.vertices.clear();
        self.vertices.extend(
            objects
                .positions
                .iter()
                .zip(&objects.normals)
                .zip(&objects.colours)
                .map(|((p, &normal), &colour)| Vertex {
                    position: (DVec3::from_array(*p) - eye).as_vec3().to_array(),
                    normal,
                    colour,
                }),
        );
        queue.write_buffer(&self.vertex_buffer, 0, bytemuck::cast_slice(&self.vertices));
        let uniforms = Uniforms {
            view_proj: eye_relative_view_projection(camera),
            sun: SUN,
        };
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&uniforms));
    }

    /// Draw over the terrain already in the targets.
    pub fn draw(&self, encoder: &mut wgpu::CommandEncoder, targets: &Targets) {
        let mut pass = targets.begin(encoder, None, "objects");
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_vertex_buffer(0, self.vertex_buffer.slice(..));
        pass.draw(0..self.count, 0..1);
    }
}
