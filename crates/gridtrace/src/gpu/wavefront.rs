//! The frame: all tiles of at most `MAX_TILE_PIXELS` in one submission (each tile the kernel
//! sequence in the module docs: raygen, then per bounce indirect, traverse, shade and, with
//! shadows, indirect, occlusion, resolve), their results copied in the command stream into one
//! readback buffer, and that buffer mapped once: one host round trip per frame. (Before, each
//! tile ended with three blocking reads: a 4096x4096 frame waited 48 times.) A frame whose
//! results exceed the device's largest buffer is cut into as few submissions as fit.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::constants::{SLOT_REFLECT_TOTAL, SLOT_SHADOW, SLOT_SHADOW_TOTAL};
use super::device_image::DeviceImage;
use super::kernels::{Kernel, PassRecorder};
use super::layout::SceneUniform;
use super::renderer::{ACCUM_TEXEL_BYTES, COUNTERS_BYTES, GpuRenderer, PACKED_TEXEL_BYTES, TILE_UNIFORM_BYTES, grow};
use super::timing::{GpuTimings, HostPhases, MAX_TIMESTAMPS_BYTES};
use crate::render::{Image, Mode, PixelFormat, RenderOptions, RenderStats};
use crate::scene::{Camera, PointLight};
use crate::{Error, Result};

/// Bytes of one counter slot.
const SLOT_BYTES: u64 = std::mem::size_of::<u32>() as u64;

/// Statistics of one GPU frame. Times have one meaning everywhere (`render`, `bench`, `view`,
/// Python): `wall_ms` is the host's clock from the first upload to the image in host memory
/// (what a program waits), `timings` the device's own per-stage times (timestamps, where the
/// adapter has them): their difference is submission, readback and host work.
#[derive(Debug, Default, Clone)]
pub struct GpuRenderStats {
    pub render: RenderStats,
    pub timings: GpuTimings,
    pub tiles: u32,
    /// Bytes written to the device for this frame: the camera, the scene constants (its light
    /// count), the lights and each tile's pass uniforms. The scene itself is uploaded once.
    pub uploaded_bytes: u64,
    /// Bytes read back: the image (16 a pixel, 4 as `PixelFormat::Srgb8`), each tile's
    /// counters, the timestamps.
    pub downloaded_bytes: u64,
    /// Times the host waited for the device (one per submission: 1 unless the frame's results
    /// exceed the device's largest buffer).
    pub round_trips: u32,
    /// Host wall clock of the frame, uploads to image (ms).
    pub wall_ms: f64,
}

impl GpuRenderStats {
    /// The frame's milliseconds as every report gives them: wall time (`wall_ms`).
    pub fn frame_ms(&self) -> f64 {
        self.wall_ms
    }

    /// The device's time for the frame (the stages' timestamps summed), where it has them.
    pub fn gpu_ms(&self) -> Option<f64> {
        self.timings.from_timestamps.then_some(self.timings.total_ms)
    }
}

/// One tile of a frame: its first pixel (in the frame's numbering) and its pixel count.
#[derive(Debug, Clone, Copy)]
struct Tile {
    offset: u32,
    pixels: u32,
}

/// What one submission (a run of tiles) reads back, parsed.
struct Readback {
    /// Shadow and reflection rays per tile.
    rays: Vec<(u64, u64)>,
    /// Milliseconds per timed pass.
    stage_ms: Vec<(&'static str, f64)>,
    untimed: u32,
    bytes: u64,
    /// Its wait and readout on the host's clock.
    host: HostPhases,
}

impl GpuRenderer {
    /// Renders one frame with the given camera and lights (the scene's own need not be used).
    pub fn render(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
    ) -> Result<(Image, GpuRenderStats)> {
        let (img, stats) = self.trace_frame(camera, lights, opts, None)?;
        Ok((img.expect("a frame without a device image comes to the host"), stats))
    }

    /// `render`, the pixels left in `target` (8-bit sRGB, whatever `opts.pixels` says; a band
    /// of rows, `opts.rows`, in its own rows): only the counters and timestamps come back, so
    /// the frame's round trip carries no image. `target` must be on this renderer's device and
    /// of the frame's size; heat frames are not taken (they are coloured on the host by the
    /// whole frame's largest cost).
    pub fn render_to_device(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
        target: &DeviceImage,
    ) -> Result<GpuRenderStats> {
        if !Arc::ptr_eq(target.context(), &self.ctx) {
            return Err(Error::InvalidInput(
                "the device image was made on another device than this renderer's".into(),
            ));
        }
        if target.size() != (opts.width, opts.height) {
            return Err(Error::InvalidInput(format!(
                "a {}x{} frame asked into a {}x{} device image",
                opts.width,
                opts.height,
                target.size().0,
                target.size().1
            )));
        }
        if opts.mode == Mode::Heat {
            return Err(Error::InvalidInput(
                "heat frames are coloured on the host (by the whole frame's largest cost): use render".into(),
            ));
        }
        let opts = RenderOptions {
            pixels: PixelFormat::Srgb8,
            ..*opts
        };
        let (_, stats) = self.trace_frame(camera, lights, &opts, Some(target))?;
        Ok(stats)
    }

    /// The frame: its pixels into a host image (returned) or into `target`.
    fn trace_frame(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
        target: Option<&DeviceImage>,
    ) -> Result<(Option<Image>, GpuRenderStats)> {
        opts.validate()?;
        self.check_serves(opts.accel)?;
        camera.validate().map_err(Error::Scene)?;
        let n_lights = lights.len() as u32;
        // The frame's pixels are numbered row by row; a band of rows is a range of them.
        let rows = opts.row_range();
        let (first, pixels) = (rows.start * opts.width, rows.end * opts.width);
        let tile = self.tile_capacity(n_lights).min(pixels - first);
        self.ensure_work(tile, n_lights, super::renderer::WorkUse::FRAME);
        let t0 = Instant::now();
        let frame = camera.frame(opts.width, opts.height);
        let q = &self.ctx.queue;
        q.write_buffer(&self.camera_uniform, 0, bytemuck::bytes_of(&frame));
        let consts = SceneUniform {
            n_lights,
            ..self.scene.consts
        };
        q.write_buffer(&self.scene.uniform, 0, bytemuck::bytes_of(&consts));
        let mut uploaded = (std::mem::size_of_val(&frame) + std::mem::size_of_val(&consts)) as u64;
        if !lights.is_empty() {
            let w = self.work.as_ref().unwrap();
            q.write_buffer(&w.lights, 0, bytemuck::cast_slice(lights));
            uploaded += std::mem::size_of_val(lights) as u64;
        }
        let tiles: Vec<Tile> = (first..pixels)
            .step_by(tile as usize)
            .map(|offset| Tile {
                offset,
                pixels: tile.min(pixels - offset),
            })
            .collect();
        grow(
            &self.ctx.device,
            &mut self.tile_uniforms,
            tiles.len() as u64 * TILE_UNIFORM_BYTES,
            "tile pass uniforms",
            wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        );
        let tile_uniforms = self.tile_uniforms.as_ref().unwrap();
        for (k, t) in tiles.iter().enumerate() {
            uploaded += self.write_pass_uniforms_to(
                tile_uniforms,
                k as u64 * TILE_UNIFORM_BYTES,
                t.offset,
                t.pixels,
                opts.mode,
                opts.accel,
                opts.ablation,
            );
        }
        let mut img = target.is_none().then(|| Image::new(opts.width, rows.len() as u32));
        let mut stats = GpuRenderStats::default();
        let max_bytes = self.ctx.limits().max_buffer_size;
        let mut k = 0;
        while k < tiles.len() {
            let dest = match &mut img {
                Some(img) => Dest::Host(img),
                None => Dest::Device(target.expect("no host image only with a device image")),
            };
            let n = tiles_per_submission(&tiles[k..], dest.readback_texel(opts), max_bytes);
            let out = self.run_tiles(k, &tiles[k..k + n], first, opts, dest)?;
            for (r, t) in out.rays.iter().zip(&tiles[k..k + n]) {
                stats.render.rays.eye += t.pixels as u64;
                stats.render.rays.shadow += r.0;
                stats.render.rays.reflection += r.1;
            }
            for (name, ms) in out.stage_ms {
                *stats.timings.stages_ms.entry(name).or_default() += ms;
            }
            stats.timings.untimed_passes += out.untimed;
            stats.timings.host.add(&out.host);
            stats.downloaded_bytes += out.bytes;
            stats.round_trips += 1;
            k += n;
        }
        stats.tiles = tiles.len() as u32;
        stats.uploaded_bytes = uploaded;
        stats.wall_ms = t0.elapsed().as_secs_f64() * 1e3;
        stats.timings.host.close(stats.wall_ms);
        stats.timings.from_timestamps = self.timed();
        stats.timings.total_ms = if self.timed() {
            stats.timings.stages_ms.values().sum()
        } else {
            stats.wall_ms
        };
        stats.render.render_ms = stats.wall_ms;
        if opts.mode == Mode::Heat
            && let Some(img) = &img
        {
            let cost: f64 = img.pixels().iter().map(|p| p.x as f64).sum();
            stats.render.counters.cells = cost as u64;
        }
        Ok((img, stats))
    }

    /// Records `tiles` (the frame's tiles from index `first_tile` on; their pass uniforms are
    /// written) into one submission, runs it, waits once and writes their pixels into `dest`
    /// (a host image, whose first row starts at pixel `first`, or a device image of the whole
    /// frame, copied into in the command stream).
    fn run_tiles(
        &mut self,
        first_tile: usize,
        tiles: &[Tile],
        first: u32,
        opts: &RenderOptions,
        mut dest: Dest,
    ) -> Result<Readback> {
        let texel = texel_bytes(opts);
        let packed = texel == PACKED_TEXEL_BYTES;
        // The readback: the tiles' pixels in order (none for a device image), then a counters
        // block per tile, then the timestamps.
        let readback_texel = dest.readback_texel(opts);
        let image_bytes: u64 = tiles.iter().map(|t| t.pixels as u64 * readback_texel).sum();
        let counters_at = image_bytes;
        let stamps_at = counters_at + tiles.len() as u64 * COUNTERS_BYTES;
        let stamps_bytes = if self.timed() { MAX_TIMESTAMPS_BYTES } else { 0 };
        grow(
            &self.ctx.device,
            &mut self.readback,
            stamps_at + stamps_bytes,
            "frame readback",
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let readback = self.readback.as_ref().unwrap();
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
                (first_tile + k) as u64 * TILE_UNIFORM_BYTES,
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
            match &dest {
                // The tile's pixels to their place in the frame (its pixel numbering is the
                // frame's, bands included; a device image is always packed).
                Dest::Device(d) => {
                    let at = t.offset as u64 * PACKED_TEXEL_BYTES;
                    enc.copy_buffer_to_buffer(pixels, 0, d.buffer(), at, Some(bytes));
                }
                Dest::Host(_) => {
                    enc.copy_buffer_to_buffer(pixels, 0, readback, image_at, Some(bytes));
                    image_at += bytes;
                }
            }
            enc.copy_buffer_to_buffer(
                &self.counters,
                0,
                readback,
                counters_at + k as u64 * COUNTERS_BYTES,
                Some(COUNTERS_BYTES),
            );
        }
        rec.timer.resolve_into(&mut enc, readback, stamps_at);
        let total = stamps_at + rec.timer.bytes();
        self.ctx.queue.submit([enc.finish()]);
        let timer = rec.timer;
        let (out, host) = self.ctx.map_read_with(readback, total, |raw| {
            if let Dest::Host(img) = &mut dest {
                let mut at = 0usize;
                for t in tiles {
                    let n = t.pixels as usize;
                    let start = (t.offset - first) as usize;
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
                stage_ms: timer.parse(&self.ctx, &raw[stamps_at as usize..total as usize]),
                untimed: timer.untimed,
                bytes: total,
                host: HostPhases::default(),
            }
        })?;
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

/// Where a submission's pixels go.
enum Dest<'a> {
    /// Read back into the host's image.
    Host(&'a mut Image),
    /// Copied into a device image (in the command stream); nothing read back.
    Device(&'a DeviceImage),
}

impl Dest<'_> {
    /// Bytes a pixel takes in the readback: none when the image stays on the device.
    fn readback_texel(&self, opts: &RenderOptions) -> u64 {
        match self {
            Dest::Host(_) => texel_bytes(opts),
            Dest::Device(_) => 0,
        }
    }
}

/// Bytes a pixel takes in the frame's readback: 4 when the caller wants 8-bit sRGB (packed on
/// the device), else the accumulation's 16. Heat frames keep their raw costs.
fn texel_bytes(opts: &RenderOptions) -> u64 {
    if opts.pixels == PixelFormat::Srgb8 && opts.mode != Mode::Heat {
        PACKED_TEXEL_BYTES
    } else {
        ACCUM_TEXEL_BYTES
    }
}

/// How many of `tiles` (from the first) one submission takes: as many as the device's largest
/// buffer holds the results of, at least one.
fn tiles_per_submission(tiles: &[Tile], texel_bytes: u64, max_buffer_bytes: u64) -> usize {
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
