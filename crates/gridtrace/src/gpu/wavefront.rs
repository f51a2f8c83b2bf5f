//! The frame: all tiles of at most `MAX_TILE_PIXELS` in one submission (each tile the kernel
//! sequence in the module docs: raygen, then per bounce indirect, traverse, shade and, with
//! shadows, indirect, occlusion, resolve), their results copied in the command stream into one
//! readback buffer, and that buffer mapped once: one host round trip per frame. (Before, each
//! tile ended with three blocking reads: a 4096x4096 frame waited 48 times.) A frame whose
//! results exceed the device's largest buffer is cut into as few submissions as fit. A frame
//! is submitted without a wait and read back later (`submit_frame`, `finish_frame`), so
//! frames can be in flight; the runs of tiles themselves are `tiles.rs`.

use crate::util::Instant;
use std::sync::Arc;

use super::constants::MAX_LIGHTS;
use super::device_image::DeviceImage;
use super::layout::SceneUniform;
use super::renderer::{GpuRenderer, TILE_UNIFORM_BYTES, grow};
use super::tiles::{FrameShape, Readback, SubmittedTiles, Tile, texel_bytes, tiles_per_submission};
use super::timing::GpuTimings;
use crate::render::{Image, Mode, PixelFormat, RenderOptions, RenderStats};
use crate::scene::{Camera, PointLight};
use crate::{Error, Result};

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
    /// The preparation's own parts (before the frame's submission returned).
    pub prepare_parts: PrepareParts,
}

/// Where a frame's preparation goes, on the host's clock (ms): the H200 run of 2026-11-26 spent
/// about 3 ms of a 1080p frame's wall time before its wait, where lavapipe spends 0.2-0.4 ms;
/// these say which part it is on the next hardware run.
#[derive(Debug, Default, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PrepareParts {
    /// Checking the work buffers (made anew only when a frame outgrows them).
    pub buffers_ms: f64,
    /// Writing the camera, scene constants, lights and tiles' pass uniforms (`write_buffer`).
    pub uniforms_ms: f64,
    /// Recording the frame's passes and copies into a command buffer.
    pub record_ms: f64,
    /// `queue.submit` and asking for the readback's mapping.
    pub submit_ms: f64,
}

impl std::fmt::Display for PrepareParts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "buffers {:.2}, uniforms {:.2}, record {:.2}, submit {:.2} ms",
            self.buffers_ms, self.uniforms_ms, self.record_ms, self.submit_ms
        )
    }
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

/// A frame given to the device and not yet read back (`GpuRenderer::submit_frame`); hand it
/// to `finish_frame` of the same renderer. Dropped unfinished, its results are discarded.
pub struct FrameInFlight(Flight);

impl FrameInFlight {
    /// Whether its results are in host-visible memory, so that `finish_frame` reads it back
    /// without waiting. A browser page yields to its event loop until this holds (the mapping
    /// completes only there, and nothing on the page's thread may block).
    pub fn is_ready(&self) -> bool {
        match &self.0 {
            Flight::Submitted(f) => f.run.is_ready(),
            Flight::Done(_) => true,
        }
    }
}

enum Flight {
    /// One submission, its results on their way to a mapped readback.
    Submitted(Box<SubmittedFrame>),
    /// A frame too large for one submission: traced and read back already (boxed as the
    /// other: a frame in flight is moved from caller to caller).
    Done(Box<(Option<Image>, GpuRenderStats)>),
}

struct SubmittedFrame {
    run: SubmittedTiles,
    shape: FrameShape,
    /// Its tiles and uploads so far.
    stats: GpuRenderStats,
    /// When its preparation began.
    t0: Instant,
}

/// Adds a run's readback (over `tiles`) to the frame's figures.
fn add_readback(stats: &mut GpuRenderStats, out: Readback, tiles: &[Tile]) {
    for (r, t) in out.rays.iter().zip(tiles) {
        stats.render.rays.eye += t.pixels as u64;
        stats.render.rays.shadow += r.0;
        stats.render.rays.reflection += r.1;
    }
    for (name, ms) in out.stage_ms {
        *stats.timings.stages_ms.entry(name).or_default() += ms;
    }
    stats.timings.untimed_passes += out.untimed;
    stats.timings.host.add(&out.host);
    stats.prepare_parts.record_ms += out.record_ms;
    stats.prepare_parts.submit_ms += out.submit_ms;
    stats.downloaded_bytes += out.bytes;
    stats.round_trips += 1;
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
        let (_, stats) = self.trace_frame(camera, lights, opts, Some(target))?;
        Ok(stats)
    }

    /// The frame: its pixels into a host image (returned) or into `target`; submitted and
    /// waited for at once.
    fn trace_frame(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
        target: Option<&DeviceImage>,
    ) -> Result<(Option<Image>, GpuRenderStats)> {
        let frame = self.submit_frame(camera, lights, opts, target)?;
        self.finish_frame(frame)
    }

    /// Gives the device a frame (`render`'s, or `render_to_device`'s when `target` is given)
    /// and returns without waiting for it: the host can prepare and submit the next frame
    /// while the device traces this one, and `finish_frame` reads it back later. wgpu has one
    /// queue, so frames run on the device in the order submitted; what overlaps is the host's
    /// work (uniforms, command recording, submission, readout) with the device's. Uniforms
    /// written for the next frame reach the device only at its submission, after this one's
    /// commands, and every frame in flight has its own readback buffer, so any number of
    /// frames may be in flight; each one's pixels are those it would have alone. Frames into
    /// one `target` overwrite it in submission order.
    ///
    /// A frame whose results exceed the device's largest buffer takes several submissions;
    /// it is traced and read back here, whole (its `finish_frame` only hands it over).
    pub fn submit_frame(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
        target: Option<&DeviceImage>,
    ) -> Result<FrameInFlight> {
        if let Some(target) = target {
            self.check_target(opts, target)?;
        }
        let opts = match target {
            Some(_) => RenderOptions {
                pixels: PixelFormat::Srgb8,
                ..*opts
            },
            None => *opts,
        };
        opts.validate()?;
        camera.validate().map_err(Error::Scene)?;
        let t0 = Instant::now();
        if lights.len() > MAX_LIGHTS as usize {
            return Err(Error::Gpu(format!(
                "the scene has {} lights; the GPU tracer takes at most {MAX_LIGHTS} (a uniform array, \
                 constants::MAX_LIGHTS); the CPU tracer (--backend cpu) has no limit",
                lights.len()
            )));
        }
        let n_lights = lights.len() as u32;
        // The frame's pixels are numbered row by row; a band of rows is a range of them.
        let rows = opts.row_range();
        let (first, pixels) = (rows.start * opts.width, rows.end * opts.width);
        let tile = self.tile_capacity(n_lights).min(pixels - first);
        self.ensure_work(tile, n_lights, super::work::WorkUse::FRAME);
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let mut parts = PrepareParts {
            buffers_ms: ms(t0),
            ..Default::default()
        };
        let t_uniforms = Instant::now();
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
                self.kind,
                opts.ablation,
            );
        }
        let shape = FrameShape {
            tiles,
            first,
            width: opts.width,
            rows: rows.len() as u32,
            to_host: target.is_none(),
            heat: opts.mode == Mode::Heat,
        };
        parts.uniforms_ms = ms(t_uniforms);
        let mut stats = GpuRenderStats {
            tiles: shape.tiles.len() as u32,
            uploaded_bytes: uploaded,
            prepare_parts: parts,
            ..Default::default()
        };
        let texel = if shape.to_host { texel_bytes(&opts) } else { 0 };
        let max_bytes = self.ctx.limits().max_buffer_size;
        if tiles_per_submission(&shape.tiles, texel, max_bytes) == shape.tiles.len() {
            let run = self.submit_tiles(0..shape.tiles.len(), &shape, &opts, target)?;
            return Ok(FrameInFlight(Flight::Submitted(Box::new(SubmittedFrame {
                run,
                shape,
                stats,
                t0,
            }))));
        }
        // Several submissions, each waited for before the next: the device's largest buffer
        // holds one run of tiles' results at a time.
        let mut img = shape.to_host.then(|| Image::new(shape.width, shape.rows));
        let mut k = 0;
        while k < shape.tiles.len() {
            let n = tiles_per_submission(&shape.tiles[k..], texel, max_bytes);
            let run = self.submit_tiles(k..k + n, &shape, &opts, target)?;
            let out = self.read_tiles(run, &shape, img.as_mut())?;
            add_readback(&mut stats, out, &shape.tiles[k..k + n]);
            k += n;
        }
        self.close_stats(&mut stats, t0, img.as_ref(), shape.heat);
        Ok(FrameInFlight(Flight::Done(Box::new((img, stats)))))
    }

    /// Waits for a frame from `submit_frame` (of this renderer) and reads it back: its host
    /// image (`None` for a frame into a device image) and its figures. Its `wall_ms` is the
    /// frame's latency: from its preparation to its pixels in host memory. Its host phases add
    /// up to it; with frames in flight its `prepare_ms` holds, besides its own preparation, the
    /// host's work on other frames between its submission and its wait.
    pub fn finish_frame(&mut self, frame: FrameInFlight) -> Result<(Option<Image>, GpuRenderStats)> {
        let f = match frame.0 {
            Flight::Done(done) => return Ok(*done),
            Flight::Submitted(f) => *f,
        };
        let SubmittedFrame {
            run,
            shape,
            mut stats,
            t0,
        } = f;
        let mut img = shape.to_host.then(|| Image::new(shape.width, shape.rows));
        let out = self.read_tiles(run, &shape, img.as_mut())?;
        add_readback(&mut stats, out, &shape.tiles);
        self.close_stats(&mut stats, t0, img.as_ref(), shape.heat);
        Ok((img, stats))
    }

    /// A device image fit for this renderer's frame of `opts`.
    fn check_target(&self, opts: &RenderOptions, target: &DeviceImage) -> Result<()> {
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
        Ok(())
    }

    /// The frame's totals once its pixels are in: wall time since `t0`, the host phases (the
    /// preparation is what the waits and readouts leave of the wall time), the device's total,
    /// and a heat frame's summed cost.
    fn close_stats(&self, stats: &mut GpuRenderStats, t0: Instant, img: Option<&Image>, heat: bool) {
        stats.wall_ms = t0.elapsed().as_secs_f64() * 1e3;
        stats.timings.host.close(stats.wall_ms);
        stats.timings.from_timestamps = self.timed();
        stats.timings.total_ms = if self.timed() {
            stats.timings.stages_ms.values().sum()
        } else {
            stats.wall_ms
        };
        stats.render.render_ms = stats.wall_ms;
        if heat && let Some(img) = img {
            let cost: f64 = img.pixels().iter().map(|p| p.x as f64).sum();
            stats.render.counters.cells = cost as u64;
        }
    }
}
