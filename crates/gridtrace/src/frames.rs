//! Runs of frames with frames in flight (`Tracer::render_frames`): on a GPU the host prepares
//! and submits frame N+1 before it waits for frame N, so the device never idles while the host
//! records commands and the host's readout of one frame overlaps the device's next. Every
//! frame's pixels and counts are those it has traced alone (tests/gpu_frames.rs checks them bit
//! for bit against frames one by one).
//!
//! What overlaps, and what does not: wgpu has one queue, so the device runs the frames in the
//! order submitted, one after the other. The host's part of a frame (uniforms, command
//! recording, submission; the readout of the frame before) runs while the device traces.
//! The H200 run of 2026-11-26 measured 1080p frames at 0.5-2.4 ms of device time and 5.3-8 ms
//! of wall time, about 3 ms of it host preparation: with two frames in flight the frame rate is
//! bound by the larger of the device's time and the host's, not their sum.
//!
//! ```
//! use gridtrace::{scene::builtin, AccelKind, Backend, FramesOptions, Mode, RenderOptions, Tracer, AccelParams};
//!
//! let accel = AccelKind::Bvh;
//! let scene = builtin::knot_box().prepare_for(accel, &AccelParams::NONE)?;
//! let (mut tracer, _) = Tracer::open_with(Backend::Cpu, scene)?;
//! let views = (0..3).map(|_| (tracer.scene.camera, tracer.scene.lights.clone())).collect::<Vec<_>>();
//! let opts = RenderOptions::new(16, 16, Mode::Cast);
//! let mut seen = Vec::new();
//! let run = tracer.render_frames(views, &opts, FramesOptions::default(), |i, frame| {
//!     seen.push((i, frame.stats().rays.eye));
//!     Ok(())
//! })?;
//! assert_eq!((run.frames, seen), (3, vec![(0, 256), (1, 256), (2, 256)]));
//! # Ok::<(), gridtrace::Error>(())
//! ```

use crate::util::Instant;
use std::collections::VecDeque;

use crate::Result;
use crate::backend::{Frame, Rendered, Tracer};
use crate::gpu::{DeviceImage, FrameInFlight};
use crate::render::RenderOptions;
use crate::scene::{Camera, PointLight};

/// Frames in flight unless asked otherwise: one traced on the device while the host prepares
/// the next and reads out the one before. More would only queue (the device runs them in
/// order) and cost a readback buffer each.
pub const DEFAULT_IN_FLIGHT: usize = 2;

/// How `Tracer::render_frames` traces its frames.
#[derive(Clone, Copy)]
pub struct FramesOptions<'a> {
    /// Frames given to the GPU before the oldest is read back: 1 traces them one by one, 2
    /// (`DEFAULT_IN_FLIGHT`) submits frame N+1 before it waits for frame N. On the CPU each
    /// frame takes every core and they are made one by one.
    pub in_flight: usize,
    /// A device image the frames' pixels stay in (`Tracer::render_to_device`), each frame
    /// overwriting the one before in order; `None`: every frame comes to the host.
    pub target: Option<&'a DeviceImage>,
    /// Called with the number of image rows finished (CPU frames only).
    pub progress: Option<&'a (dyn Fn(u32) + Sync)>,
}

impl Default for FramesOptions<'_> {
    fn default() -> Self {
        FramesOptions {
            in_flight: DEFAULT_IN_FLIGHT,
            target: None,
            progress: None,
        }
    }
}

/// A run of frames as a whole: throughput beside each frame's own latency (`RenderStats`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FramesStats {
    pub frames: u32,
    /// Rays of all frames.
    pub rays: u64,
    /// From the first frame's preparation to the last frame handed over (ms), the caller's
    /// work on each frame included.
    pub wall_ms: f64,
    /// Until the first frame was handed over (ms): it pays for pipelines and buffers.
    pub first_ms: f64,
    /// Rays of the first frame.
    pub first_rays: u64,
}

impl FramesStats {
    /// Frames a second after the first frame (the steady rate); `None` for a single frame.
    pub fn frames_per_s(&self) -> Option<f64> {
        let ms = self.wall_ms - self.first_ms;
        (self.frames > 1 && ms > 0.0).then(|| (self.frames - 1) as f64 / (ms * 1e-3))
    }

    /// Millions of rays a second of wall time after the first frame.
    pub fn mrays_per_s(&self) -> Option<f64> {
        let ms = self.wall_ms - self.first_ms;
        (self.frames > 1 && ms > 0.0).then(|| (self.rays - self.first_rays) as f64 / (ms * 1e3))
    }
}

/// A frame on its way: where it came from (to trace it again on the CPU should the GPU fail)
/// and what the device holds of it.
struct Pending {
    index: usize,
    camera: Camera,
    lights: Vec<PointLight>,
    /// `None` once the GPU that had it was given up.
    frame: Option<FrameInFlight>,
}

impl Tracer {
    /// Traces one frame per `(camera, lights)` of `views`, in order, and hands each to
    /// `on_frame` with its index as soon as it is done; `how` says how many frames the GPU may
    /// have in flight and where pixels go. Under `auto` a GPU that fails hands its frames in
    /// flight, and the rest, to the CPU (`render`'s rule); an error of `on_frame` ends the run.
    pub fn render_frames<I>(
        &mut self,
        views: I,
        opts: &RenderOptions,
        how: FramesOptions,
        mut on_frame: impl FnMut(usize, Rendered) -> Result<()>,
    ) -> Result<FramesStats>
    where
        I: IntoIterator<Item = (Camera, Vec<PointLight>)>,
    {
        let t0 = Instant::now();
        let mut run = FramesStats::default();
        let mut deliver = |run: &mut FramesStats, index: usize, frame: Rendered| {
            let rays = frame.stats().rays.total();
            if run.frames == 0 {
                run.first_ms = t0.elapsed().as_secs_f64() * 1e3;
                run.first_rays = rays;
            }
            on_frame(index, frame)?;
            run.frames += 1;
            run.rays += rays;
            run.wall_ms = t0.elapsed().as_secs_f64() * 1e3;
            Ok::<(), crate::Error>(())
        };
        let depth = how.in_flight.max(1);
        let mut flight: VecDeque<Pending> = VecDeque::with_capacity(depth);
        let mut views = views.into_iter().enumerate();
        loop {
            let next = views.next();
            let more = next.is_some();
            if let Some((index, (camera, lights))) = next {
                match self
                    .gpu
                    .as_mut()
                    .map(|g| g.submit_frame(&camera, &lights, opts, how.target))
                {
                    Some(Ok(frame)) => flight.push_back(Pending {
                        index,
                        camera,
                        lights,
                        frame: Some(frame),
                    }),
                    Some(Err(e)) => {
                        self.gpu_failed(e)?;
                        flight.push_back(Pending {
                            index,
                            camera,
                            lights,
                            frame: None,
                        });
                        self.frames_on_cpu(&mut flight, opts, &how, |i, f| deliver(&mut run, i, f))?;
                    }
                    None => {
                        let frame = self.render_with_progress(&camera, &lights, opts, how.progress)?;
                        deliver(&mut run, index, Rendered::OnHost(frame))?;
                    }
                }
            }
            if flight.len() >= depth || (!more && !flight.is_empty()) {
                let mut p = flight.pop_front().expect("a frame in flight");
                let (g, frame) = (
                    self.gpu.as_mut().expect("frames in flight only on a GPU"),
                    p.frame.take().expect("frames in flight are on the GPU"),
                );
                match g.finish_frame(frame) {
                    Ok((Some(image), s)) => deliver(
                        &mut run,
                        p.index,
                        Rendered::OnHost(Frame {
                            image,
                            stats: s.render,
                            gpu: Some(s),
                        }),
                    )?,
                    Ok((None, s)) => deliver(&mut run, p.index, Rendered::OnDevice(s))?,
                    Err(e) => {
                        self.gpu_failed(e)?;
                        flight.push_front(p);
                        self.frames_on_cpu(&mut flight, opts, &how, |i, f| deliver(&mut run, i, f))?;
                    }
                }
            }
            if !more && flight.is_empty() {
                return Ok(run);
            }
        }
    }

    /// The GPU was given up (`gpu_failed`): the frames it had in flight, traced again on the
    /// CPU in order.
    fn frames_on_cpu(
        &mut self,
        flight: &mut VecDeque<Pending>,
        opts: &RenderOptions,
        how: &FramesOptions,
        mut deliver: impl FnMut(usize, Rendered) -> Result<()>,
    ) -> Result<()> {
        while let Some(p) = flight.pop_front() {
            let frame = self.render_with_progress(&p.camera, &p.lights, opts, how.progress)?;
            deliver(p.index, Rendered::OnHost(frame))?;
        }
        Ok(())
    }
}
