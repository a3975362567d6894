//! Raycast mode: relevo-core's floating-horizon raycast writes colour and
//! depth on the CPU, in column tiles; they are uploaded as they are, one
//! tile per layer of a texture array (depth as `R32Float`, since wgpu
//! cannot write a depth texture directly), and a full-screen pass writes
//! both into the shared targets with `frag_depth`. A terrain-only frame
//! uploads colour alone (Szenberg 1997, table 8.1).

use super::shared::{self, FrameStats};
use super::targets::{Targets, COLOUR_FORMAT};
use crate::scene::Scene;
use crate::settings::Settings;
use eframe::egui_wgpu::wgpu;
use relevo_core::camera::Camera;
use relevo_core::horizon::TILE_COLUMNS;
use relevo_core::pyramid::render::{render_with, LevelOptions};
use std::time::Instant;

/// A pyramid's raycast: a level's cell at most 2 pixels on screen before
/// the next band reads the next coarser level (the raycast's bands are the
/// pyramid's levels; see relevo-core's `pyramid::render`).
const PYRAMID_LEVELS: LevelOptions = LevelOptions {
    max_cell_px: 2.0,
    hillshade: None,
};

pub struct RaycastPass {
    layout: wgpu::BindGroupLayout,
    with_depth: wgpu::RenderPipeline,
    colour_only: wgpu::RenderPipeline,
    /// Upload textures and their bind group, for one size.
    uploads: Option<Uploads>,
    depth_uploaded: bool,
}

struct Uploads {
    size: [u32; 2],
    colour: wgpu::Texture,
    depth: wgpu::Texture,
    bind_group: wgpu::BindGroup,
}

impl RaycastPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let texture_entry = |binding, filterable| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable },
                view_dimension: wgpu::TextureViewDimension::D2Array,
                multisampled: false,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("raycast bindings"),
            entries: &[texture_entry(0, true), texture_entry(1, false)],
        });
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raycast.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("raycast.wgsl").into()),
        });
        let pipeline = |fragment: &str, write_depth: bool| {
            shared::pipeline(
                device,
                fragment,
                &shader,
                &layout,
                None,
                wgpu::PrimitiveTopology::TriangleList,
                fragment,
                (write_depth, wgpu::CompareFunction::Always),
            )
        };
        RaycastPass {
            with_depth: pipeline("fs_colour_and_depth", true),
            colour_only: pipeline("fs_colour", false),
            layout,
            uploads: None,
            depth_uploaded: false,
        }
    }

    /// Raycast for `camera` and upload the colour, and the depth when
    /// objects will be drawn against it. Fails on a pitch the raycaster
    /// does not draw.
    #[allow(clippy::too_many_arguments)]
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &mut Scene,
        camera: &Camera,
        settings: &Settings,
        objects_drawn: bool,
        stats: &mut FrameStats,
    ) -> anyhow::Result<()> {
        let start = Instant::now();
        let frame = match &mut scene.level_windows {
            // A pyramid: each distance band reads its own level.
            Some(windows) => {
                let waited = render_with(
                    &mut scene.raycaster,
                    windows,
                    camera,
                    &settings.raycast,
                    PYRAMID_LEVELS,
                )?;
                stats.level_windows_waited = waited.len();
                scene.raycaster.frame()
            }
            None => scene
                .raycaster
                .render(&scene.terrain, camera, &settings.raycast)?,
        };
        stats.raycast_ms = start.elapsed().as_secs_f64() * 1e3;
        let size = [camera.width, camera.height];
        if self.uploads.as_ref().is_none_or(|u| u.size != size) {
            self.uploads = Some(self.uploads_of(device, size));
        }
        let Some(uploads) = &self.uploads else {
            return Ok(());
        };
        let write = |texture: &wgpu::Texture, bytes: &[u8]| {
            queue.write_texture(
                texture.as_image_copy(),
                bytes,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(4 * TILE_COLUMNS as u32),
                    rows_per_image: Some(size[1]),
                },
                texture.size(),
            );
        };
        let start = Instant::now();
        write(&uploads.colour, bytemuck::cast_slice(&frame.rgba));
        stats.colour_upload_ms = start.elapsed().as_secs_f64() * 1e3;
        self.depth_uploaded = objects_drawn;
        if objects_drawn {
            let start = Instant::now();
            write(&uploads.depth, bytemuck::cast_slice(&frame.depth));
            stats.depth_upload_ms = start.elapsed().as_secs_f64() * 1e3;
        }
        Ok(())
    }

    /// Write the uploaded raycast into the targets.
    pub fn draw(&self, encoder: &mut wgpu::CommandEncoder, targets: &Targets) {
        let Some(uploads) = &self.uploads else {
            return;
        };
        let mut pass = targets.begin(encoder, Some(wgpu::Color::BLACK), "raycast composite");
        pass.set_pipeline(if self.depth_uploaded {
            &self.with_depth
        } else {
            &self.colour_only
        });
        pass.set_bind_group(0, &uploads.bind_group, &[]);
        pass.draw(0..3, 0..1);
    }

    fn uploads_of(&self, device: &wgpu::Device, size: [u32; 2]) -> Uploads {
        let texture = |label, format| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: TILE_COLUMNS as u32,
                    height: size[1],
                    depth_or_array_layers: size[0].div_ceil(TILE_COLUMNS as u32),
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        };
        let colour = texture("raycast colour", COLOUR_FORMAT);
        let depth = texture("raycast depth", wgpu::TextureFormat::R32Float);
        let view = |t: &wgpu::Texture| {
            // An array even of one tile (the default view of one layer is 2D).
            t.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            })
        };
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("raycast bindings"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&view(&colour)),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&view(&depth)),
                },
            ],
        });
        Uploads {
            size,
            colour,
            depth,
            bind_group,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::TILE_COLUMNS;

    /// The shader splits pixels into tiles with the raycaster's tile width.
    #[test]
    fn the_shader_reads_the_raycasters_tiles() {
        let declared = format!("const TILE_COLUMNS: u32 = {TILE_COLUMNS}u;");
        assert!(include_str!("raycast.wgsl").contains(&declared));
    }
}
