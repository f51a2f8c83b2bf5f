//! The work buffers a renderer keeps between pieces of work: ray queues, hits, the shadow
//! queue, the resolve spans, accumulation and packed pixels, with the frame's bind groups over
//! them. Each piece of work names the buffers it uses (`WorkUse`); the others are small
//! stand-ins.

use std::mem::size_of;

use super::bindings::{self, FrameSlot, PACK_BINDINGS, PackSlot};
use super::constants::MAX_LIGHTS;
use super::kernels::{FrameGroups, Kernels};
use super::layout::{GpuHit, PassUniform, RayRec};
use super::scene::SceneBuffers;
use crate::scene::PointLight;

/// Bytes between the bounces' pass uniforms: uniform binding offsets must be multiples of
/// this (WebGPU's largest allowed `min_uniform_buffer_offset_alignment`).
pub(super) const PASS_UNIFORM_STRIDE_BYTES: u64 = 256;
/// Bounces per frame at most: eye + two reflection levels.
pub(super) const MAX_PASSES: usize = 3;
/// Bytes per pixel of the accumulation buffer (`vec4<f32>`).
pub(super) const ACCUM_TEXEL_BYTES: u64 = size_of::<[f32; 4]>() as u64;
/// Bytes per pixel of the packed 8-bit sRGB pixels (pack.wgsl).
pub(super) const PACKED_TEXEL_BYTES: u64 = size_of::<u32>() as u64;
/// Bytes per ray of the resolve buffer (`vec2<u32>`: first shadow ray, count).
const RESOLVE_SPAN_BYTES: u64 = size_of::<[u32; 2]>() as u64;
/// Bytes of a work buffer that a piece of work does not use (`WorkUse`): one element of the
/// largest array a kernel binds.
const STAND_IN_BYTES: u64 = 64;

/// Which work buffers a piece of work reads or writes, as bits: the others are bound as small
/// stand-ins, so that a ray batch allocates its queue and its hits only (a frame's buffers
/// for a million pixels are about 200 MB, the first batch's allocation time on hardware).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct WorkUse(u8);

impl WorkUse {
    const QUEUE_A: u8 = 1;
    const QUEUE_B: u8 = 2;
    const HITS: u8 = 4;
    const SHADOW: u8 = 8;
    const RESOLVE: u8 = 16;
    const ACCUM: u8 = 32;
    const PACKED: u8 = 64;
    /// A frame: every buffer.
    pub const FRAME: WorkUse = WorkUse(u8::MAX);
    /// Closest hits of a batch: queue A and the hits.
    pub const CLOSEST_HITS: WorkUse = WorkUse(Self::QUEUE_A | Self::HITS);
    /// Occlusion of a batch: the shadow queue.
    pub const OCCLUSION: WorkUse = WorkUse(Self::SHADOW);
    /// Closest points: queue A (the points), the hits and the work per point (accum).
    pub const CLOSEST_POINTS: WorkUse = WorkUse(Self::QUEUE_A | Self::HITS | Self::ACCUM);

    fn has(self, bit: u8) -> bool {
        self.0 & bit != 0
    }

    fn covers(self, other: WorkUse) -> bool {
        self.0 & other.0 == other.0
    }

    /// The buffers of both.
    pub fn and(self, other: WorkUse) -> WorkUse {
        WorkUse(self.0 | other.0)
    }
}

/// Queues and per-tile buffers, sized for a tile of `tile_pixels` and `max_lights` lights.
pub(super) struct WorkBuffers {
    pub tile_pixels: u32,
    pub max_lights: u32,
    /// The buffers made at full size; the others are stand-ins.
    pub uses: WorkUse,
    pub queue_a: wgpu::Buffer,
    pub queue_b: wgpu::Buffer,
    pub hits: wgpu::Buffer,
    pub shadow: wgpu::Buffer,
    pub resolve: wgpu::Buffer,
    pub accum: wgpu::Buffer,
    /// The tile's pixels as 8-bit sRGB (the pack kernel's output), and its group 1.
    pub packed: wgpu::Buffer,
    pub packed_group: wgpu::BindGroup,
    pub lights: wgpu::Buffer,
    /// Group 0 per bounce (queues A/B swap roles every bounce), a bind group for each kernel.
    pub bind_groups: Vec<FrameGroups>,
}

/// What a frame's bind groups bind besides the work buffers: the renderer's device, kernels,
/// scene and uniforms.
pub(super) struct Bound<'a> {
    pub device: &'a wgpu::Device,
    pub kernels: &'a Kernels,
    pub scene: &'a SceneBuffers,
    pub camera_uniform: &'a wgpu::Buffer,
    /// `MAX_PASSES` pass uniforms, `PASS_UNIFORM_STRIDE_BYTES` apart.
    pub pass_uniform: &'a wgpu::Buffer,
    pub counters: &'a wgpu::Buffer,
}

impl WorkBuffers {
    /// Whether these buffers hold a tile of `tile_pixels` with `lights` in the buffers `uses`
    /// names.
    pub fn hold(&self, tile_pixels: u32, lights: u32, uses: WorkUse) -> bool {
        self.tile_pixels >= tile_pixels && self.max_lights >= lights && self.uses.covers(uses)
    }

    /// Buffers for a tile of `tile_pixels` and `lights` lights, full size where `uses` names
    /// them, and the frame's bind groups over them and `b`.
    pub fn new(b: &Bound, tile_pixels: u32, lights: u32, uses: WorkUse) -> WorkBuffers {
        let dev = b.device;
        let buf = |label: &str, bit: u8, size: u64| {
            dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                // Zero-length bindings are invalid, and a binding must hold one element of its
                // array (a queued ray is 48 bytes): an unused buffer is a stand-in of 64.
                size: if uses.has(bit) {
                    size.max(STAND_IN_BYTES)
                } else {
                    STAND_IN_BYTES
                },
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let n = tile_pixels as u64;
        let rec = size_of::<RayRec>() as u64;
        let max_lights = lights.max(1);
        let queue_a = buf("ray queue A", WorkUse::QUEUE_A, n * rec);
        let queue_b = buf("ray queue B", WorkUse::QUEUE_B, n * rec);
        let hits = buf("hits", WorkUse::HITS, n * size_of::<GpuHit>() as u64);
        let shadow = buf("shadow queue", WorkUse::SHADOW, n * rec * max_lights as u64);
        let resolve = buf("resolve", WorkUse::RESOLVE, n * RESOLVE_SPAN_BYTES);
        let accum = buf("accum", WorkUse::ACCUM, n * ACCUM_TEXEL_BYTES);
        let packed = buf("packed pixels", WorkUse::PACKED, n * PACKED_TEXEL_BYTES);
        let packed_group = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("packed pixels"),
            layout: &b.kernels.pack_layout,
            entries: &bindings::group_entries(&PACK_BINDINGS, |slot| match slot {
                PackSlot::Packed => packed.as_entire_binding(),
            }),
        });
        // A uniform array of `MAX_LIGHTS` (common.wgsl): its binding must hold all of them.
        let lights_buf = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("lights"),
            size: size_of::<PointLight>() as u64 * MAX_LIGHTS as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_groups = (0..MAX_PASSES)
            .map(|d| {
                let (rays_in, rays_out) = if d % 2 == 0 {
                    (&queue_a, &queue_b)
                } else {
                    (&queue_b, &queue_a)
                };
                b.kernels.frame_groups(dev, |slot| match slot {
                    FrameSlot::SceneUniform => b.scene.uniform.as_entire_binding(),
                    FrameSlot::CameraUniform => b.camera_uniform.as_entire_binding(),
                    FrameSlot::PassUniform => wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: b.pass_uniform,
                        offset: d as u64 * PASS_UNIFORM_STRIDE_BYTES,
                        size: wgpu::BufferSize::new(size_of::<PassUniform>() as u64),
                    }),
                    FrameSlot::Tris => b.scene.tris.as_entire_binding(),
                    FrameSlot::TriShade => b.scene.tri_shade.as_entire_binding(),
                    FrameSlot::Materials => b.scene.materials.as_entire_binding(),
                    FrameSlot::Lights => lights_buf.as_entire_binding(),
                    FrameSlot::RaysIn => rays_in.as_entire_binding(),
                    FrameSlot::RaysOut => rays_out.as_entire_binding(),
                    FrameSlot::Hits => hits.as_entire_binding(),
                    FrameSlot::ShadowRays => shadow.as_entire_binding(),
                    FrameSlot::Resolve => resolve.as_entire_binding(),
                    FrameSlot::Accum => accum.as_entire_binding(),
                    FrameSlot::Counters => b.counters.as_entire_binding(),
                })
            })
            .collect();
        WorkBuffers {
            tile_pixels,
            max_lights,
            uses,
            queue_a,
            queue_b,
            hits,
            shadow,
            resolve,
            accum,
            packed,
            packed_group,
            lights: lights_buf,
            bind_groups,
        }
    }
}
