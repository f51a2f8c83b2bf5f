//! `gridtrace render`: one image of a scene.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use glam::Vec3;
use gridtrace::scene::PointLight;
use gridtrace::{Mode, RenderOptions};
use indicatif::{ProgressBar, ProgressStyle};

use crate::common::{Backend, GridArgs, SceneArgs, backend_parser, mode_parser, open_gpu, parse_res, parse_vec3};

// Every number and x,y,z option takes `allow_hyphen_values`: without it clap reads
// `--target -0.0169,0.11,-0.0016` as a new flag "-0" and suggests "-- -1", which is wrong here.
#[derive(Args)]
pub struct RenderArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// With a mesh file: leave out the floor of the auto-framed scene (the mesh alone).
    #[arg(long)]
    no_floor: bool,
    #[command(flatten)]
    grid: GridArgs,
    /// cast (eye rays), shadow (+ shadow rays), trace (+ two levels of reflection), heat (cost).
    #[arg(long, default_value = "trace", value_parser = mode_parser())]
    mode: Mode,
    /// Image size in pixels: WxH, or N for a square N x N image.
    #[arg(long, value_name = "WxH|N", default_value = "512x512", value_parser = parse_res, allow_hyphen_values = true)]
    res: (u32, u32),
    /// Camera position x,y,z (overrides the scene's), e.g. --eye -1,2,3.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    eye: Option<Vec3>,
    /// Camera target x,y,z (the point at the image centre).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    target: Option<Vec3>,
    /// Camera up vector x,y,z.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    up: Option<Vec3>,
    /// Vertical field of view in degrees.
    #[arg(long, value_name = "DEGREES", allow_hyphen_values = true)]
    vfov: Option<f32>,
    /// A point light at x,y,z (repeatable; replaces the scene's lights). Its intensity is set
    /// so that it lights the scene centre with unit irradiance.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    light: Vec<Vec3>,
    /// Where to trace: auto (GPU if present, else CPU), gpu or cpu.
    #[arg(long, default_value = "auto", value_parser = backend_parser())]
    backend: Backend,
    /// Count traversal work (cells, jumps, triangle tests) and print it.
    #[arg(long)]
    stats: bool,
    /// Output PNG.
    #[arg(short, long, default_value = "gridtrace.png")]
    output: PathBuf,
}

pub fn run(a: RenderArgs) -> gridtrace::Result<()> {
    let (mut scene, name) = a.scene.load(!a.no_floor)?;
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
    // Without lights only the ambient term shows (and shadow rays have nothing to test): a
    // nearly black image that looks like a bug unless we say why. Heat images do not shade.
    if scene.lights.is_empty() && a.mode != Mode::Heat {
        eprintln!(
            "warning: scene {name} has no lights: only the ambient term lights it (add [[light]] \
             tables to the scene file, or --light X,Y,Z)"
        );
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
            let mut gpu = gridtrace::gpu::GpuRenderer::new(ctx, &prepared)?;
            // The GPU path reports no progress: a spinner at least shows it is working.
            let spinner = spinner(a.res, "rendering on the GPU");
            let rendered = gpu.render(&prepared.camera, &prepared.lights, &opts);
            if let Some(b) = spinner {
                b.finish_and_clear();
            }
            let (image, s) = rendered?;
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
            let result = if a.stats {
                // The counting renderer takes no progress callback: a spinner instead.
                let spinner = spinner(a.res, "rendering on the CPU (counting traversal work)");
                let r = gridtrace::cpu::render_with_counters(&prepared, &opts);
                if let Some(b) = spinner {
                    b.finish_and_clear();
                }
                r
            } else {
                // `cpu::render` calls back with the number of image rows each finished band
                // holds, from the worker threads; a bar of rows fits that.
                let bar = show_progress(a.res).then(|| {
                    let b = ProgressBar::new(a.res.1 as u64);
                    b.set_style(
                        ProgressStyle::with_template("{bar:40} {pos}/{len} rows {elapsed} (eta {eta})")
                            .expect("valid template"),
                    );
                    b
                });
                let tick = |rows: u32| {
                    if let Some(b) = &bar {
                        b.inc(rows as u64);
                    }
                };
                let r = gridtrace::cpu::render(&prepared, &opts, Some(&tick));
                if let Some(b) = bar {
                    b.finish_and_clear();
                }
                r
            };
            result?
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

/// Whether to draw progress: only on a terminal (piped or captured stderr stays exactly as it
/// was) and only for images of at least 512x512 pixels (smaller ones finish before a bar helps).
fn show_progress(res: (u32, u32)) -> bool {
    std::io::stderr().is_terminal() && res.0 as u64 * res.1 as u64 >= 512 * 512
}

/// A ticking spinner for renders that report no progress, under the same rule as the bar.
fn spinner(res: (u32, u32), what: &str) -> Option<ProgressBar> {
    show_progress(res).then(|| {
        let b = ProgressBar::new_spinner();
        b.set_style(ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("valid template"));
        b.set_message(format!("{what}, {}x{} pixels", res.0, res.1));
        b.enable_steady_tick(std::time::Duration::from_millis(120));
        b
    })
}
