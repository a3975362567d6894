//! Mesh mode: relevo-core's view-dependent refinement each frame, drawn as
//! triangles with the drape as a mip-mapped texture. Triangles touching
//! padding or voids (mask 0) are not drawn. The vertex buffer grows to the
//! largest frame seen and is reused; nothing else is allocated per frame.
//!
//! A pyramid is refined through the cut core's `PagedPyramid` gives for
//! the frame (never waiting for a tile), and each triangle is textured
//! from the drape of the smallest tile of the cut holding it: tiles' drapes
//! are layers of one texture array, the least recently used replaced, a
//! few uploaded a frame; until a tile's layer is there its parent's is
//! used (the top tile's always is).

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
use relevo_core::lp::refine::VertexSource;
use relevo_core::lp::terrain_position;
use relevo_core::pyramid::paging::{Cut, CutSample};
use relevo_core::pyramid::{TileKey, TileLayout};
use std::collections::HashMap;
use std::time::Instant;

/// Tiles' drapes uploaded a frame at most: a frame's upload stays short.
const TILE_UPLOADS_PER_FRAME: u32 = 8;

/// GPU memory the tiles' drape layers may take, bytes.
const TILE_TEXTURE_BYTES: u64 = 256 << 20;

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
    /// The drape's layer in the texture array.
    layer: u32,
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
    /// What the mesh draws at each entry of the frame's strip, read once
    /// (neighbouring triangles of a strip share two entries); reused.
    entries: Vec<Option<CutSample>>,
    /// When building this frame's vertices began.
    upload_started: Instant,
    vertex_count: u32,
    has_drape: bool,
    /// A pyramid's tile drapes.
    tiles: Option<TileTextures>,
    /// Wait for every tile a frame needs (headless renders) instead of
    /// drawing what has arrived.
    pub settle: bool,
}

/// A pyramid's tile drapes as layers of one texture array.
struct TileTextures {
    texture: wgpu::Texture,
    layout: TileLayout,
    /// Each uploaded tile's layer and the last frame it was used.
    slots: HashMap<TileKey, (u32, u64)>,
    layers: u32,
    frame: u64,
    uploads: u32,
    /// Upload every tile a frame asks for (a settled frame).
    unlimited: bool,
}

impl TileTextures {
    /// The layer a triangle in `key` is textured from and the tile it
    /// holds: `key`'s, uploaded now if this frame's uploads allow, else its
    /// nearest ancestor's that is there.
    fn layer_for(&mut self, queue: &wgpu::Queue, cut: &Cut, mut key: TileKey) -> (TileKey, u32) {
        loop {
            if let Some(slot) = self.slots.get_mut(&key) {
                slot.1 = self.frame;
                return (key, slot.0);
            }
            if self.unlimited || self.uploads < TILE_UPLOADS_PER_FRAME {
                if let (Some(tile), Some(layer)) = (cut.tile(key), self.free_layer()) {
                    let side = self.layout.samples() as u32;
                    write_layer(queue, &self.texture, layer, side, side, &tile.drape);
                    self.slots.retain(|_, slot| slot.0 != layer);
                    self.slots.insert(key, (layer, self.frame));
                    self.uploads += 1;
                    return (key, layer);
                }
            }
            // The top tile is uploaded first and never replaced.
            key = TileKey {
                level: key.level + 1,
                x: key.x / 2,
                y: key.y / 2,
            };
        }
    }

    /// A layer no tile holds, else the least recently used one not used
    /// this frame (never layer 0, the top tile's).
    fn free_layer(&self) -> Option<u32> {
        if (self.slots.len() as u32) < self.layers {
            return (1..self.layers).find(|l| self.slots.values().all(|s| s.0 != *l));
        }
        self.slots
            .values()
            .filter(|s| s.0 != 0 && s.1 < self.frame)
            .min_by_key(|s| s.1)
            .map(|s| s.0)
    }
}

impl MeshPass {
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, scene: &Scene) -> Self {
        let (drape_view, has_drape, tiles) = match (&scene.drape, &scene.paged) {
            (_, Some(paged)) => {
                let layout = paged.pyramid.layout;
                let side = layout.samples() as u32;
                let top = TileKey {
                    level: layout.levels() - 1,
                    x: 0,
                    y: 0,
                };
                let layer_bytes = u64::from(side * side) * 4 * 4 / 3;
                let layers = (TILE_TEXTURE_BYTES / layer_bytes).clamp(
                    2,
                    u64::from(device.limits().max_texture_array_layers.min(256)),
                ) as u32;
                let texture = create_texture(device, side, side, layers);
                let has_drape = paged.pyramid.manifest.files.contains_key("drape");
                if let Ok(tile) = paged.pyramid.tile(top) {
                    write_layer(queue, &texture, 0, side, side, tile.drape);
                }
                let view = texture.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2Array),
                    ..Default::default()
                });
                let tiles = TileTextures {
                    texture,
                    layout,
                    slots: HashMap::from([(top, (0, 0))]),
                    layers,
                    frame: 0,
                    uploads: 0,
                    unlimited: false,
                };
                (view, has_drape, Some(tiles))
            }
            (Some(d), None) => (
                upload_mipmapped(device, queue, d.width, d.height, &d.rgba),
                true,
                None,
            ),
            (None, None) => (
                upload_mipmapped(device, queue, 1, 1, &[255; 4]),
                false,
                None,
            ),
        };
        let sampler = shared::mipmap_sampler(device, "drape sampler");
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("mesh uniforms"),
            size: size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout =
            shared::textured_layout(device, "mesh bindings", wgpu::TextureViewDimension::D2Array);
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
            0 => Float32x3, 1 => Float32x2, 2 => Float32x3, 3 => Float32x3, 4 => Float32,
            5 => Uint32
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
            entries: Vec::new(),
            upload_started: Instant::now(),
            vertex_count: 0,
            has_drape,
            tiles,
            settle: false,
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
        if scene.paged.is_some() {
            self.prepare_paged(queue, scene, camera, settings, stats)?;
        } else {
            self.prepare_grid(scene, camera, settings, stats);
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

        let [lo, hi] = scene.grid.height_range_m;
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
        stats.mesh_upload_ms = self.upload_started.elapsed().as_secs_f64() * 1e3;
        Ok(())
    }

    /// A single grid's frame: refined from its mapped arrays.
    fn prepare_grid(
        &mut self,
        scene: &mut Scene,
        camera: &Camera,
        settings: &Settings,
        stats: &mut FrameStats,
    ) {
        let start = Instant::now();
        let params = settings.refine_params(camera);
        let Some(lp) = &scene.lp else { return };
        let hierarchy = lp.hierarchy();
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
        self.entries.clear();
        self.entries.extend(strip.indices.iter().map(|&i| {
            let i = i as usize;
            (mask[i] != 0).then(|| CutSample {
                height_m: heights[i],
                mask: mask[i],
                normal: vertex_normal(heights, side, cell, i % side, i / side),
            })
        }));
        let barycentric = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        self.vertices.clear();
        for entries in strip.triangle_entries() {
            let [Some(first), Some(second), Some(third)] = entries.map(|e| self.entries[e]) else {
                continue;
            };
            let drawn = [first, second, third];
            for (k, &e) in entries.iter().enumerate() {
                let i = strip.indices[e] as usize;
                let (c, r) = (i % side, i / side);
                let z = strip
                    .morphed_z
                    .get(e)
                    .map_or(drawn[k].height_m as f64, |&z| z as f64);
                let p = DVec3::from_array(terrain_position(c, r, side, cell, z));
                let n = drawn[k].normal;
                self.vertices.push(Vertex {
                    position: (p - eye).as_vec3().to_array(),
                    uv: uv_of(p.x, p.y),
                    normal: n.map(|v| v as f32),
                    barycentric: barycentric[k],
                    height: z as f32,
                    layer: 0,
                });
            }
        }
        self.upload_started = start;
    }

    /// A pyramid's frame: refined through the cut of the tiles resident
    /// now, each triangle textured from the smallest tile holding it.
    fn prepare_paged(
        &mut self,
        queue: &wgpu::Queue,
        scene: &mut Scene,
        camera: &Camera,
        settings: &Settings,
        stats: &mut FrameStats,
    ) -> anyhow::Result<()> {
        let (Some(paged), Some(tiles)) = (scene.paged.as_mut(), self.tiles.as_mut()) else {
            return Ok(());
        };
        let start = Instant::now();
        let params = settings.refine_params(camera);
        let cut = if self.settle {
            paged.settled(&params)?
        } else {
            paged.frame(&params)
        };
        let strip = scene.refiner.refine_source(&cut, &params);
        stats.refine_ms = start.elapsed().as_secs_f64() * 1e3;
        stats.paging = Some(paged.stats());

        let start = Instant::now();
        tiles.frame += 1;
        tiles.uploads = 0;
        tiles.unlimited = self.settle;
        let (side, cell) = (cut.side(), cut.cell_size_m());
        let samples = tiles.layout.samples() as f64;
        let eye = camera.position;
        let barycentric = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        self.entries.clear();
        self.entries.extend(strip.indices.iter().map(|&i| {
            let i = i as usize;
            cut.sample(i % side, i / side).filter(|s| s.mask != 0)
        }));
        self.vertices.clear();
        // Neighbouring triangles mostly share a tile: its layer, kept.
        let mut last: Option<(TileKey, (TileKey, u32))> = None;
        for entries in strip.triangle_entries() {
            let at = entries.map(|e| {
                let i = strip.indices[e] as usize;
                (i % side, i / side)
            });
            let [Some(first), Some(second), Some(third)] = entries.map(|e| self.entries[e]) else {
                continue;
            };
            let drawn = [first, second, third];
            let holding = cut.tile_holding(&at);
            let (key, layer) = match last {
                Some((k, found)) if k == holding => found,
                _ => {
                    let found = tiles.layer_for(queue, &cut, holding);
                    last = Some((holding, found));
                    found
                }
            };
            let ([c0, r0, _, _], stride) = tiles.layout.vertices(key);
            for (k, (&e, &(c, r))) in entries.iter().zip(&at).enumerate() {
                let z = strip
                    .morphed_z
                    .get(e)
                    .map_or(drawn[k].height_m as f64, |&z| z as f64);
                let p = DVec3::from_array(terrain_position(c, r, side, cell, z));
                let uv = [
                    (((c - c0) as f64 / stride as f64 + 0.5) / samples) as f32,
                    (((r - r0) as f64 / stride as f64 + 0.5) / samples) as f32,
                ];
                self.vertices.push(Vertex {
                    position: (p - eye).as_vec3().to_array(),
                    uv,
                    normal: drawn[k].normal.map(|v| v as f32),
                    barycentric: barycentric[k],
                    height: z as f32,
                    layer,
                });
            }
        }
        stats.tile_uploads = tiles.uploads;
        self.upload_started = start;
        scene.mesh_cut = Some(cut);
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
/// the one above (sizes halve rounding down, as wgpu's levels do), viewed
/// as an array of one layer. Levels larger than the device's textures are
/// made but not uploaded: the texture starts at the first level that fits
/// (its UVs are the same).
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
    let texture = create_texture(device, w, h, 1);
    write_layer(queue, &texture, 0, w, h, &level);
    texture.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    })
}

/// An RGBA8 texture array of `layers` layers of `w`×`h` with full mip chains.
fn create_texture(device: &wgpu::Device, w: u32, h: u32, layers: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("drape"),
        size: wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: layers,
        },
        mip_level_count: 32 - w.max(h).leading_zeros(),
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: COLOUR_FORMAT,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    })
}

/// Write `rgba` (`w`×`h`, or nothing when it is not that size: a pyramid
/// without a drape) and its mip chain into `layer` of `texture`.
fn write_layer(
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    layer: u32,
    width: u32,
    height: u32,
    rgba: &[u8],
) {
    if rgba.len() != (width * height * 4) as usize {
        return;
    }
    let levels = 32 - width.max(height).leading_zeros();
    let mut level = rgba.to_vec();
    let (mut w, mut h) = (width, height);
    for mip in 0..levels {
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: mip,
                origin: wgpu::Origin3d {
                    x: 0,
                    y: 0,
                    z: layer,
                },
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
