//! The offscreen colour and depth targets every mode draws into, and
//! reading them back (headless renders, tests).

use anyhow::{Context, Result};
use eframe::egui_wgpu::wgpu;

/// Colour as stored: RGBA bytes, no sRGB conversion, so the raycaster's
/// and the drape's bytes reach the PNG, and egui's gamma-space image, unchanged.
pub const COLOUR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// Depth in [0, 1] as the off-axis projection writes it.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// A colour and a depth texture of one size.
pub struct Targets {
    pub size: [u32; 2],
    pub colour: wgpu::Texture,
    pub colour_view: wgpu::TextureView,
    pub depth: wgpu::Texture,
    pub depth_view: wgpu::TextureView,
}

/// The targets' contents read back to the CPU.
pub struct Readback {
    /// RGBA8, row-major, top row first.
    pub rgba: Vec<u8>,
    /// [0, 1] depth, row-major, top row first.
    pub depth: Vec<f32>,
}

impl Targets {
    pub fn new(device: &wgpu::Device, size: [u32; 2]) -> Self {
        let extent = wgpu::Extent3d {
            width: size[0].max(1),
            height: size[1].max(1),
            depth_or_array_layers: 1,
        };
        let colour = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("colour target"),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: COLOUR_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let depth = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("depth target"),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        Targets {
            size,
            colour_view: colour.create_view(&wgpu::TextureViewDescriptor::default()),
            depth_view: depth.create_view(&wgpu::TextureViewDescriptor::default()),
            colour,
            depth,
        }
    }

    /// A render pass over both targets, clearing colour to `clear` and
    /// depth to 1 — or keeping what they hold when `clear` is `None`.
    pub fn begin<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        clear: Option<wgpu::Color>,
        label: &str,
    ) -> wgpu::RenderPass<'e> {
        let (colour_load, depth_load) = match clear {
            Some(colour) => (wgpu::LoadOp::Clear(colour), wgpu::LoadOp::Clear(1.0)),
            None => (wgpu::LoadOp::Load, wgpu::LoadOp::Load),
        };
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &self.colour_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: colour_load,
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: depth_load,
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            ..Default::default()
        })
    }

    /// Copy colour and depth back to the CPU (waits for the GPU).
    pub fn read(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Readback> {
        let [w, h] = self.size;
        // Rows of a buffer copy are padded to 256 bytes.
        let row = (w * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer_of = |label| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: row as u64 * h as u64,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            })
        };
        let (colour_buffer, depth_buffer) =
            (buffer_of("colour readback"), buffer_of("depth readback"));
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("readback"),
        });
        let extent = wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        };
        for (texture, buffer, aspect) in [
            (&self.colour, &colour_buffer, wgpu::TextureAspect::All),
            (&self.depth, &depth_buffer, wgpu::TextureAspect::DepthOnly),
        ] {
            encoder.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(row),
                        rows_per_image: Some(h),
                    },
                },
                extent,
            );
        }
        queue.submit([encoder.finish()]);
        for buffer in [&colour_buffer, &depth_buffer] {
            buffer.map_async(wgpu::MapMode::Read, .., |_| {});
        }
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .context("waiting for the GPU to finish the frame")?;
        let unpad = |buffer: &wgpu::Buffer| -> Result<Vec<u8>> {
            let mapped = buffer
                .get_mapped_range(..)
                .context("reading back the frame")?;
            Ok(mapped
                .chunks(row as usize)
                .flat_map(|r| r[..w as usize * 4].iter().copied())
                .collect())
        };
        let rgba = unpad(&colour_buffer)?;
        let depth = unpad(&depth_buffer)?
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        Ok(Readback { rgba, depth })
    }
}
