//! A run of a frame's tiles in one submission: each tile's kernels recorded after its pass
//! uniforms are copied into place, its pixels and counters copied into the run's readback in the
//! command stream, the run submitted and its readback asked for without a wait
//! (`submit_tiles`); later the wait and the readout (`read_tiles`). The frame (`wavefront.rs`)
//! makes one run, or as few as the device's largest buffer allows.

use crate::util::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::constants::{SLOT_REFLECT_TOTAL, SLOT_SHADOW, SLOT_SHADOW_TOTAL};
use super::context::PendingRead;
use super::device_image::DeviceImage;
use super::kernels::{Kernel, PassRecorder};
use super::renderer::{COUNTERS_BYTES, GpuRenderer, TILE_UNIFORM_BYTES};
use super::timing::{HostPhases, MAX_TIMESTAMPS_BYTES, parse_stages};
use super::work::{ACCUM_TEXEL_BYTES, PACKED_TEXEL_BYTES};
use crate::Result;
use crate::render::{Image, Mode, PixelFormat, RenderOptions};

/// Bytes of one counter slot.
const SLOT_BYTES: u64 = std::mem::size_of::<u32>() as u64;

/// One tile of a frame: its first pixel (in the frame's numbering) and its pixel count.
#[derive(Debug, Clone, Copy)]
pub(super) struct Tile {
    pub(super) offset: u32,
    pub(super) pixels: u32,
}

/// What one submission (a run of tiles) reads back, parsed.
pub(super) struct Readback {
    /// Shadow and reflection rays per tile.
    pub(super) rays: Vec<(u64, u64)>,
    /// Milliseconds per timed pass.
    pub(super) stage_ms: Vec<(&'static str, f64)>,
    pub(super) untimed: u32,
    pub(super) bytes: u64,
    /// Its wait and readout on the host's clock.
    pub(super) host: HostPhases,
    /// Its recording and its submission (ms, host clock).
    pub(super) record_ms: f64,
    pub(super) submit_ms: f64,
}

pub(super) struct FrameShape {
    pub(super) tiles: Vec<Tile>,
    /// The first pixel of the frame's band of rows (the host image's first pixel).
    pub(super) first: u32,
    pub(super) width: u32,
    pub(super) rows: u32,
    /// The pixels come to a host image (else they stay in a device image).
    pub(super) to_host: bool,
    pub(super) heat: bool,
}

/// A run of a frame's tiles in one submission (`submit_tiles`), its readback asked for.
pub(super) struct SubmittedTiles {
    read: PendingRead,
    readback: wgpu::Buffer,
    /// Which of the frame's tiles.
    range: std::ops::Range<usize>,
    /// Bytes a pixel on the device (packed or accumulated).
    texel: u64,
    counters_at: u64,
    stamps_at: u64,
    total: u64,
    stages: Vec<&'static str>,
    untimed: u32,
    /// Its recording and its submission (ms, host clock).
    pub(super) record_ms: f64,
    pub(super) submit_ms: f64,
}

impl SubmittedTiles {
    /// Whether its readback is mapped (`PendingRead::is_ready`).
    pub(super) fn is_ready(&self) -> bool {
        self.read.is_ready()
    }
}

impl GpuRenderer {
    /// Records the tiles `range` of `shape` (their pass uniforms are written) into one
    /// submission, submits it and asks for its readback, without waiting: the tiles' pixels
    /// (unless they go to `target`, copied in the command stream), a counters block per tile,
    /// the timestamps. The readback buffer is the run's own until `read_tiles`.
    pub(super) fn submit_tiles(
        &mut self,
        range: std::ops::Range<usize>,
        shape: &FrameShape,
        opts: &RenderOptions,
        target: Option<&DeviceImage>,
    ) -> Result<SubmittedTiles> {
        let tiles = &shape.tiles[range.clone()];
        let texel = texel_bytes(opts);
        let packed = texel == PACKED_TEXEL_BYTES;
        let readback_texel = if shape.to_host { texel } else { 0 };
        let image_bytes: u64 = tiles.iter().map(|t| t.pixels as u64 * readback_texel).sum();
        let counters_at = image_bytes;
        let stamps_at = counters_at + tiles.len() as u64 * COUNTERS_BYTES;
        let stamps_bytes = if self.timed() { MAX_TIMESTAMPS_BYTES } else { 0 };
        let t_record = Instant::now();
        let readback = self.take_readback(stamps_at + stamps_bytes);
        let w = self.work.as_ref().unwrap();
        let mut enc = self
            .ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        let mut rec = self.recorder(tiles[0].pixels, true, opts.ablation);
        let mut image_at = 0;
        for (k, t) in tiles.iter().enumerate() {
            // Copies in the command stream run in order with the passes: this tile's passes
            // read its own uniforms, and the next tile's raygen starts after this tile's
            // results are copied out.
            enc.copy_buffer_to_buffer(
                self.tile_uniforms.as_ref().unwrap(),
                (range.start + k) as u64 * TILE_UNIFORM_BYTES,
                self.pass_uniform(),
                0,
                Some(TILE_UNIFORM_BYTES),
            );
            rec.tile_pixels = t.pixels;
            self.record_tile(&mut enc, &mut rec, opts.mode);
            let bytes = t.pixels as u64 * texel;
            if packed {
                rec.pass(&mut enc, Kernel::Pack, &w.bind_groups[0]);
            }
            let pixels = if packed { &w.packed } else { &w.accum };
            match target {
                // The tile's pixels to their place in the frame (its pixel numbering is the
                // frame's, bands included; a device image is always packed).
                Some(d) => {
                    let at = t.offset as u64 * PACKED_TEXEL_BYTES;
                    enc.copy_buffer_to_buffer(pixels, 0, d.buffer(), at, Some(bytes));
                }
                None => {
                    enc.copy_buffer_to_buffer(pixels, 0, &readback, image_at, Some(bytes));
                    image_at += bytes;
                }
            }
            enc.copy_buffer_to_buffer(
                &self.counters,
                0,
                &readback,
                counters_at + k as u64 * COUNTERS_BYTES,
                Some(COUNTERS_BYTES),
            );
        }
        rec.timer.resolve_into(&mut enc, &readback, stamps_at);
        let total = stamps_at + rec.timer.bytes();
        let (stages, untimed) = (rec.timer.stages().to_vec(), rec.timer.untimed);
        let commands = enc.finish();
        let record_ms = t_record.elapsed().as_secs_f64() * 1e3;
        let t_submit = Instant::now();
        let index = self.ctx.queue.submit([commands]);
        let read = self.ctx.begin_read(&readback, total, Some(index));
        let submit_ms = t_submit.elapsed().as_secs_f64() * 1e3;
        Ok(SubmittedTiles {
            read,
            readback,
            range,
            texel,
            counters_at,
            stamps_at,
            total,
            stages,
            untimed,
            record_ms,
            submit_ms,
        })
    }

    /// Waits for a run of tiles from `submit_tiles` and writes their pixels into `img` (the
    /// frame's host image, whose first row starts at the shape's first pixel; `None` when they
    /// went to a device image); its readback buffer goes back to the renderer's spares.
    pub(super) fn read_tiles(
        &mut self,
        run: SubmittedTiles,
        shape: &FrameShape,
        img: Option<&mut Image>,
    ) -> Result<Readback> {
        let (texel, counters_at, stamps_at, total) = (run.texel, run.counters_at, run.stamps_at, run.total);
        let (stages, untimed) = (run.stages, run.untimed);
        let (record_ms, submit_ms) = (run.record_ms, run.submit_ms);
        let tiles = &shape.tiles[run.range];
        let packed = texel == PACKED_TEXEL_BYTES;
        let ctx = self.ctx.clone();
        let (out, host) = run.read.finish(&ctx, |raw| {
            if let Some(img) = img {
                let mut at = 0usize;
                for t in tiles {
                    let n = t.pixels as usize;
                    let start = (t.offset - shape.first) as usize;
                    let texels = &raw[at..at + n * texel as usize];
                    if packed {
                        // The device's levels as they are (`Image` makes linear values only if
                        // asked): a copy on every core, no conversion.
                        let dst = &mut img.srgb8_mut()[start..][..n];
                        dst.par_chunks_mut(PIECE_PIXELS)
                            .zip(texels.par_chunks(PIECE_PIXELS * PACKED_TEXEL_BYTES as usize))
                            .for_each(|(d, s)| d.copy_from_slice(bytemuck::cast_slice(s)));
                    } else {
                        let dst = &mut img.pixels_mut()[start..][..n];
                        // On every core: a 1920x1080 frame is 2M pixels to convert.
                        dst.par_iter_mut()
                            .zip(texels.par_chunks_exact(texel as usize))
                            .for_each(|(px, texel)| {
                                let f = |i: usize| f32::from_ne_bytes(texel[4 * i..4 * i + 4].try_into().unwrap());
                                *px = Vec3::new(f(0), f(1), f(2));
                            });
                    }
                    at += n * texel as usize;
                }
            }
            let counter = |k: usize, slot: usize| {
                let i = (counters_at + k as u64 * COUNTERS_BYTES) as usize + slot * SLOT_BYTES as usize;
                u32::from_ne_bytes(raw[i..i + 4].try_into().unwrap()) as u64
            };
            Readback {
                rays: (0..tiles.len())
                    .map(|k| (counter(k, SLOT_SHADOW_TOTAL), counter(k, SLOT_REFLECT_TOTAL)))
                    .collect(),
                stage_ms: parse_stages(&stages, &ctx, &raw[stamps_at as usize..total as usize]),
                untimed,
                bytes: total,
                host: HostPhases::default(),
                record_ms,
                submit_ms,
            }
        })?;
        self.give_back_readback(run.readback);
        Ok(Readback { host, ..out })
    }

    /// Records one tile's kernels (its pass uniforms in place).
    fn record_tile(&self, enc: &mut wgpu::CommandEncoder, rec: &mut PassRecorder, mode: Mode) {
        let w = self.work.as_ref().unwrap();
        enc.clear_buffer(&self.counters, 0, None);
        rec.pass(enc, Kernel::Raygen, &w.bind_groups[0]);
        for d in 0..=mode.reflection_depth() as usize {
            let bg = &w.bind_groups[d];
            rec.pass(enc, Kernel::Indirect, bg);
            if mode == Mode::Heat {
                rec.pass(enc, Kernel::TraverseHeat, bg);
                break;
            }
            rec.pass(enc, Kernel::Traverse, bg);
            rec.pass(enc, Kernel::Shade, bg);
            if mode.shadows() {
                rec.pass(enc, Kernel::Indirect, bg);
                rec.pass(enc, Kernel::Occlusion, bg);
                rec.pass(enc, Kernel::Resolve, bg);
            }
            // This bounce's input queue (slot d % 2) becomes the next one's output: empty it,
            // and the shadow queue.
            enc.clear_buffer(&self.counters, (d % 2) as u64 * SLOT_BYTES, Some(SLOT_BYTES));
            enc.clear_buffer(&self.counters, SLOT_SHADOW as u64 * SLOT_BYTES, Some(SLOT_BYTES));
        }
    }
}

/// Pixels a worker copies at a time in a packed frame's readout.
const PIECE_PIXELS: usize = 64 * 1024;

/// Bytes a pixel takes in the frame's readback: 4 when the caller wants 8-bit sRGB (packed on
/// the device), else the accumulation's 16. Heat frames keep their raw costs.
pub(super) fn texel_bytes(opts: &RenderOptions) -> u64 {
    if opts.pixels == PixelFormat::Srgb8 && opts.mode != Mode::Heat {
        PACKED_TEXEL_BYTES
    } else {
        ACCUM_TEXEL_BYTES
    }
}

/// How many of `tiles` (from the first) one submission takes: as many as the device's largest
/// buffer holds the results of, at least one.
pub(super) fn tiles_per_submission(tiles: &[Tile], texel_bytes: u64, max_buffer_bytes: u64) -> usize {
    let mut bytes = MAX_TIMESTAMPS_BYTES;
    let mut n = 0;
    for t in tiles {
        bytes += t.pixels as u64 * texel_bytes + COUNTERS_BYTES;
        if n > 0 && bytes > max_buffer_bytes {
            break;
        }
        n += 1;
    }
    n
}
