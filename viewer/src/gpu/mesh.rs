//! Mesh mode: relevo-core's view-dependent refinement each frame, drawn as
//! triangles with the drape as a mip-mapped texture. Triangles touching
//! padding or voids (mask 0) are not drawn. The vertex buffer grows to the
//! largest frame seen and is reused; nothing else is allocated per frame.

use super::shared::{self, eye_relative_view_projection, FrameStats, SUN};
use super::targets::{Targets, COLOUR_FORMAT};
use crate::scene::Scene;
use crate::settings::Settings;
use anyhow::Context;
use bytemuck::{Pod, Zeroable};
use eframe::egui_wgpu::wgpu;
use glam::DVec3;
use relevo_core::camera::Camera;
use relevo_core::grid::vertex_normal;
use relevo_core::lp::terrain_position;
use std::time::Instant;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Vertex {
    /// Terrain-frame position minus the eye, metres.
    position: [f32; 3],
    uv: [f32; 2],
    normal: [f32; 3],
    barycentric: [f32; 3],
    /// Height above the datum, metres (the height ramp).
    height: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Uniforms {
    view_proj: [[f32; 4]; 4],
    sun: [f32; 4],
    options: [f32; 4],
}

pub struct MeshPass {
    pipeline: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    uniforms: wgpu::Buffer,
    vertex_buffer: wgpu::Buffer,
    /// Vertices of the current frame, reused.
    vertices: Vec<Vertex>,
    vertex_count: u32,
    has_drape: bool,
}

impl MeshPass {
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, scene: &Scene) -> Self {
        let (drape_view, has_drape) = match &scene.drape {
            Some(d) => (
                upload_mipmapped(device, queue, d.width, d.height, &d.rgba),
                true,
            ),
            None => (upload_mipmapped(device, queue, 1, 1, &[255; 4]), false),
        };
        let sampler = shared::mipmap_sampler(device, "drape sampler");
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("mesh uniforms"),
            size: size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout =
            shared::textured_layout(device, "mesh bindings", wgpu::TextureViewDimension::D2);
        let bind_group = shared::textured_bind_group(
            device,
            "mesh bindings",
            &layout,
            &uniforms,
            &drape_view,
            &sampler,
        );
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("mesh.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("mesh.wgsl").into()),
        });
        let attributes = wgpu::vertex_attr_array![
            0 => Float32x3, 1 => Float32x2, 2 => Float32x3, 3 => Float32x3, 4 => Float32
        ];
        let pipeline = shared::pipeline(
            device,
            "mesh",
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
        MeshPass {
            pipeline,
            bind_group,
            uniforms,
            vertex_buffer: shared::empty_vertex_buffer(device, "mesh vertices"),
            vertices: Vec::new(),
            vertex_count: 0,
            has_drape,
        }
    }

    /// Refine for `camera` and upload the frame's triangles and uniforms.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &mut Scene,
        camera: &Camera,
        settings: &Settings,
        stats: &mut FrameStats,
    ) -> anyhow::Result<()> {
        let start = Instant::now();
        let params = settings.refine_params(camera);
        let hierarchy = scene.lp.hierarchy();
        let strip = scene
            .refiner
            .refine(&hierarchy, scene.terrain.heights(), &params);
        stats.refine_ms = start.elapsed().as_secs_f64() * 1e3;

        let start = Instant::now();
        let frame = &scene.frame;
        let (side, cell) = (frame.side, frame.cell_size_m);
        let eye = camera.position;
        let uv_of = |x: f64, y: f64| match &scene.drape {
            Some(d) => {
                let t = &d.terrain_to_uv;
                [
                    (t[0] + t[1] * x + t[2] * y) as f32,
                    (t[3] + t[4] * x + t[5] * y) as f32,
                ]
            }
            None => [0.0, 0.0],
        };
        let (heights, mask) = (scene.terrain.heights(), scene.terrain.mask());
        let barycentric = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        self.vertices.clear();
        for entries in strip.triangle_entries() {
            let index = entries.map(|e| strip.indices[e] as usize);
            if index.iter().any(|&i| mask[i] == 0) {
                continue;
            }
            for (k, (&e, &i)) in entries.iter().zip(&index).enumerate() {
                let (c, r) = (i % side, i / side);
                let z = strip
                    .morphed_z
                    .get(e)
                    .map_or(heights[i] as f64, |&z| z as f64);
                let p = DVec3::from_array(terrain_position(c, r, side, cell, z));
                let n = vertex_normal(heights, side, cell, c, r);
                self.vertices.push(Vertex {
                    position: (p - eye).as_vec3().to_array(),
                    uv: uv_of(p.x, p.y),
                    normal: n.map(|v| v as f32),
                    barycentric: barycentric[k],
                    height: z as f32,
                });
            }
        }
        let bytes: &[u8] = bytemuck::cast_slice(&self.vertices);
        shared::grow(
            device,
            &mut self.vertex_buffer,
            "mesh vertices",
            bytes.len() as u64,
        )
        .with_context(|| format!("at τ = {} px (raise it to draw fewer)", settings.tau_px))?;
        queue.write_buffer(&self.vertex_buffer, 0, bytes);
        self.vertex_count = self.vertices.len() as u32;
        stats.triangles = self.vertices.len() / 3;

        let [lo, hi] = scene.bundle.manifest.grid.height_range_m;
        let uniforms = Uniforms {
            view_proj: eye_relative_view_projection(camera),
            sun: SUN,
            options: [
                f32::from(u8::from(settings.texture && self.has_drape)),
                f32::from(u8::from(settings.wireframe)),
                lo,
                1.0 / (hi - lo).max(1.0),
            ],
        };
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&uniforms));
        stats.mesh_upload_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(())
    }

    /// Clear to the sky and draw the prepared triangles.
    pub fn draw(&self, encoder: &mut wgpu::CommandEncoder, targets: &Targets, sky: wgpu::Color) {
        let mut pass = targets.begin(encoder, Some(sky), "mesh");
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_vertex_buffer(0, self.vertex_buffer.slice(..));
        pass.draw(0..self.vertex_count, 0..1);
    }
}

/// An RGBA8 texture with its full mip chain, each level the 2×2 mean of
/// the one above (sizes halve rounding down, as wgpu's levels do). Levels
/// larger than the device's textures are made but not uploaded: the
/// texture starts at the first level that fits (its UVs are the same).
fn upload_mipmapped(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    width: u32,
    height: u32,
    rgba: &[u8],
) -> wgpu::TextureView {
    let largest = device.limits().max_texture_dimension_2d;
    let mut level = rgba.to_vec();
    let (mut w, mut h) = (width, height);
    while w.max(h) > largest {
        (level, w, h) = halved(&level, w, h);
    }
    let levels = 32 - w.max(h).leading_zeros();
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("drape"),
        size: wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
        mip_level_count: levels,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: COLOUR_FORMAT,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for mip in 0..levels {
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: mip,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &level,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * w),
                rows_per_image: Some(h),
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
        (level, w, h) = halved(&level, w, h);
    }
    texture.create_view(&wgpu::TextureViewDescriptor::default())
}

/// The next mip level of a `w`×`h` RGBA8 image: each texel the rounded
/// mean of the 2×2 above it (edges repeat), sides halved rounding down.
fn halved(level: &[u8], w: u32, h: u32) -> (Vec<u8>, u32, u32) {
    let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
    let texel = |x: u32, y: u32| {
        let i = ((y.min(h - 1) * w + x.min(w - 1)) * 4) as usize;
        [level[i], level[i + 1], level[i + 2], level[i + 3]]
    };
    let mut next = Vec::with_capacity((nw * nh * 4) as usize);
    for y in 0..nh {
        for x in 0..nw {
            let quad = [
                texel(2 * x, 2 * y),
                texel(2 * x + 1, 2 * y),
                texel(2 * x, 2 * y + 1),
                texel(2 * x + 1, 2 * y + 1),
            ];
            for c in 0..4 {
                let sum: u32 = quad.iter().map(|t| u32::from(t[c])).sum();
                next.push(((sum + 2) / 4) as u8);
            }
        }
    }
    (next, nw, nh)
}
