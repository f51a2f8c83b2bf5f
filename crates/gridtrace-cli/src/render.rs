//! `gridtrace render`: one image of a scene.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use glam::Vec3;
use gridtrace::scene::PointLight;
use gridtrace::{Mode, RenderOptions};
use indicatif::{ProgressBar, ProgressStyle};

use crate::common::{Backend, GridArgs, SceneArgs, open_gpu, parse_res, parse_vec3};

#[derive(Args)]
pub struct RenderArgs {
    #[command(flatten)]
    scene: SceneArgs,
    #[command(flatten)]
    grid: GridArgs,
    /// cast (eye rays), shadow (+ shadow rays), trace (+ two levels of reflection), heat (cost).
    #[arg(long, default_value = "trace", value_parser = |s: &str| s.parse::<Mode>())]
    mode: Mode,
    /// Image size WxH.
    #[arg(long, default_value = "512x512", value_parser = parse_res)]
    res: (u32, u32),
    /// Camera position (overrides the scene's).
    #[arg(long, value_parser = parse_vec3)]
    eye: Option<Vec3>,
    /// Camera target.
    #[arg(long, value_parser = parse_vec3)]
    target: Option<Vec3>,
    /// Camera up vector.
    #[arg(long, value_parser = parse_vec3)]
    up: Option<Vec3>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    vfov: Option<f32>,
    /// A point light at x,y,z (repeatable; replaces the scene's lights). Its intensity is set
    /// so that it lights the scene centre with unit irradiance.
    #[arg(long, value_parser = parse_vec3)]
    light: Vec<Vec3>,
    /// Where to trace: auto (GPU if present, else CPU), gpu or cpu.
    #[arg(long, default_value = "auto", value_parser = |s: &str| s.parse::<Backend>())]
    backend: Backend,
    /// Count traversal work (cells, jumps, triangle tests) and print it.
    #[arg(long)]
    stats: bool,
    /// Output PNG.
    #[arg(short, long, default_value = "gridtrace.png")]
    output: PathBuf,
}

pub fn run(a: RenderArgs) -> gridtrace::Result<()> {
    let (mut scene, name) = a.scene.load()?;
    if let Some(e) = a.eye {
        scene.camera.eye = e;
    }
    if let Some(t) = a.target {
        scene.camera.target = t;
    }
    if let Some(u) = a.up {
        scene.camera.up = u;
    }
    if let Some(v) = a.vfov {
        scene.camera.vfov_deg = v;
    }
    if !a.light.is_empty() {
        let c = scene.bounds().center();
        scene.lights = a
            .light
            .iter()
            .map(|&p| PointLight::new(p, Vec3::splat((p - c).length_squared())))
            .collect();
    }
    let t_build = Instant::now();
    let prepared = crate::common::prepare(&scene, &name, a.grid.grid)?;
    let build_ms = t_build.elapsed().as_secs_f64() * 1e3;
    let g = &prepared.accel.grid.stats;
    println!(
        "scene {name}: {} triangles ({} degenerate dropped), grid {}x{}x{}, {:.2} refs/tri",
        prepared.accel.tris.len(),
        prepared.degenerate_dropped,
        g.dims[0],
        g.dims[1],
        g.dims[2],
        g.refs_per_triangle()
    );
    println!("build   {build_ms:.1} ms (grid {:.1} ms)", g.build_ms);

    let opts = RenderOptions::new(a.res.0, a.res.1, a.mode, a.grid.accel);
    let (image, stats) = match open_gpu(a.backend, a.grid.accel)? {
        Some(ctx) => {
            println!("backend gpu: {}", ctx.describe());
            if ctx.is_software() {
                println!("        (a software adapter: CPU speed, not GPU speed)");
            }
            let mut gpu = gridtrace::gpu::GpuRenderer::new(std::sync::Arc::new(ctx), &prepared)?;
            let (image, s) = gpu.render(&prepared.camera, &prepared.lights, &opts)?;
            let source = if s.timings.from_timestamps {
                "GPU timestamps"
            } else {
                "wall clock, no timestamp queries"
            };
            let stages: Vec<String> = s.timings.stages_ms.iter().map(|(k, v)| format!("{k} {v:.2}")).collect();
            println!(
                "stages  {} ms ({source}; {} tile{})",
                stages.join(", "),
                s.tiles,
                if s.tiles == 1 { "" } else { "s" }
            );
            // Rays per second by kind, from the stage that traces them.
            let rate = |rays: u64, stage: &str| {
                s.timings
                    .stages_ms
                    .get(stage)
                    .filter(|ms| **ms > 0.0)
                    .map(|ms| rays as f64 / (ms * 1e3))
            };
            let r = s.render.rays;
            if let Some(v) = rate(r.eye + r.reflection, "traverse") {
                print!("rates   eye+reflection {v:.2} Mrays/s (traverse)");
                if let Some(v) = rate(r.shadow, "occlusion") {
                    print!(", shadow {v:.2} Mrays/s (occlusion)");
                }
                println!();
            }
            (image, s.render)
        }
        None => {
            println!("backend cpu ({} threads)", rayon::current_num_threads());
            let bar = (std::io::stderr().is_terminal() && (a.res.0 as u64 * a.res.1 as u64) >= 512 * 512).then(|| {
                let b = ProgressBar::new(a.res.1 as u64);
                b.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} rows {elapsed}").unwrap());
                b
            });
            let tick = |rows: u32| {
                if let Some(b) = &bar {
                    b.inc(rows as u64);
                }
            };
            let result = if a.stats {
                gridtrace::cpu::render_with_counters(&prepared, &opts)?
            } else {
                gridtrace::cpu::render(&prepared, &opts, Some(&tick))?
            };
            if let Some(b) = bar {
                b.finish_and_clear();
            }
            result
        }
    };
    let r = stats.rays;
    println!(
        "render  {:.1} ms, {} rays (eye {}, shadow {}, reflection {}), {:.2} Mrays/s  [{} {} {}x{}]",
        stats.render_ms,
        r.total(),
        r.eye,
        r.shadow,
        r.reflection,
        stats.mrays_per_s(),
        a.mode.name(),
        a.grid.accel.name(),
        a.res.0,
        a.res.1
    );
    if a.stats && stats.counters.cells > 0 {
        let c = stats.counters;
        let n = r.total().max(1) as f64;
        println!(
            "work    {:.2} cells, {:.2} jumps, {:.2} triangle tests per ray",
            c.cells as f64 / n,
            c.jumps as f64 / n,
            c.tri_tests as f64 / n
        );
    }
    let out = if a.mode == Mode::Heat {
        image.heat_to_color()
    } else {
        image
    };
    out.save_png(&a.output)?;
    println!("wrote   {}", a.output.display());
    Ok(())
}
