//! The tile loop: a frame is rendered in tiles of at most `MAX_TILE_PIXELS`, each one
//! submission of the kernel sequence in the module docs (raygen, then per bounce indirect,
//! traverse, shade and, with shadows, indirect, occlusion, resolve).

use std::time::Instant;

use glam::Vec3;

use super::constants::{SLOT_REFLECT_TOTAL, SLOT_SHADOW, SLOT_SHADOW_TOTAL};
use super::kernels::Kernel;
use super::layout::SceneUniform;
use super::renderer::{ACCUM_TEXEL_BYTES, COUNTERS_BYTES, GpuRenderer};
use super::timing::GpuTimings;
use crate::render::{Ablation, Image, Mode, RenderOptions, RenderStats};
use crate::scene::{Camera, PointLight};
use crate::{Error, Result};

/// Bytes of one counter slot.
const SLOT_BYTES: u64 = std::mem::size_of::<u32>() as u64;

/// Statistics of one GPU frame.
#[derive(Debug, Default, Clone)]
pub struct GpuRenderStats {
    pub render: RenderStats,
    pub timings: GpuTimings,
    pub tiles: u32,
    /// Bytes written to the device for this frame: the camera, the scene constants (its light
    /// count), the lights and each tile's pass uniforms. The scene itself is uploaded once.
    pub uploaded_bytes: u64,
}

impl GpuRenderStats {
    /// The frame's milliseconds as benchmarks report them: the sum of the stages' timestamps
    /// where the adapter has timestamp queries, else wall time around the submissions.
    pub fn frame_ms(&self) -> f64 {
        if self.timings.from_timestamps {
            self.timings.total_ms
        } else {
            self.render.render_ms
        }
    }
}

/// What one tile's submission reads back.
struct TileOutput {
    /// RGBA per pixel of the tile.
    accum: Vec<f32>,
    counters: Vec<u32>,
    /// Milliseconds per timed pass.
    stage_ms: Vec<(&'static str, f64)>,
}

impl GpuRenderer {
    /// Renders one frame with the given camera and lights (the scene's own need not be used).
    pub fn render(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
    ) -> Result<(Image, GpuRenderStats)> {
        opts.validate()?;
        self.check_serves(opts.accel)?;
        camera.validate().map_err(Error::Scene)?;
        let n_lights = lights.len() as u32;
        // The frame's pixels are numbered row by row; a band of rows is a range of them.
        let rows = opts.row_range();
        let (first, pixels) = (rows.start * opts.width, rows.end * opts.width);
        let tile = self.tile_capacity(n_lights).min(pixels - first);
        self.ensure_work(tile, n_lights);
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
        {
            let w = self.work.as_ref().unwrap();
            if !lights.is_empty() {
                q.write_buffer(&w.lights, 0, bytemuck::cast_slice(lights));
                uploaded += std::mem::size_of_val(lights) as u64;
            }
        }
        let mut img = Image::new(opts.width, rows.len() as u32);
        let mut stats = GpuRenderStats::default();
        let mut offset = first;
        while offset < pixels {
            let tp = tile.min(pixels - offset);
            uploaded += self.write_pass_uniforms(offset, tp, opts.mode, opts.accel, opts.ablation);
            let out = self.run_tile(tp, opts.mode, opts.ablation)?;
            for (i, px) in out.accum.chunks_exact(4).enumerate() {
                img.pixels[(offset - first) as usize + i] = Vec3::new(px[0], px[1], px[2]);
            }
            stats.render.rays.eye += tp as u64;
            stats.render.rays.shadow += out.counters[SLOT_SHADOW_TOTAL] as u64;
            stats.render.rays.reflection += out.counters[SLOT_REFLECT_TOTAL] as u64;
            for (k, v) in out.stage_ms {
                *stats.timings.stages_ms.entry(k).or_default() += v;
            }
            stats.tiles += 1;
            offset += tp;
        }
        stats.uploaded_bytes = uploaded;
        let wall_ms = t0.elapsed().as_secs_f64() * 1e3;
        stats.timings.from_timestamps = self.timed();
        stats.timings.total_ms = if self.timed() {
            stats.timings.stages_ms.values().sum()
        } else {
            wall_ms
        };
        stats.render.render_ms = stats.timings.total_ms;
        if opts.mode == Mode::Heat {
            let cost: f64 = img.pixels.iter().map(|p| p.x as f64).sum();
            stats.render.counters.cells = cost as u64;
        }
        Ok((img, stats))
    }

    /// Records and runs one tile's kernels (`tp` pixels; the pass uniforms are written).
    fn run_tile(&self, tp: u32, mode: Mode, ablation: Ablation) -> Result<TileOutput> {
        let w = self.work.as_ref().unwrap();
        let mut enc = self
            .ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        enc.clear_buffer(&self.counters, 0, None);
        let mut rec = self.recorder(tp, true, ablation);
        rec.pass(&mut enc, Kernel::Raygen, &w.bind_groups[0]);
        for d in 0..=mode.reflection_depth() as usize {
            let bg = &w.bind_groups[d];
            rec.pass(&mut enc, Kernel::Indirect, bg);
            if mode == Mode::Heat {
                rec.pass(&mut enc, Kernel::TraverseHeat, bg);
                break;
            }
            rec.pass(&mut enc, Kernel::Traverse, bg);
            rec.pass(&mut enc, Kernel::Shade, bg);
            if mode.shadows() {
                rec.pass(&mut enc, Kernel::Indirect, bg);
                rec.pass(&mut enc, Kernel::Occlusion, bg);
                rec.pass(&mut enc, Kernel::Resolve, bg);
            }
            // This bounce's input queue (slot d % 2) becomes the next one's output: empty it,
            // and the shadow queue.
            enc.clear_buffer(&self.counters, (d % 2) as u64 * SLOT_BYTES, Some(SLOT_BYTES));
            enc.clear_buffer(&self.counters, SLOT_SHADOW as u64 * SLOT_BYTES, Some(SLOT_BYTES));
        }
        rec.timer.resolve(&mut enc);
        self.ctx.queue.submit([enc.finish()]);
        let accum = bytemuck::cast_slice(&self.ctx.read_buffer(&w.accum, tp as u64 * ACCUM_TEXEL_BYTES)?).to_vec();
        let counters = bytemuck::cast_slice(&self.ctx.read_buffer(&self.counters, COUNTERS_BYTES)?).to_vec();
        let stage_ms = rec.timer.read(&self.ctx)?;
        Ok(TileOutput {
            accum,
            counters,
            stage_ms,
        })
    }
}
