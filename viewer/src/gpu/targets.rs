//! The offscreen colour and depth targets every mode draws into, and
//! reading them back (headless renders, tests).

use anyhow::{Context, Result};
use eframe::egui_wgpu::wgpu;

/// Colour as stored: RGBA bytes, no sRGB conversion, so the raycaster's
/// and the drape's bytes reach the PNG, and egui's gamma-space image, unchanged.
pub const COLOUR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// Depth in [0, 1] as the off-axis projection writes it.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Largest staging buffer a read-back uses, bytes: larger frames are read
/// back in bands of rows.
const READBACK_BAND_BYTES: u64 = 64 << 20;

/// Bytes a headless frame holds per pixel on the host at its peak, an
/// upper bound of what was measured on lavapipe (docs/reliability.md):
/// colour and depth targets (a software GPU keeps them in host memory),
/// the read-back colour and the PNG being encoded; the depth read back
/// adds its staging copy and values, and the raycast mode relevo-core's
/// CPU frame.
pub fn frame_bytes_per_pixel(raycast: bool, with_depth: bool) -> u64 {
    let targets = 8;
    let colour_read_back = 8;
    let png = 4;
    let depth_read_back = if with_depth { 8 } else { 0 };
    let cpu_frame = if raycast {
        relevo_core::horizon::RaycastFrame::BYTES_PER_PIXEL
    } else {
        0
    };
    targets + colour_read_back + png + depth_read_back + cpu_frame
}

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
    /// [0, 1] depth, row-major, top row first; empty when not read back.
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

    /// Copy the colour, and the depth when asked, back to the CPU (waits
    /// for the GPU). Colour comes in bands of rows whose staging buffer
    /// stays within `READBACK_BAND_BYTES` and the device's buffer limit,
    /// so a frame of any size the GPU can draw is read back at a bounded
    /// staging cost; depth can only be copied whole (a depth texture is
    /// copied as one), and is refused where that exceeds the buffer limit.
    pub fn read(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        with_depth: bool,
    ) -> Result<Readback> {
        let [w, h] = self.size;
        // Rows of a buffer copy are padded to 256 bytes.
        let row = (w * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let largest = device.limits().max_buffer_size;
        let band_rows = (READBACK_BAND_BYTES.min(largest) / u64::from(row))
            .clamp(1, u64::from(h.max(1))) as u32;
        let mut rgba = Vec::with_capacity(w as usize * h as usize * 4);
        let mut top = 0;
        while top < h {
            let rows = band_rows.min(h - top);
            let band = self.read_rows(device, queue, Aspect::Colour, row, top, rows)?;
            rgba.extend_from_slice(&band);
            top += rows;
        }
        let depth = if with_depth {
            if u64::from(row) * u64::from(h) > largest {
                anyhow::bail!(
                    "the depth of a {w}×{h} frame needs a {} buffer, more than this GPU's \
                     largest ({}); render it without its depth or at a smaller size",
                    relevo_core::memory::human(u64::from(row) * u64::from(h)),
                    relevo_core::memory::human(largest)
                );
            }
            self.read_rows(device, queue, Aspect::Depth, row, 0, h)?
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        } else {
            Vec::new()
        };
        Ok(Readback { rgba, depth })
    }

    /// Rows `top..top + rows` of the colour or the depth target, unpadded
    /// bytes (4 a pixel).
    fn read_rows(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        aspect: Aspect,
        row: u32,
        top: u32,
        rows: u32,
    ) -> Result<Vec<u8>> {
        let w = self.size[0];
        let (texture, aspect, label) = match aspect {
            Aspect::Colour => (&self.colour, wgpu::TextureAspect::All, "colour readback"),
            Aspect::Depth => (
                &self.depth,
                wgpu::TextureAspect::DepthOnly,
                "depth readback",
            ),
        };
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: u64::from(row) * u64::from(rows),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d { x: 0, y: top, z: 0 },
                aspect,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(rows),
                },
            },
            wgpu::Extent3d {
                width: w,
                height: rows,
                depth_or_array_layers: 1,
            },
        );
        queue.submit([encoder.finish()]);
        buffer.map_async(wgpu::MapMode::Read, .., |_| {});
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .context("waiting for the GPU to finish the frame")?;
        let mapped = buffer
            .get_mapped_range(..)
            .context("reading back the frame")?;
        Ok(mapped
            .chunks(row as usize)
            .flat_map(|r| r[..w as usize * 4].iter().copied())
            .collect())
    }
}

/// Which target a read-back copies.
#[derive(Clone, Copy)]
enum Aspect {
    Colour,
    Depth,
}
