//! The objects pass: relevo-core's object triangles drawn into the shared
//! targets after the terrain, depth-tested against whatever the terrain
//! wrote — the refined mesh's depth or the raycast's uploaded depth.

use super::shared::{self, eye_relative_view_projection, SUN};
use super::targets::Targets;
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
        // `prepare` grows the vertex buffer to the placement's size.
        let (uniforms, layout, bind_group) =
            shared::uniforms(device, "object uniforms", size_of::<Uniforms>() as u64);
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("objects.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("objects.wgsl").into()),
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Unorm8x4];
        let pipeline = shared::pipeline(
            device,
            "objects",
            &shader,
            &layout,
            Some(wgpu::VertexBufferLayout {
                array_stride: size_of::<Vertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &attributes,
            }),
            wgpu::PrimitiveTopology::TriangleList,
            "fs_main",
            (true, wgpu::CompareFunction::Less),
        );
        ObjectPass {
            pipeline,
            bind_group,
            uniforms,
            vertex_buffer: shared::empty_vertex_buffer(device, "object vertices"),
            vertices: Vec::with_capacity(objects.positions.len()),
            count: objects.positions.len() as u32,
        }
    }

    /// Upload the objects relative to the eye and the camera's projection
    /// (the buffer grows when another placement brings more triangles).
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        objects: &ObjectMesh,
        camera: &Camera,
    ) -> anyhow::Result<()> {
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
        let bytes: &[u8] = bytemuck::cast_slice(&self.vertices);
        shared::grow(
            device,
            &mut self.vertex_buffer,
            "object vertices",
            bytes.len() as u64,
        )?;
        queue.write_buffer(&self.vertex_buffer, 0, bytes);
        self.count = self.vertices.len() as u32;
        let uniforms = Uniforms {
            view_proj: eye_relative_view_projection(camera),
            sun: SUN,
        };
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&uniforms));
        Ok(())
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
