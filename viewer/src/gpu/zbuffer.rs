//! Z-buffer mode: relevo-core's baseline representations [a]–[g] of the
//! whole grid (Szenberg 1997, ch. 3, table 3.1), uploaded once per
//! representation and drawn by the rasterizer with its depth test.

use super::shared::{self, FrameStats};
use super::targets::Targets;
use crate::scene::Scene;
use anyhow::{Context, Result};
use bytemuck::{Pod, Zeroable};
use eframe::egui_wgpu::wgpu;
use glam::DVec3;
use relevo_core::camera::Camera;
use relevo_core::zbuffer::{self, Primitive, Representation};

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Vertex {
    position: [f32; 3],
    colour: [u8; 4],
}

/// The uploaded geometry of one representation.
struct Uploaded {
    representation: Representation,
    origin: DVec3,
    vertex_buffer: wgpu::Buffer,
    vertices: u32,
    primitives: usize,
}

pub struct ZBufferPass {
    points: wgpu::RenderPipeline,
    lines: wgpu::RenderPipeline,
    triangles: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    uniforms: wgpu::Buffer,
    uploaded: Option<Uploaded>,
}

impl ZBufferPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let (uniforms, layout, bind_group) = shared::uniforms(device, "z-buffer uniforms", 64);
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("zbuffer.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("zbuffer.wgsl").into()),
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Unorm8x4];
        let pipeline = |topology| {
            shared::pipeline(
                device,
                "z-buffer",
                &shader,
                &layout,
                Some(wgpu::VertexBufferLayout {
                    array_stride: size_of::<Vertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &attributes,
                }),
                topology,
                "fs_main",
                (true, wgpu::CompareFunction::Less),
            )
        };
        ZBufferPass {
            points: pipeline(wgpu::PrimitiveTopology::PointList),
            lines: pipeline(wgpu::PrimitiveTopology::LineList),
            triangles: pipeline(wgpu::PrimitiveTopology::TriangleList),
            bind_group,
            uniforms,
            uploaded: None,
        }
    }

    /// Build and upload `representation` (once) and the camera.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        camera: &Camera,
        representation: Representation,
        stats: &mut FrameStats,
    ) -> Result<()> {
        if self
            .uploaded
            .as_ref()
            .is_none_or(|u| u.representation != representation)
        {
            let f = &scene.frame;
            let colour = |i: usize| {
                let (x, y) = f.terrain_from_vertex((i % f.side) as f64, (i / f.side) as f64);
                scene.terrain.color(x, y, false, 0).to_le_bytes()
            };
            let mesh = zbuffer::build(
                representation,
                scene.terrain.heights(),
                scene.terrain.mask(),
                f.side,
                f.cell_size_m,
                &colour,
            )
            .with_context(|| {
                format!(
                    "the Z-buffer baselines are built for grids up to {} vertices",
                    zbuffer::MAX_VERTICES
                )
            })?;
            let vertices: Vec<Vertex> = mesh
                .positions
                .iter()
                .zip(&mesh.colours)
                .map(|(&position, &colour)| Vertex { position, colour })
                .collect();
            let bytes = (vertices.len() * size_of::<Vertex>()) as u64;
            let vertex_buffer = shared::vertex_buffer(device, "z-buffer vertices", bytes, 0)?;
            queue.write_buffer(&vertex_buffer, 0, bytemuck::cast_slice(&vertices));
            self.uploaded = Some(Uploaded {
                representation,
                origin: DVec3::from_array(mesh.origin),
                vertex_buffer,
                vertices: vertices.len() as u32,
                primitives: mesh.primitives(),
            });
        }
        let Some(uploaded) = &self.uploaded else {
            return Ok(());
        };
        let mut relative = *camera;
        relative.position -= uploaded.origin;
        let view_proj = relative.view_projection().as_mat4().to_cols_array_2d();
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&view_proj));
        stats.triangles = uploaded.primitives;
        Ok(())
    }

    /// Clear to the sky and draw the representation.
    pub fn draw(&self, encoder: &mut wgpu::CommandEncoder, targets: &Targets, sky: wgpu::Color) {
        let Some(uploaded) = &self.uploaded else {
            return;
        };
        let mut pass = targets.begin(encoder, Some(sky), "z-buffer");
        pass.set_pipeline(match uploaded.representation.primitive() {
            Primitive::Points => &self.points,
            Primitive::Lines => &self.lines,
            Primitive::Triangles => &self.triangles,
        });
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_vertex_buffer(0, uploaded.vertex_buffer.slice(..));
        pass.draw(0..uploaded.vertices, 0..1);
    }
}
