//! `gridtrace render`: one image of a scene.

use std::io::IsTerminal;
use std::path::PathBuf;

use clap::Args;
use clap::builder::TypedValueParser;
use glam::Vec3;
use gridtrace::scene::PointLight;
use gridtrace::{FramesOptions, FramesStats, Mode, PixelFormat, RenderOptions};
use indicatif::{ProgressBar, ProgressStyle};

use crate::common::{
    AccelArgs, Backend, GpuFigures, GpuVariantArgs, SceneArgs, backend_parser, mode_parser, parse_image_output,
    parse_res, parse_vec3, print_gpu_figures,
};

// Every number and x,y,z option takes `allow_hyphen_values`: without it clap reads
// `--target -0.0169,0.11,-0.0016` as a new flag "-0" and suggests "-- -1", which is wrong here.
#[derive(Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// With a mesh file: leave out the floor of the auto-framed scene (the mesh alone).
    #[arg(long)]
    no_floor: bool,
    #[command(flatten)]
    pub accel_args: AccelArgs,
    /// cast (eye rays), shadow (+ shadow rays), trace (+ two levels of reflection), heat (cost).
    /// Default trace; with --animate --scene tumbling-bunnies, cast.
    #[arg(long, value_parser = mode_parser())]
    mode: Option<Mode>,
    /// Image size in pixels: WxH, or N for a square N x N image.
    #[arg(long, value_name = "WxH|N", default_value = "512x512", value_parser = parse_res, allow_hyphen_values = true)]
    pub res: (u32, u32),
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
    /// so that it lights the scene centre with unit irradiance, or given as X,Y,Z:R,G,B (as the
    /// viewer's screenshots print it).
    #[arg(long, value_name = "X,Y,Z[:R,G,B]", value_parser = parse_light, allow_hyphen_values = true)]
    light: Vec<(Vec3, Option<Vec3>)>,
    /// Where to trace: auto (GPU if present, else CPU), gpu or cpu.
    #[arg(long, default_value = "auto", value_parser = backend_parser())]
    pub backend: Backend,
    #[command(flatten)]
    pub gpu: GpuVariantArgs,
    /// Count traversal work (cells, jumps, triangle tests) and print it. Not with --animate
    /// (its frames print their build and trace times; the counts are not kept there).
    #[arg(long, conflicts_with = "animate")]
    stats: bool,
    /// Frames to render (the first is written): the first frame's time and the median and best
    /// of the rest are reported, so the figure compares with `bench` (warm, not one cold frame).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100_000), allow_hyphen_values = true)]
    pub frames: u32,
    /// With --frames: frames the GPU may have in flight. 2 (the default) prepares and submits
    /// frame N+1 before it reads back frame N; 1 traces them one by one. The CPU makes frames one
    /// by one (each takes every core). Not with --animate (each frame's structure update waits
    /// for the frame before).
    #[arg(long, conflicts_with = "animate", default_value_t = gridtrace::frames::DEFAULT_IN_FLIGHT, value_parser = clap::value_parser!(u64).range(1..=16).map(|n| n as usize), allow_hyphen_values = true)]
    pub in_flight: usize,
    /// Move the camera along a circle around its target over the frames (about the up axis,
    /// one turn in all): the paper's dynamic camera. Not with --animate (its camera stays put
    /// while the scene moves).
    #[arg(long, conflicts_with = "animate")]
    orbit: bool,
    /// Play an animated scene (--scene animated, twisting-knot or bouncing-spheres; default
    /// animated) over the frames: every frame moves the vertices, updates the structure (the
    /// grids rebuilt, on the GPU with the GPU backend; the BVH refitted) and traces. Prints each
    /// frame's build and trace times. --scene tumbling-bunnies: --instances rigid Bunnies, each
    /// frame moving them (the top level of two alone) and tracing eye rays, headlight-shaded,
    /// or lit by --light (with shadow rays under --mode shadow or trace; heat is refused).
    #[arg(long)]
    pub animate: bool,
    /// With --animate: frames per second of animation time.
    #[arg(long, default_value_t = 30.0, requires = "animate", allow_hyphen_values = true)]
    pub fps: f32,
    /// With --animate: also write every frame as DIR/frame_0000.png, ...
    #[arg(long, value_name = "DIR", requires = "animate")]
    pub sequence: Option<PathBuf>,
    /// With --animate --scene tumbling-bunnies: how many instances tumble (default 1000).
    #[arg(long, value_name = "N", requires = "animate", value_parser = clap::value_parser!(u32).range(1..=gridtrace::scene::tumbling::MAX_INSTANCES as i64), allow_hyphen_values = true)]
    pub instances: Option<u32>,
    /// With --animate --scene tumbling-bunnies: the mesh placed (default the Stanford Bunny,
    /// bunny/bun_zipper.ply in the mesh folder: $GRIDTRACE_DATA_DIR, else shared/data/meshes
    /// beside the checkout).
    #[arg(long, value_name = "PATH", requires = "animate")]
    pub instance_mesh: Option<PathBuf>,
    /// Output image: PNG, or JPEG for a .jpg or .jpeg name (the extension names the format).
    /// Checked before any work, with the folder it goes into.
    #[arg(short, long, default_value = "gridtrace.png", value_parser = parse_image_output)]
    pub output: PathBuf,
}

impl RenderArgs {
    /// `--mode`, trace where none was given.
    pub fn mode(&self) -> Mode {
        self.mode.unwrap_or(Mode::Trace)
    }

    /// `--mode` as given (`None`: not given), for a scene whose default is not trace.
    pub fn mode_given(&self) -> Option<Mode> {
        self.mode
    }

    /// `camera` with what --eye, --target, --up and --vfov set in its place.
    pub fn camera_over(&self, camera: gridtrace::scene::Camera) -> gridtrace::scene::Camera {
        gridtrace::scene::Camera {
            eye: self.eye.unwrap_or(camera.eye),
            target: self.target.unwrap_or(camera.target),
            up: self.up.unwrap_or(camera.up),
            vfov_deg: self.vfov.unwrap_or(camera.vfov_deg),
        }
    }

    /// The camera options given, as typed ("--eye 1,2,3 --vfov 30"), for errors about the
    /// camera they make; empty where none was.
    pub fn camera_args(&self) -> String {
        let v = |p: Vec3| format!("{},{},{}", p.x, p.y, p.z);
        [
            self.eye.map(|p| format!("--eye {}", v(p))),
            self.target.map(|p| format!("--target {}", v(p))),
            self.up.map(|p| format!("--up {}", v(p))),
            self.vfov.map(|d| format!("--vfov {d}")),
        ]
        .into_iter()
        .flatten()
        .collect::<Vec<_>>()
        .join(" ")
    }

    /// The `--light` lights (none where none was given): each at its point, with its intensity,
    /// or where none is given one that lights `center` with unit irradiance.
    pub fn lights(&self, center: Vec3) -> Vec<PointLight> {
        self.light
            .iter()
            .map(|&(p, i)| PointLight::new(p, i.unwrap_or(Vec3::splat((p - center).length_squared()))))
            .collect()
    }
}

pub fn run(a: RenderArgs) -> gridtrace::Result<()> {
    let (mut scene, name) = a.scene.load(!a.no_floor)?;
    set_view(&a, &mut scene, &name);
    let mut renderer = open_tracer(&a, &scene, &name)?;
    let opts = RenderOptions::new(a.res.0, a.res.1, a.mode()).with_pixels(PixelFormat::Srgb8);
    let traced = trace_frames(&a, &mut renderer, &opts)?;
    report(&a, &renderer, &traced);
    let image = traced.first.image;
    let out = if a.mode() == Mode::Heat {
        image.heat_to_color()
    } else {
        image
    };
    out.save_png(&a.output)?;
    println!("wrote   {}", a.output.display());
    Ok(())
}

/// The camera and lights the options give in place of the scene's, and a warning for a scene
/// left without lights.
pub(crate) fn set_view(a: &RenderArgs, scene: &mut gridtrace::Scene, name: &str) {
    scene.camera = a.camera_over(scene.camera);
    if !a.light.is_empty() {
        scene.lights = a.lights(scene.bounds().center());
    }
    // Without lights only the ambient term shows (and shadow rays have nothing to test): a
    // nearly black image that looks like a bug unless we say why. Heat images do not shade.
    if scene.lights.is_empty() && a.mode() != Mode::Heat {
        eprintln!(
            "warning: scene {name} has no lights: only the ambient term lights it (add [[light]] \
             tables to the scene file, or --light X,Y,Z)"
        );
    }
}

/// The scene opened along the library's one path (`gridtrace::open_scene`) with `--accel`,
/// `--backend` and `--gpu-variant`, for `work`: a still frame's (`render`) or an animation's
/// (`render --animate`), which both open theirs here so that neither drops an option.
pub(crate) fn open_scene(
    a: &RenderArgs,
    scene: &gridtrace::Scene,
    name: &str,
    work: gridtrace::Work,
) -> gridtrace::Result<gridtrace::OpenedScene> {
    let spec = a.accel_args.spec()?;
    gridtrace::open_scene(scene, &spec, work, a.backend, a.gpu.gpu_variant).map_err(|e| crate::common::named(name, e))
}

/// The notes of opening a tracer, then its `backend` line: the GPU's adapter (whether it is a
/// software one, whose speed is the CPU's, and the GPU variants it runs) or the CPU's threads.
pub(crate) fn print_tracer(tracer: &gridtrace::Tracer, notes: &[String]) {
    for n in notes {
        eprintln!("note: {n}");
    }
    match tracer.gpu() {
        Some(gpu) => {
            println!("backend gpu: {}", gpu.context().describe());
            if gpu.context().is_software() {
                println!("        (a software adapter: CPU speed, not GPU speed)");
            }
            println!("        gpu variants: {}", gpu.variants().changes());
        }
        None => println!("backend {}", gridtrace::backend::describe_cpu()),
    }
}

/// The scene prepared for the structure `--accel` resolves to, on the device `--backend`
/// gives, with what was chosen printed.
fn open_tracer(a: &RenderArgs, scene: &gridtrace::Scene, name: &str) -> gridtrace::Result<gridtrace::Tracer> {
    let opened = open_scene(a, scene, name, gridtrace::Work::Render)?;
    let prepared = &opened.tracer.scene;
    println!(
        "scene {name}: {} triangles ({} degenerate dropped), {}",
        prepared.accel.tris.len(),
        prepared.degenerate_dropped,
        crate::common::describe_structure(&prepared.accel)
    );
    println!("build   {:.1} ms", opened.build_ms);
    print_tracer(&opened.tracer, &opened.notes);
    Ok(opened.tracer)
}

/// The frames of a run: the first (the one written), every frame's figures, the last GPU
/// frame's, and the run's throughput (none for the counting renderer).
struct Traced {
    first: gridtrace::Frame,
    frames: Vec<gridtrace::RenderStats>,
    last_gpu: Option<gridtrace::gpu::GpuRenderStats>,
    run: Option<FramesStats>,
}

/// Traces `--frames` frames (along the orbit with `--orbit`), with a bar or spinner.
fn trace_frames(a: &RenderArgs, renderer: &mut gridtrace::Tracer, opts: &RenderOptions) -> gridtrace::Result<Traced> {
    let (camera0, lights) = (renderer.scene.camera, renderer.scene.lights.clone());
    // `cpu::render` calls back with the number of image rows each finished band holds, from
    // the worker threads: a bar of rows fits that. The GPU and the counting renderer report no
    // progress: a spinner at least shows they are working.
    let bar = if renderer.gpu().is_none() && !a.stats {
        show_progress(a.res).then(|| {
            let b = ProgressBar::new(a.res.1 as u64 * a.frames as u64);
            b.set_style(
                ProgressStyle::with_template("{bar:40} {pos}/{len} rows {elapsed} (eta {eta})")
                    .expect("valid template"),
            );
            b
        })
    } else {
        spinner(a.res, &format!("rendering on {}", renderer.describe()))
    };
    let tick = |rows: u32| {
        if let Some(b) = &bar {
            b.inc(rows as u64);
        }
    };
    let views = (0..a.frames).map(|i| {
        let camera = if a.orbit {
            orbit(&camera0, i as f32 / a.frames as f32)
        } else {
            camera0
        };
        (camera, lights.clone())
    });
    let mut frames = Vec::with_capacity(a.frames as usize);
    let mut first = None;
    let mut last_gpu = None;
    let mut run = None;
    if a.stats && renderer.gpu().is_none() {
        // The counting renderer (CPU): one frame after another.
        for (camera, lights) in views {
            let (image, stats) = gridtrace::cpu::render_with_counters(&renderer.scene, &camera, &lights, opts)?;
            frames.push(stats);
            first.get_or_insert(gridtrace::Frame {
                image,
                stats,
                gpu: None,
            });
        }
    } else {
        let how = FramesOptions {
            in_flight: a.in_flight,
            target: None,
            progress: Some(&tick),
        };
        run = Some(renderer.render_frames(views, opts, how, |_, frame| {
            let gridtrace::Rendered::OnHost(frame) = frame else {
                unreachable!("frames come to the host without a device image")
            };
            frames.push(frame.stats);
            if let Some(g) = &frame.gpu {
                last_gpu = Some(g.clone());
            }
            first.get_or_insert(frame);
            Ok(())
        })?);
        for n in renderer.take_notes() {
            println!("note: {n}");
        }
    }
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    Ok(Traced {
        first: first.expect("at least one frame (--frames is at least 1)"),
        frames,
        last_gpu,
        run,
    })
}

/// The run's figures: the last GPU frame's stages, the first frame, the rest, the rate and
/// (with --stats) the work per ray.
fn report(a: &RenderArgs, renderer: &gridtrace::Tracer, t: &Traced) {
    let stats = &t.first.stats;
    // The stages of the last frame: with --frames above 1 a warm one (the first pays for
    // pipeline and buffer creation).
    if let Some(s) = t.last_gpu.as_ref().or(t.first.gpu.as_ref()) {
        print_gpu_frame(s, if a.frames > 1 { "last frame" } else { "frame" });
    }
    let r = stats.rays;
    println!(
        "{}  {:.1} ms, {} rays (eye {}, shadow {}, reflection {}), {:.2} Mrays/s  [{} {} {}x{}]",
        if a.frames > 1 { "first " } else { "render" },
        stats.render_ms,
        r.total(),
        r.eye,
        r.shadow,
        r.reflection,
        stats.mrays_per_s(),
        a.mode().name(),
        renderer.scene.accel.kind().name(),
        a.res.0,
        a.res.1
    );
    if t.frames.len() > 1 {
        let overlapped = renderer.gpu().is_some() && a.in_flight > 1;
        println!("{}", describe_frames(&t.frames[1..], a.orbit, overlapped));
        if let Some(rate) = t
            .run
            .as_ref()
            .and_then(describe_throughput(renderer.gpu().is_some(), a.in_flight))
        {
            println!("{rate}");
        }
    }
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
}

/// A GPU frame's times, round trips and bytes, and its stages with the rates of the two that
/// trace.
fn print_gpu_frame(s: &gridtrace::gpu::GpuRenderStats, which: &str) {
    let figures = GpuFigures {
        wall_ms: s.wall_ms,
        timings: &s.timings,
        parts: (s.tiles, "tile"),
        round_trips: s.round_trips,
        uploaded_bytes: s.uploaded_bytes,
        downloaded_bytes: s.downloaded_bytes,
    };
    let timed = print_gpu_figures(&format!("{which}: "), &figures).is_some();
    println!("prepare {} (the host's preparation, by part)", s.prepare_parts);
    if !timed {
        return;
    }
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
}

/// `--light`: X,Y,Z, or X,Y,Z:R,G,B with the intensity.
fn parse_light(s: &str) -> Result<(Vec3, Option<Vec3>), String> {
    match s.split_once(':') {
        Some((p, i)) => Ok((parse_vec3(p)?, Some(parse_vec3(i)?))),
        None => Ok((parse_vec3(s)?, None)),
    }
}

/// The camera `turn` of the way (0..1) round its orbit: rotated about the up axis through the
/// target, at the same distance and height.
pub(crate) fn orbit(camera: &gridtrace::scene::Camera, turn: f32) -> gridtrace::scene::Camera {
    let up = camera.up.normalize_or_zero();
    let rot = glam::Quat::from_axis_angle(up, turn * std::f32::consts::TAU);
    gridtrace::scene::Camera {
        eye: camera.target + rot * (camera.eye - camera.target),
        ..*camera
    }
}

/// The frames after the first: median and best, in ms and Mrays/s. With frames in flight
/// (`overlapped`) a frame's time is its latency, which holds another frame's host work, so the
/// rates are left to the run's throughput line.
fn describe_frames(rest: &[gridtrace::RenderStats], orbit: bool, overlapped: bool) -> String {
    let mut ms: Vec<f64> = rest.iter().map(|s| s.render_ms).collect();
    ms.sort_by(f64::total_cmp);
    let median = ms[ms.len() / 2];
    let best = ms[0];
    // Rays per frame vary along an orbit: rates are each frame's own, summarised the same way,
    // fastest first, so that the median takes the same rank as the time's (the slower of two
    // middle frames) and the best is the fastest.
    let mut rates: Vec<f64> = rest.iter().map(|s| s.mrays_per_s()).collect();
    rates.sort_by(|a, b| b.total_cmp(a));
    if overlapped {
        return format!(
            "frames  {} more{}: latency median {median:.1} ms, best {best:.1} ms (frames in flight)",
            rest.len(),
            if orbit { " along the orbit" } else { "" },
        );
    }
    format!(
        "frames  {} more{}: median {median:.1} ms ({:.2} Mrays/s), best {best:.1} ms ({:.2} Mrays/s)",
        rest.len(),
        if orbit { " along the orbit" } else { "" },
        rates[rates.len() / 2],
        rates[0]
    )
}

/// A run's steady throughput (frames after the first), and how many frames were in flight.
fn describe_throughput(gpu: bool, in_flight: usize) -> impl Fn(&FramesStats) -> Option<String> {
    move |run| {
        let (fps, mrays) = (run.frames_per_s()?, run.mrays_per_s()?);
        let how = if gpu {
            format!("{} in flight", in_flight.max(1))
        } else {
            "one by one".into()
        };
        Some(format!(
            "rate    {fps:.1} frames/s, {mrays:.2} Mrays/s of wall time ({how})"
        ))
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use gridtrace::scene::Camera;

    /// The orbit turns the eye about the up axis through the target: the start is the camera
    /// itself, half a turn mirrors the eye through the axis, and distance and height stay.
    #[test]
    fn orbit_turns_about_the_up_axis() {
        let cam = Camera {
            eye: Vec3::new(3.0, 2.0, 1.0),
            target: Vec3::new(1.0, 0.5, 1.0),
            up: Vec3::Y,
            vfov_deg: 40.0,
        };
        assert!(orbit(&cam, 0.0).eye.abs_diff_eq(cam.eye, 1e-6));
        let half = orbit(&cam, 0.5);
        assert!(half.eye.abs_diff_eq(Vec3::new(-1.0, 2.0, 1.0), 1e-5), "{}", half.eye);
        let quarter = orbit(&cam, 0.25);
        assert!(((quarter.eye - cam.target).length() - (cam.eye - cam.target).length()).abs() < 1e-5);
        assert!((quarter.eye.y - cam.eye.y).abs() < 1e-5, "height kept: {}", quarter.eye);
        assert_ne!(quarter.eye, cam.eye);
        assert_eq!(
            (half.target, half.up, half.vfov_deg),
            (cam.target, cam.up, cam.vfov_deg)
        );
    }
}
