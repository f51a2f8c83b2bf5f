//! The suite's frames: every structure with a GPU walk (brute force left out: a ray tests every
//! triangle) and every GPU variant, each frame's image checked against the CPU's before its
//! time counts, and the CPU's own time on the same frame for the ratio.

use gridtrace::AccelParams;
use std::collections::BTreeMap;
use std::sync::Arc;

use serde::Serialize;

use gridtrace::gpu::{DeviceImage, GpuContext, GpuRenderStats, GpuRenderer, GpuVariants, HostPhases, PrepareParts};
use gridtrace::render::differing_pixels;
use gridtrace::render::{Image, PixelFormat, RenderOptions};
use gridtrace::scene::PreparedScene;
use gridtrace::{AccelKind, Mesh, Mode, Result};

use super::{Budget, Plan};
use crate::scenes::BenchScene;
use crate::timing::{Summary, host_medians, interleaved};

/// Channel levels (of 255) a GPU pixel may differ from the CPU's by: float results rounded
/// differently (a GPU may fuse multiply-adds) move a shade by a level or two.
pub const PIXEL_TOLERANCE: u8 = 2;
/// Pixels that may differ beyond `PIXEL_TOLERANCE` (a fraction): a ray grazing an edge may
/// hit the neighbouring triangle on one side and not the other. More is a mismatch.
pub const MAX_DIFFERING: f64 = 0.002;
/// Timed CPU frames per measurement (the CPU is the ratio's anchor, not the question).
const CPU_REPS: u32 = 2;

/// One frame measurement.
#[derive(Debug, Clone, Serialize)]
pub struct FrameRow {
    pub scene: String,
    pub triangles: usize,
    pub accel: String,
    /// `gpu` or `cpu`.
    pub backend: String,
    /// The GPU variant (`-` on the CPU).
    pub variant: String,
    pub mode: String,
    pub width: u32,
    pub height: u32,
    /// Rays of one frame (eye, shadow, reflection).
    pub rays: u64,
    /// Wall time (host clock, uploads to image in host memory), ms.
    #[serde(flatten)]
    pub wall: Summary,
    /// GPU time (timestamps summed) of the timed frames: median, where the adapter has them.
    pub gpu_median_ms: Option<f64>,
    /// Rays per microsecond at the median wall time, and at the median GPU time.
    pub mrays_per_s: f64,
    pub gpu_mrays_per_s: Option<f64>,
    pub round_trips: u32,
    pub bytes_up: u64,
    pub bytes_down: u64,
    /// The last timed frame's stages (GPU timestamps), ms.
    pub stages_ms: BTreeMap<String, f64>,
    /// Medians of the wall time's parts on the host (prepare, wait, readout); `None` on the CPU.
    pub host_ms: Option<HostPhases>,
    /// Medians of the preparation's parts (buffers, uniforms, recording, submission); `None`
    /// on the CPU.
    pub prepare_ms: Option<PrepareParts>,
    /// Pixels differing from the CPU's image beyond `PIXEL_TOLERANCE` (fraction; 0 on the CPU).
    pub differing_from_cpu: f64,
}

/// A mesh alone in an auto-framed scene with a floor, for the frames.
pub fn mesh_bench_scene(name: &str, mesh: Mesh) -> BenchScene {
    let triangles = mesh.triangles.len();
    BenchScene {
        name: name.into(),
        title: name.into(),
        scene: gridtrace::scene::builtin::mesh_scene(mesh, true),
        triangles,
        paper_tris: None,
        paper_grid: None,
        description: format!("{name} on a floor, one light"),
    }
}

/// The structures the frames run on `gpu`: those with a GPU walk, brute force left out, and
/// `hwrt` only where the adapter has ray queries (`not_offered` says why it is left out).
pub fn frame_accels(gpu: &GpuContext) -> Vec<AccelKind> {
    AccelKind::ALL
        .into_iter()
        .filter(|k| k.entry().gpu && !k.entry().every_triangle)
        .filter(|&k| not_offered(gpu, k).is_none())
        .collect()
}

/// Why `accel` is left out on `gpu`, if it is: `hwrt` on an adapter without ray queries.
pub fn not_offered(gpu: &GpuContext, accel: AccelKind) -> Option<String> {
    let structure = accel.structure();
    let needs_rq = gridtrace::gpu::walks::WALKS
        .iter()
        .any(|w| w.structure == structure && w.tlas.is_some());
    (needs_rq && !gpu.ray_query).then(|| {
        format!(
            "{}: not offered by this adapter ({}: no ray queries)",
            accel.name(),
            gpu.info.name
        )
    })
}

/// The CPU's stand-in for `accel` where the CPU does not trace it (`hwrt`, the GPU's
/// ray-tracing hardware): the BVH, whose images and hits its frames and batches are checked
/// against. Every other structure is its own.
pub fn cpu_reference(accel: AccelKind) -> AccelKind {
    if accel.entry().cpu { accel } else { AccelKind::Bvh }
}

/// A renderer of `prepared` with the GPU variants `variant`.
pub fn open_gpu(ctx: &Arc<GpuContext>, prepared: &PreparedScene, variant: &GpuVariants) -> Result<GpuRenderer> {
    GpuRenderer::new(ctx.clone(), prepared, variant)
}

/// The variants that change anything for `accel`'s structure: the default, and each one that
/// applies (the BVH's layout and stack change only the BVH's walk).
pub fn variants_for(variants: &[GpuVariants], accel: AccelKind) -> impl Iterator<Item = &GpuVariants> {
    variants
        .iter()
        .filter(move |v| **v == GpuVariants::default() || v.applies_to(accel.structure()))
}

/// Every scene x structure x variant x mode, as long as the budget lasts.
#[allow(clippy::too_many_arguments)]
pub fn frame_matrix(
    plan: &Plan,
    gpu: &Arc<GpuContext>,
    scenes: &[BenchScene],
    variants: &[GpuVariants],
    budget: &Budget,
    skipped: &mut Vec<String>,
    mismatches: &mut Vec<String>,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<FrameRow>> {
    let mut rows = Vec::new();
    let (w, h) = plan.frame_size;
    for bs in scenes {
        for accel in frame_accels(gpu) {
            if !budget.allows(&format!("frames of {} with {}", bs.name, accel.name()), skipped) {
                continue;
            }
            let prepared = bs.scene.prepare_for(accel, &AccelParams::NONE)?;
            // The CPU's row and reference image: the structure's own, or its stand-in's.
            let on_cpu = cpu_reference(accel);
            let cpu_prepared = match on_cpu == accel {
                true => None,
                false => Some(bs.scene.prepare_for(on_cpu, &AccelParams::NONE)?),
            };
            let mut reference = Vec::new();
            for &mode in &plan.modes {
                let opts = RenderOptions::new(w, h, mode);
                let (row, image) = cpu_row(bs, cpu_prepared.as_ref().unwrap_or(&prepared), &opts)?;
                log(&row_line(&row));
                rows.push(row);
                reference.push(image.to_rgb8());
            }
            // Every variant's renderer at once, so that each mode's frames are timed in
            // rounds across the variants (`interleaved`).
            let mut renderers = variants_for(variants, accel)
                .map(|v| Ok((v.changes(), open_gpu(gpu, &prepared, v)?)))
                .collect::<Result<Vec<(String, GpuRenderer)>>>()?;
            for (k, &mode) in plan.modes.iter().enumerate() {
                // As `render` and the viewer ask: 8-bit pixels, packed on the device.
                let opts = RenderOptions::new(w, h, mode).with_pixels(PixelFormat::Srgb8);
                for row in gpu_rows(plan, bs, &prepared, &mut renderers, &opts, &reference[k], mismatches)? {
                    log(&row_line(&row));
                    rows.push(row);
                }
            }
        }
    }
    Ok(rows)
}

/// One large frame (trace, the BVH, default variant) on the GPU, read back and left on the
/// device, and on the CPU: the case where tiling and readback matter most.
pub fn big_frame(
    plan: &Plan,
    gpu: &Arc<GpuContext>,
    scenes: &[BenchScene],
    budget: &Budget,
    skipped: &mut Vec<String>,
    mismatches: &mut Vec<String>,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<FrameRow>> {
    let Some(bs) = scenes.first() else {
        return Ok(Vec::new());
    };
    if !budget.allows("the big frame", skipped) {
        return Ok(Vec::new());
    }
    let (w, h) = plan.big_frame;
    let prepared = bs.scene.prepare_for(AccelKind::Bvh, &AccelParams::NONE)?;
    let opts = RenderOptions::new(w, h, Mode::Trace);
    let (cpu, image) = cpu_row(bs, &prepared, &opts)?;
    log(&row_line(&cpu));
    let opts = opts.with_pixels(PixelFormat::Srgb8);
    let mut r = vec![(
        "default".to_string(),
        open_gpu(gpu, &prepared, &GpuVariants::default())?,
    )];
    let one = Plan {
        reps: 1,
        warmup_ms: 0.0,
        ..plan.clone()
    };
    let mut rows = vec![cpu];
    for row in gpu_rows(&one, bs, &prepared, &mut r, &opts, &image.to_rgb8(), mismatches)? {
        log(&row_line(&row));
        rows.push(row);
    }
    Ok(rows)
}

fn cpu_row(bs: &BenchScene, prepared: &PreparedScene, opts: &RenderOptions) -> Result<(FrameRow, Image)> {
    // The first render is the reference image and the warm-up.
    let (image, stats) = gridtrace::cpu::render(prepared, opts, None)?;
    let mut times = Vec::new();
    for _ in 0..CPU_REPS {
        times.push(gridtrace::cpu::render(prepared, opts, None)?.1.render_ms);
    }
    let wall = Summary::of(&times);
    let rays = stats.rays.total();
    Ok((
        FrameRow {
            scene: bs.name.clone(),
            triangles: bs.triangles,
            accel: prepared.accel.kind().name().into(),
            backend: "cpu".into(),
            variant: "-".into(),
            mode: opts.mode.name().into(),
            width: opts.width,
            height: opts.height,
            rays,
            wall,
            gpu_median_ms: None,
            mrays_per_s: rays as f64 / (wall.median_ms * 1e3).max(1e-9),
            gpu_mrays_per_s: None,
            round_trips: 0,
            bytes_up: 0,
            bytes_down: 0,
            stages_ms: BTreeMap::new(),
            host_ms: None,
            prepare_ms: None,
            differing_from_cpu: 0.0,
        },
        image,
    ))
}

/// The variant label of the row whose frames stay on the device (`render_to_device`, as the
/// viewer presents them): the default kernels, no image read back.
pub const ON_DEVICE_LABEL: &str = "image=device";

/// The variant label of the row whose frames are read back with frames in flight (frame N+1
/// submitted before frame N is read back, `GpuRenderer::submit_frame`): the default kernels;
/// its wall time is a run's time over its frames (the throughput), not one frame's latency.
pub const IN_FLIGHT_LABEL: &str = "in-flight=2";
/// Frames in flight in the `IN_FLIGHT_LABEL` row, and frames a measurement of it runs.
const IN_FLIGHT: usize = gridtrace::frames::DEFAULT_IN_FLIGHT;
const IN_FLIGHT_RUN: usize = 6;

/// The frames of `opts` on every renderer (a variant each, with its label), timed in rounds
/// across them; a row each, its last image checked against the CPU's `reference`. When the
/// first renderer has the default variants, one more row with frames in flight
/// (`IN_FLIGHT_LABEL`), and (unless the mode is heat) one with its frames left in a device
/// image (`ON_DEVICE_LABEL`), what the viewer waits for a frame; that image is read back once,
/// after the timing, for the check.
fn gpu_rows(
    plan: &Plan,
    bs: &BenchScene,
    prepared: &PreparedScene,
    renderers: &mut [(String, GpuRenderer)],
    opts: &RenderOptions,
    reference: &[u8],
    mismatches: &mut Vec<String>,
) -> Result<Vec<FrameRow>> {
    let device_image = match renderers.first() {
        Some((_, r)) if opts.mode != Mode::Heat && r.variants() == GpuVariants::default() => {
            DeviceImage::new(r.context(), opts.width, opts.height).ok()
        }
        _ => None,
    };
    let defaults = renderers
        .first()
        .is_some_and(|(_, r)| r.variants() == GpuVariants::default());
    let on_device = renderers.len();
    let in_flight = on_device + device_image.is_some() as usize;
    let n = in_flight + defaults as usize;
    let mut last: Vec<Option<Image>> = (0..n).map(|_| None).collect();
    // Warm-up: each variant at least once (pipelines, buffers), then until `warmup_ms` passed.
    let runs = interleaved(n, plan.warmup_ms, plan.reps, |k| {
        if k == on_device {
            let target = device_image.as_ref().expect("a device row only with its image");
            let s = renderers[0]
                .1
                .render_to_device(&prepared.camera, &prepared.lights, opts, target)?;
            return Ok((s.wall_ms, s));
        }
        if k == in_flight {
            let (ms, image, s) = frames_in_flight(&mut renderers[0].1, prepared, opts)?;
            last[k] = Some(image);
            return Ok((ms, s));
        }
        let (image, s) = renderers[k].1.render(&prepared.camera, &prepared.lights, opts)?;
        last[k] = Some(image);
        Ok((s.wall_ms, s))
    })?;
    let mut labels: Vec<&str> = renderers.iter().map(|(l, _)| l.as_str()).collect();
    if let Some(t) = &device_image {
        last[on_device] = Some(t.read()?);
        labels.push(ON_DEVICE_LABEL);
    }
    if defaults {
        labels.push(IN_FLIGHT_LABEL);
    }
    let mut rows = Vec::new();
    for (((walls, frames), image), label) in runs.into_iter().zip(last).zip(labels) {
        let image = image.expect("at least one timed frame");
        rows.push(gpu_row(
            bs,
            prepared.accel.kind(),
            opts,
            label,
            &walls,
            &frames,
            &image,
            reference,
            mismatches,
        ));
    }
    Ok(rows)
}

/// `IN_FLIGHT_RUN` frames of `opts` with `IN_FLIGHT` in flight: the milliseconds a frame of
/// the run (its wall time over its frames), the last frame's image and figures.
fn frames_in_flight(
    gpu: &mut GpuRenderer,
    prepared: &PreparedScene,
    opts: &RenderOptions,
) -> Result<(f64, Image, GpuRenderStats)> {
    let t0 = std::time::Instant::now();
    let mut flight = std::collections::VecDeque::with_capacity(IN_FLIGHT);
    let mut last = None;
    for _ in 0..IN_FLIGHT_RUN {
        flight.push_back(gpu.submit_frame(&prepared.camera, &prepared.lights, opts, None)?);
        if flight.len() >= IN_FLIGHT {
            last = Some(gpu.finish_frame(flight.pop_front().expect("in flight"))?);
        }
    }
    while let Some(f) = flight.pop_front() {
        last = Some(gpu.finish_frame(f)?);
    }
    let (image, stats) = last.expect("at least one frame");
    let ms = t0.elapsed().as_secs_f64() * 1e3 / IN_FLIGHT_RUN as f64;
    Ok((ms, image.expect("frames read back come to the host"), stats))
}

/// The medians, part by part, of frames' preparations.
fn prepare_medians(parts: impl Iterator<Item = PrepareParts> + Clone) -> PrepareParts {
    let med = |f: fn(PrepareParts) -> f64| Summary::of(&parts.clone().map(f).collect::<Vec<_>>()).median_ms;
    PrepareParts {
        buffers_ms: med(|p| p.buffers_ms),
        uniforms_ms: med(|p| p.uniforms_ms),
        record_ms: med(|p| p.record_ms),
        submit_ms: med(|p| p.submit_ms),
    }
}

/// One variant's row from its timed frames.
#[allow(clippy::too_many_arguments)]
fn gpu_row(
    bs: &BenchScene,
    accel: AccelKind,
    opts: &RenderOptions,
    variant: &str,
    walls: &[f64],
    frames: &[GpuRenderStats],
    image: &Image,
    reference: &[u8],
    mismatches: &mut Vec<String>,
) -> FrameRow {
    let wall = Summary::of(walls);
    let gpu_median_ms = Summary::median_of(frames.iter().filter_map(|s| s.gpu_ms()));
    let host = host_medians(frames.iter().map(|s| s.timings.host));
    let last = frames.last().expect("at least one timed frame");
    let rays = last.render.rays.total();
    let differing = differing_pixels(&image.to_rgb8(), reference, PIXEL_TOLERANCE);
    if differing > MAX_DIFFERING {
        mismatches.push(format!(
            "{} {} {} {} {}x{}: {:.3}% of pixels differ from the CPU's",
            bs.name,
            accel.name(),
            variant,
            opts.mode.name(),
            opts.width,
            opts.height,
            100.0 * differing
        ));
    }
    FrameRow {
        scene: bs.name.clone(),
        triangles: bs.triangles,
        accel: accel.name().into(),
        backend: "gpu".into(),
        variant: variant.into(),
        mode: opts.mode.name().into(),
        width: opts.width,
        height: opts.height,
        rays,
        wall,
        gpu_median_ms,
        mrays_per_s: rays as f64 / (wall.median_ms * 1e3).max(1e-9),
        gpu_mrays_per_s: gpu_median_ms.map(|ms| rays as f64 / (ms * 1e3).max(1e-9)),
        round_trips: last.round_trips,
        bytes_up: last.uploaded_bytes,
        bytes_down: last.downloaded_bytes,
        stages_ms: last
            .timings
            .stages_ms
            .iter()
            .map(|(k, v)| (k.to_string(), *v))
            .collect(),
        host_ms: Some(host),
        prepare_ms: Some(prepare_medians(frames.iter().map(|s| s.prepare_parts))),
        differing_from_cpu: differing,
    }
}

/// One line of the log for a row.
pub fn row_line(r: &FrameRow) -> String {
    let gpu = r.gpu_median_ms.map_or(String::new(), |ms| {
        format!(", GPU {ms:.2} ms ({:.1} Mrays/s)", r.gpu_mrays_per_s.unwrap_or(0.0))
    });
    format!(
        "  {:<15} {:<9} {:<3} {:<12} {:<6} {}x{}: wall {:.2} ms ({:.1} Mrays/s){gpu}",
        r.scene, r.accel, r.backend, r.variant, r.mode, r.width, r.height, r.wall.median_ms, r.mrays_per_s
    )
}
