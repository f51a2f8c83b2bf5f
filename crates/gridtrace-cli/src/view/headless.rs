//! `gridtrace view --headless`: the viewer's frames without a window, for measurement. The
//! camera goes once round its orbit (with `--orbit`) while the lights circle the scene the
//! other way, so every frame has a new camera and new lights, as an interactive session does;
//! each frame is traced whole by the viewer's tracer and timed. Prints every frame, then the
//! first frame and the median, 95th percentile and best of the rest, in ms and Mrays/s.
//!
//! On a GPU each frame stays on the device, as the window presents it (a `DeviceImage`; heat
//! frames excepted, which are coloured on the host): what is timed is what the viewer waits.
//! `--readback` brings every frame to the host instead, as `render` does.

use glam::{Quat, Vec3};
use gridtrace::gpu::DeviceImage;
use gridtrace::scene::{PointLight, Scene};
use gridtrace::{FramesOptions, Mode, PixelFormat, RenderOptions};

use super::ViewArgs;
use crate::render::orbit;

/// The lights `turn` of the way round the other way, about the camera's up axis through `centre`.
fn circle_lights(lights: &[PointLight], up: Vec3, centre: Vec3, turn: f32) -> Vec<PointLight> {
    let rot = Quat::from_axis_angle(up.normalize_or(Vec3::Y), -turn * std::f32::consts::TAU);
    lights
        .iter()
        .map(|l| {
            PointLight::new(
                centre + rot * (Vec3::from(l.position) - centre),
                Vec3::from(l.intensity),
            )
        })
        .collect()
}

pub fn run(a: &ViewArgs, src: Scene, name: &str) -> gridtrace::Result<()> {
    let spec = a.accel_args.spec()?;
    let opened = gridtrace::open_scene(&src, &spec, gridtrace::Work::Render, a.backend, a.gpu.gpu_variant)
        .map_err(|e| crate::common::named(name, e))?;
    let (mut tracer, accel) = (opened.tracer, opened.accel);
    println!(
        "scene {name}: {} triangles, {} (prepared in {:.0} ms)",
        tracer.scene.accel.tris.len(),
        crate::common::describe_structure(&tracer.scene.accel),
        opened.build_ms
    );
    for n in opened.notes {
        eprintln!("note: {n}");
    }
    println!("tracer {}", tracer.describe());
    if tracer.gpu().is_some_and(|g| g.context().is_software()) {
        println!("       (a software adapter: CPU speed, not GPU speed)");
    }
    let (w, h) = a.res;
    let opts = RenderOptions::new(w, h, a.mode).with_pixels(PixelFormat::Srgb8);
    // As the window does: a frame larger than one storage binding is read back instead.
    let (target, why) = match tracer.gpu() {
        Some(g) if !a.readback && a.mode != Mode::Heat => match DeviceImage::new(g.context(), w, h) {
            Ok(t) => (Some(t), String::new()),
            Err(e) => (None, format!(" ({e})")),
        },
        _ => (None, String::new()),
    };
    if tracer.gpu().is_some() {
        match &target {
            Some(_) => println!("image   stays on the device, as the window presents it (--readback: to the host)"),
            None => println!("image   read back to the host every frame{why}"),
        }
    }
    let centre = src.bounds().center();
    let (camera0, lights0) = (src.camera, src.lights.clone());
    // (wall ms, GPU ms where there are timestamps, Mrays/s by wall time)
    let mut frames: Vec<(f64, Option<f64>, f64)> = Vec::with_capacity(a.frames as usize);
    let mut uploaded = 0;
    let views = (0..a.frames).map(|i| {
        let turn = i as f32 / a.frames as f32;
        let camera = if a.orbit { orbit(&camera0, turn) } else { camera0 };
        (camera, circle_lights(&lights0, camera0.up, centre, turn))
    });
    let how = FramesOptions {
        in_flight: a.in_flight,
        target: target.as_ref(),
        progress: None,
    };
    let run = tracer.render_frames(views, &opts, how, |i, f| {
        let (rays, gpu) = (f.stats().rays, f.gpu());
        // The frame's latency: from its preparation to its pixels in place (the device image,
        // or host memory), what the viewer waits for one frame.
        let ms = gpu.map_or(f.stats().render_ms, |g| g.wall_ms);
        let gpu_ms = gpu.filter(|g| g.timings.from_timestamps).map(|g| g.timings.total_ms);
        uploaded = gpu.map_or(0, |g| g.uploaded_bytes);
        let rate = rays.total() as f64 / (ms * 1e3);
        // Wall time first (what the viewer waits), then the device's, its round trips and
        // the bytes read back: the same fields `render` and `bench` report.
        let trips = gpu.map_or(String::new(), |g| {
            format!(
                ", {} round trip(s), {} B down; host {}",
                g.round_trips, g.downloaded_bytes, g.timings.host
            )
        });
        println!(
            "frame {i:4}  {ms:8.2} ms{}  {rate:8.2} Mrays/s  ({} rays{trips})",
            gpu_ms.map_or(String::new(), |g| format!("  (gpu {g:.2} ms)")),
            rays.total()
        );
        frames.push((ms, gpu_ms, rate));
        Ok(())
    })?;
    for n in tracer.take_notes() {
        println!("note: {n}");
    }
    let (first, rest) = frames.split_first().expect("at least one frame");
    println!(
        "first   {:.2} ms, {:.2} Mrays/s  [{} {} {}x{}{}]",
        first.0,
        first.2,
        a.mode.name(),
        accel.name(),
        w,
        h,
        if a.orbit { ", orbit" } else { "" }
    );
    if !rest.is_empty() {
        let ms: Vec<f64> = rest.iter().map(|f| f.0).collect();
        let rates: Vec<f64> = rest.iter().map(|f| f.2).collect();
        let s = Summary::of(&ms);
        // Rates rank the other way: the p95 frame is the 5th percentile of rates.
        let r = Summary::of(&rates);
        println!(
            "rest    {} frames: median {:.2} ms ({:.2} Mrays/s), p95 {:.2} ms ({:.2} Mrays/s), best {:.2} ms ({:.2} Mrays/s)",
            rest.len(),
            s.median,
            r.median,
            s.p95,
            r.p05,
            s.best,
            r.worst
        );
        let gpu: Vec<f64> = rest.iter().filter_map(|f| f.1).collect();
        if gpu.len() == rest.len() {
            let g = Summary::of(&gpu);
            println!(
                "gpu     median {:.2} ms, p95 {:.2} ms, best {:.2} ms (timestamps, all stages)",
                g.median, g.p95, g.best
            );
        }
    }
    if let (Some(fps), Some(mrays)) = (run.frames_per_s(), run.mrays_per_s()) {
        let how = match tracer.gpu() {
            Some(_) => format!("{} in flight", a.in_flight.max(1)),
            None => "one by one".into(),
        };
        println!("rate    {fps:.1} frames/s, {mrays:.2} Mrays/s of wall time after the first frame ({how})");
    }
    if uploaded > 0 {
        println!("upload  {uploaded} B per frame (camera, lights, pass uniforms)");
    }
    Ok(())
}

/// Order statistics of a series: `best` the smallest, `worst` the largest, `p95` the value 95%
/// of the series are at or below, `p05` the value 5% are at or below.
struct Summary {
    best: f64,
    median: f64,
    p95: f64,
    p05: f64,
    worst: f64,
}

impl Summary {
    fn of(v: &[f64]) -> Summary {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
        Summary {
            best: v[0],
            median: at(0.5),
            p95: at(0.95),
            p05: at(0.05),
            worst: v[v.len() - 1],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_ranks() {
        let v: Vec<f64> = (1..=21).rev().map(f64::from).collect();
        let s = Summary::of(&v);
        assert_eq!((s.best, s.median, s.p95, s.p05, s.worst), (1.0, 11.0, 20.0, 2.0, 21.0));
        let one = Summary::of(&[3.0]);
        assert_eq!((one.best, one.median, one.p95), (3.0, 3.0, 3.0));
    }

    #[test]
    fn lights_circle_at_their_distance() {
        let l = [PointLight::new(Vec3::new(2.0, 3.0, 0.0), Vec3::ONE)];
        let q = circle_lights(&l, Vec3::Y, Vec3::ZERO, 0.25);
        let p = Vec3::from(q[0].position);
        assert!((p - Vec3::new(0.0, 3.0, 2.0)).length() < 1e-5, "{p}");
        assert_eq!(q[0].intensity, l[0].intensity);
    }
}
