//! Timing a measurement: repetitions after warm-ups, and their summary (median, best, mean).

use serde::Serialize;

use gridtrace::Result;
use gridtrace::gpu::{GpuRenderStats, GpuRenderer, HostPhases};
use gridtrace::render::{RayCounts, RenderOptions};
use gridtrace::scene::PreparedScene;

/// Median, best (minimum) and mean of a set of timings.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct Summary {
    pub median_ms: f64,
    pub best_ms: f64,
    pub mean_ms: f64,
}

impl Summary {
    /// The median of `times`, `None` when there are none (a GPU without timestamps).
    pub fn median_of(times: impl Iterator<Item = f64>) -> Option<f64> {
        let t: Vec<f64> = times.collect();
        (!t.is_empty()).then(|| Summary::of(&t).median_ms)
    }

    pub fn of(times: &[f64]) -> Summary {
        if times.is_empty() {
            return Summary::default();
        }
        let mut t = times.to_vec();
        t.sort_by(f64::total_cmp);
        let n = t.len();
        let median = if n % 2 == 1 {
            t[n / 2]
        } else {
            0.5 * (t[n / 2 - 1] + t[n / 2])
        };
        Summary {
            median_ms: median,
            best_ms: t[0],
            mean_ms: t.iter().sum::<f64>() / n as f64,
        }
    }
}

/// With warm-ups asked for, they go on at least this long (ms): a GPU frame of a few
/// milliseconds needs more than one run before clocks, caches and drivers settle, and a
/// count that suits a 2-second frame on a software adapter is far too few on hardware.
pub const WARMUP_MIN_MS: f64 = 500.0;

/// Times `f` after `warmup` warm-up runs (and more until `WARMUP_MIN_MS` have passed, when
/// `warmup` is not zero), then `reps` times, keeping the timed results.
pub fn repeat<T>(warmup: u32, reps: u32, f: impl FnMut() -> Result<(f64, T)>) -> Result<(Vec<f64>, Vec<T>)> {
    repeat_warm(warmup, WARMUP_MIN_MS, reps, f)
}

/// `repeat` with its own least warm-up time, `warmup_ms` (the hardware suite's plan sets it).
pub fn repeat_warm<T>(
    warmup: u32,
    warmup_ms: f64,
    reps: u32,
    mut f: impl FnMut() -> Result<(f64, T)>,
) -> Result<(Vec<f64>, Vec<T>)> {
    let started = std::time::Instant::now();
    let mut done = 0;
    while done < warmup || (warmup > 0 && started.elapsed().as_secs_f64() * 1e3 < warmup_ms) {
        f()?;
        done += 1;
    }
    let mut times = Vec::new();
    let mut outs = Vec::new();
    for _ in 0..reps.max(1) {
        let (t, o) = f()?;
        times.push(t);
        outs.push(o);
    }
    Ok((times, outs))
}

/// One CPU measurement: best, median and all times of a render, with its ray counts.
pub fn time_cpu(
    prepared: &PreparedScene,
    opts: &RenderOptions,
    warmup: u32,
    reps: u32,
) -> Result<(Vec<f64>, Summary, RayCounts)> {
    let (times, outs) = repeat(warmup, reps, || {
        let (_, s) = gridtrace::cpu::render(prepared, opts, None)?;
        Ok((s.render_ms, s.rays))
    })?;
    Ok((times.clone(), Summary::of(&times), outs[0]))
}

/// One GPU measurement: all times (wall time, upload to image in host memory, as every report
/// gives a GPU frame's time), their summary, and the statistics of the fastest frame (with its
/// GPU time from timestamps where the adapter has them).
pub fn time_gpu(
    gpu: &mut GpuRenderer,
    prepared: &PreparedScene,
    opts: &RenderOptions,
    warmup: u32,
    reps: u32,
) -> Result<(Vec<f64>, Summary, GpuRenderStats)> {
    let (times, mut outs) = repeat(warmup, reps, || {
        let (_, s) = gpu.render(&prepared.camera, &prepared.lights, opts)?;
        Ok((s.frame_ms(), s))
    })?;
    let summary = Summary::of(&times);
    let best = times
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)
        .unwrap_or(0);
    Ok((times, summary, outs.swap_remove(best)))
}

/// Times `n` alternatives (GPU variants) in rounds: warm-up rounds (each alternative at least
/// once, and rounds until `warmup_ms` have passed), then `reps` rounds in which each runs once
/// in turn; per alternative, its times and results in order. A GPU's clocks follow its load:
/// on the first hardware run (H200), whose frames kept the GPU busy a tenth of the time, one
/// variant's GPU time drifted 3x over a block of runs, so variants timed in blocks one after
/// another compared clock states more than code. In rounds every alternative meets the same
/// drift.
pub fn interleaved<T>(
    n: usize,
    warmup_ms: f64,
    reps: u32,
    mut f: impl FnMut(usize) -> Result<(f64, T)>,
) -> Result<Vec<(Vec<f64>, Vec<T>)>> {
    let started = std::time::Instant::now();
    loop {
        for k in 0..n {
            f(k)?;
        }
        if started.elapsed().as_secs_f64() * 1e3 >= warmup_ms {
            break;
        }
    }
    let mut out: Vec<(Vec<f64>, Vec<T>)> = (0..n).map(|_| (Vec::new(), Vec::new())).collect();
    for _ in 0..reps.max(1) {
        for (k, o) in out.iter_mut().enumerate() {
            let (t, r) = f(k)?;
            o.0.push(t);
            o.1.push(r);
        }
    }
    Ok(out)
}

/// The medians, phase by phase, of the host's phases of GPU frames or batches.
pub fn host_medians(phases: impl Iterator<Item = HostPhases> + Clone) -> HostPhases {
    let med = |f: fn(HostPhases) -> f64| Summary::of(&phases.clone().map(f).collect::<Vec<_>>()).median_ms;
    HostPhases {
        prepare_ms: med(|h| h.prepare_ms),
        wait_ms: med(|h| h.wait_ms),
        readout_ms: med(|h| h.readout_ms),
    }
}
