//! The vegetation pass: the bundle's impostor atlases as one mip-mapped
//! texture array, and per frame one GPU instance per view of each
//! instance of relevo-core's quadtree cut, drawn after the terrain and
//! depth-tested against it. The instance buffer is reused across frames.

use super::shared::{self, eye_relative_view_projection};
use super::targets::Targets;
use super::targets::COLOUR_FORMAT;
use crate::scene::Vegetation;
use crate::settings::Settings;
use bytemuck::{Pod, Zeroable};
use eframe::egui_wgpu::wgpu;
use relevo_core::camera::Camera;
use relevo_core::cluster::bake::MIP_LEVELS;
use relevo_core::cluster::cut::ViewDraw;
use relevo_core::cluster::views::ImpostorView;
use relevo_core::cluster::Clusters;

/// One view of one impostor, as the shader reads it.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GpuImpostor {
    /// Foot relative to the eye, metres.
    foot: [f32; 3],
    /// 0: side view (billboard), 1: top view (shell texture), 2 and 3:
    /// sprite planes along x (front view) and along y (left view).
    kind: u32,
    facing: [f32; 2],
    size: [f32; 2],
    top: f32,
    /// The pixels' dither thresholds this view takes: [from, to).
    share: [f32; 2],
    uv: [f32; 4],
    page: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Uniforms {
    view_proj: [[f32; 4]; 4],
    /// x: 1 when impostors are cut out by their alpha.
    flags: [u32; 4],
}

pub struct VegetationPass {
    pipeline: wgpu::RenderPipeline,
    /// Bindings with the filtered, mip-mapped sampler and with the nearest
    /// texel of level 0.
    bind_group: wgpu::BindGroup,
    sharp_bind_group: wgpu::BindGroup,
    uniforms: wgpu::Buffer,
    instance_buffer: wgpu::Buffer,
    instances: Vec<GpuImpostor>,
    /// Sample with the filtered sampler (else the nearest texel).
    blur: bool,
    /// Texels of the atlas array's level 0 (pages are padded to it).
    atlas_size: [f32; 2],
}

impl VegetationPass {
    /// The pipeline and the atlas uploaded; refused when the atlas does not
    /// fit the device's texture limits.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        clusters: &Clusters,
    ) -> anyhow::Result<Self> {
        let (atlas, atlas_size) = upload_atlas(device, queue, clusters)?;
        let sampler = shared::mipmap_sampler(device, "impostor sampler");
        let sharp_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("impostor sampler, nearest"),
            lod_max_clamp: 0.0,
            ..Default::default()
        });
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vegetation uniforms"),
            size: size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = shared::textured_layout(
            device,
            "vegetation bindings",
            wgpu::TextureViewDimension::D2Array,
        );
        let bind = |sampler: &wgpu::Sampler| {
            shared::textured_bind_group(
                device,
                "vegetation bindings",
                &layout,
                &uniforms,
                &atlas,
                sampler,
            )
        };
        let (bind_group, sharp_bind_group) = (bind(&sampler), bind(&sharp_sampler));
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("vegetation.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("vegetation.wgsl").into()),
        });
        let attributes = wgpu::vertex_attr_array![
            0 => Float32x3, 1 => Uint32, 2 => Float32x2, 3 => Float32x2,
            4 => Float32, 5 => Float32x2, 6 => Float32x4, 7 => Uint32
        ];
        let pipeline = shared::pipeline(
            device,
            "vegetation",
            &shader,
            &layout,
            Some(wgpu::VertexBufferLayout {
                array_stride: size_of::<GpuImpostor>() as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &attributes,
            }),
            wgpu::PrimitiveTopology::TriangleStrip,
            "fs_main",
            (true, wgpu::CompareFunction::Less),
        );
        Ok(VegetationPass {
            pipeline,
            bind_group,
            sharp_bind_group,
            uniforms,
            instance_buffer: shared::empty_vertex_buffer(device, "impostors"),
            instances: Vec::new(),
            blur: true,
            atlas_size,
        })
    }

    /// Upload one GPU instance per view of every instance the selection
    /// left in `vegetation.list`, relative to the eye (with sprites, the
    /// side views become the two crossed planes); the buffer grows when a
    /// frame needs more, never shrinks.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        vegetation: &Vegetation,
        camera: &Camera,
        settings: &Settings,
    ) -> anyhow::Result<()> {
        let eye = camera.position;
        let [tw, th] = self.atlas_size;
        let clusters = &vegetation.clusters;
        self.instances.clear();
        for instance in vegetation.list.instances() {
            let foot = [
                (instance.foot[0] as f64 - eye.x) as f32,
                (instance.foot[1] as f64 - eye.y) as f32,
                (instance.foot[2] as f64 - eye.z) as f32,
            ];
            let impostor = |view: &ViewDraw, kind: u32, share: [f32; 2]| {
                let f = view.frame;
                GpuImpostor {
                    foot,
                    kind,
                    facing: instance.facing,
                    size: view.size,
                    top: instance.top_m,
                    share,
                    uv: [
                        f.x as f32 / tw,
                        f.y as f32 / th,
                        (f.x + f.width) as f32 / tw,
                        (f.y + f.height) as f32 / th,
                    ],
                    page: f.page as u32,
                }
            };
            // The views split the instance's share by their weights.
            let [mut from, end] = instance.share;
            let views = instance.views();
            for (k, view) in views.iter().enumerate() {
                // The last view takes the rounding of the weights.
                let to = if k + 1 == views.len() {
                    end
                } else {
                    from + view.weight * (instance.share[1] - instance.share[0])
                };
                if view.view == ImpostorView::Top {
                    self.instances.push(impostor(view, 1, [from, to]));
                } else if !settings.sprites {
                    self.instances.push(impostor(view, 0, [from, to]));
                } else if k == 0 || views[k - 1].view == ImpostorView::Top {
                    // Sprites: the side share goes to the two crossed planes.
                    let share = [from, end];
                    for (kind, plane) in [(2, ImpostorView::Front), (3, ImpostorView::Left)] {
                        let plane_view = clusters.view_of(instance.drawn, plane);
                        self.instances.push(impostor(&plane_view, kind, share));
                    }
                }
                from = to;
            }
        }
        let bytes: &[u8] = bytemuck::cast_slice(&self.instances);
        shared::grow(
            device,
            &mut self.instance_buffer,
            "impostors",
            bytes.len() as u64,
        )?;
        queue.write_buffer(&self.instance_buffer, 0, bytes);
        let uniforms = Uniforms {
            view_proj: eye_relative_view_projection(camera),
            flags: [settings.alpha as u32, 0, 0, 0],
        };
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&uniforms));
        self.blur = settings.blur;
        Ok(())
    }

    /// GPU instances of the last frame (views, not objects).
    pub fn drawn(&self) -> usize {
        self.instances.len()
    }

    /// Draw over the terrain already in the targets.
    pub fn draw(&self, encoder: &mut wgpu::CommandEncoder, targets: &Targets) {
        if self.instances.is_empty() {
            return;
        }
        let mut pass = targets.begin(encoder, None, "vegetation");
        pass.set_pipeline(&self.pipeline);
        let bindings = if self.blur {
            &self.bind_group
        } else {
            &self.sharp_bind_group
        };
        pass.set_bind_group(0, bindings, &[]);
        pass.set_vertex_buffer(0, self.instance_buffer.slice(..));
        pass.draw(0..4, 0..self.instances.len() as u32);
    }
}

/// The atlas pages as one texture array (pages padded to the largest),
/// each layer with relevo-core's premultiplied mip chain; refused when
/// the pages are larger, or more, than the device's textures hold.
fn upload_atlas(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    clusters: &Clusters,
) -> anyhow::Result<(wgpu::TextureView, [f32; 2])> {
    let width = clusters
        .pages
        .iter()
        .map(|p| p.width)
        .max()
        .unwrap_or(1)
        .max(1) as u32;
    let height = clusters
        .pages
        .iter()
        .map(|p| p.height)
        .max()
        .unwrap_or(1)
        .max(1) as u32;
    let layers = clusters.pages.len().max(1) as u32;
    let limits = device.limits();
    if width.max(height) > limits.max_texture_dimension_2d
        || layers > limits.max_texture_array_layers
    {
        anyhow::bail!(
            "the vegetation atlas has {layers} page(s) of up to {width}×{height} texels, \
             but this GPU's texture arrays hold at most {} layers of {} texels a side \
             (bake with a smaller --budget-mib)",
            limits.max_texture_array_layers,
            limits.max_texture_dimension_2d
        );
    }
    let levels = (MIP_LEVELS as u32).min(32 - width.min(height).leading_zeros());
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("impostor atlas"),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: layers,
        },
        mip_level_count: levels,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: COLOUR_FORMAT,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for (layer, page) in clusters.pages.iter().enumerate() {
        for (mip, image) in page.mip_chain(levels as usize).iter().enumerate() {
            queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &texture,
                    mip_level: mip as u32,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: layer as u32,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                image.bytes(),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(4 * image.width as u32),
                    rows_per_image: Some(image.height as u32),
                },
                wgpu::Extent3d {
                    width: image.width as u32,
                    height: image.height as u32,
                    depth_or_array_layers: 1,
                },
            );
        }
    }
    let view = texture.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    });
    Ok((view, [width as f32, height as f32]))
}
