//! `gridtrace view`: the interactive tracer in a window (winit), the paper's point. The scene is
//! prepared and uploaded once; per frame only the camera, the lights and the pass uniforms go to
//! the device. Frames are traced by the same tracers as `render` (GPU, or the CPU with
//! `--backend cpu` or when no GPU is usable; the overlay and title say which), in bands within a
//! time budget (progressive.rs), so input is answered between bands however slow a frame is, and
//! presented with an egui overlay (present.rs, overlay.rs).
//!
//! Module map: controls.rs (actions, the orbit camera, projection for the light gizmos),
//! script.rs (`--script`), progressive.rs (bands, preview, the display image), present.rs (the
//! surface, the image blit, egui), overlay.rs (what the overlay shows), loader.rs (dropped
//! files on a worker thread), headless.rs (`--headless`: frames along an orbit, timed).

mod controls;
mod headless;
mod loader;
mod overlay;
mod present;
mod progressive;
mod script;

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::Args;
use glam::Vec3;
use gridtrace::gpu::GpuContext;
use gridtrace::scene::animated::Animation;
use gridtrace::scene::{PointLight, Scene};
use gridtrace::{AccelKind, Backend, Mode, RenderOptions};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, ModifiersState, NamedKey};
use winit::window::{Window, WindowId};

use crate::common::{GridArgs, SceneArgs, backend_parser, mode_parser, parse_res};
use crate::tracer::Tracer;
use controls::{Action, MAX_SCALE_STEPS, Orbit, key_action, next_accel, project, unproject};
use overlay::{GIZMO_RADIUS_PT, HISTORY, Hud};
use progressive::Refiner;

#[derive(Args)]
pub struct ViewArgs {
    #[command(flatten)]
    scene: SceneArgs,
    #[command(flatten)]
    grid: GridArgs,
    /// The first mode: cast, shadow, trace or heat (keys 1-4 switch).
    #[arg(long, default_value = "shadow", value_parser = mode_parser())]
    mode: Mode,
    /// Window size in physical pixels, WxH or N (with --headless: the image size).
    #[arg(long, value_name = "WxH|N", default_value = "800x600", value_parser = parse_res, allow_hyphen_values = true)]
    res: (u32, u32),
    /// Where to trace: auto (GPU if present, else CPU), gpu or cpu.
    #[arg(long, default_value = "auto", value_parser = backend_parser())]
    backend: Backend,
    /// Trace 1/2^N of the window's pixels a side (0-3; keys [ and ] change it): speed for
    /// sharpness.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=MAX_SCALE_STEPS as i64))]
    scale: u32,
    /// Milliseconds of tracing per presented frame: a frame that takes longer is traced in
    /// bands over several, with a coarse preview first, and input is handled between them.
    #[arg(long, default_value_t = 30.0, value_name = "MS")]
    budget_ms: f64,
    /// Replay actions from this file, then exit (see `gridtrace view` in the README).
    #[arg(long, conflicts_with = "headless")]
    script: Option<PathBuf>,
    /// No window: trace --frames frames along a camera orbit with the lights circling the other
    /// way, and print per-frame times (first, median, p95, best) and Mrays/s.
    #[arg(long)]
    headless: bool,
    /// With --headless: frames to trace.
    #[arg(long, default_value_t = 60, requires = "headless", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    frames: u32,
    /// With --headless: move the camera round its orbit (one turn over the frames); without
    /// it the view stays and only the lights move.
    #[arg(long, requires = "headless")]
    orbit: bool,
}

/// The largest image the tracers take per side (`RenderOptions::validate`).
const MAX_SIDE: u32 = 16384;
/// Animation time per presented frame in scripts (wall time otherwise), so scripted runs of
/// animated scenes repeat exactly.
const SCRIPT_FRAME_S: f32 = 1.0 / 30.0;
/// Largest animation step per presented frame: a stall (a window drag) does not jump ahead.
const MAX_ANIM_STEP_S: f32 = 0.1;

pub fn run(a: ViewArgs) -> gridtrace::Result<()> {
    if !(a.budget_ms.is_finite() && a.budget_ms > 0.0) {
        return Err(gridtrace::Error::InvalidInput(format!(
            "--budget-ms must be positive, got {}",
            a.budget_ms
        )));
    }
    // A built-in animated scene plays (space pauses); anything else is still.
    let anim = match (&a.scene.scene, &a.scene.file, &a.scene.mesh) {
        (Some(n), None, None) => Animation::by_name(n),
        _ => None,
    };
    let (src, name) = match &anim {
        Some(an) => (an.scene.clone(), a.scene.scene.clone().unwrap_or_default()),
        None => a.scene.load(true)?,
    };
    if a.headless {
        return headless::run(&a, src, &name);
    }
    let script = match &a.script {
        Some(p) => Some(script::load(p)?),
        None => None,
    };
    let (ctx, notes) = open_device(a.backend)?;
    for n in &notes {
        eprintln!("note: {n}");
    }
    let orbit = Orbit::from_camera(&src.camera);
    let mut app = App {
        name,
        src,
        grid_args: a.grid.clone(),
        backend: a.backend,
        ctx,
        notes,
        tracers: Vec::new(),
        accel: a.grid.accel,
        mode: a.mode,
        orbit,
        lights: Vec::new(),
        selected_light: 0,
        scale_steps: a.scale,
        fly_speed: 1.0,
        size: a.res,
        budget: Duration::from_secs_f64(a.budget_ms / 1e3),
        window: None,
        presenter: None,
        egui_ctx: egui::Context::default(),
        egui: None,
        show_overlay: true,
        refiner: Refiner::new(),
        last: None,
        egui_repaint: false,
        dirty: true,
        history: VecDeque::with_capacity(HISTORY),
        script: script.map(|s| s.into_iter().rev().collect()),
        drag: None,
        cursor: (0.0, 0.0),
        modifiers: ModifiersState::empty(),
        error: None,
        drop_error: None,
        loader: None,
        shots: 0,
        anim: anim.map(|animation| Playback {
            animation,
            time: 0.0,
            playing: true,
            last_tick: Instant::now(),
            last_update: None,
        }),
    };
    app.reset_view();
    // Prepare and upload the first structure before the window opens: errors in the scene
    // come out as errors, not as a window that closes.
    app.tracer()?;
    let event_loop = EventLoop::new().map_err(|e| window_error("opening the event loop", e))?;
    event_loop.set_control_flow(ControlFlow::Wait);
    event_loop
        .run_app(&mut app)
        .map_err(|e| window_error("running the event loop", e))?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// The device the viewer traces on. With `auto`, a software adapter alone (lavapipe) is passed
/// over for the CPU tracer: on the same cores it is about 5x slower (Stanford Bunny, 1024x768,
/// docs/benchmarks.md), and the viewer is about speed; `--backend gpu` still takes it.
fn open_device(backend: Backend) -> gridtrace::Result<(Option<Arc<GpuContext>>, Vec<String>)> {
    let (ctx, mut notes) = backend.open_device()?;
    match ctx {
        Some(c) if backend == Backend::Auto && c.is_software() => {
            notes.push(format!(
                "the only adapter is a software rasteriser ({}), slower than the CPU tracer on the same cores: tracing on the CPU (--backend gpu to use it)",
                c.info.name
            ));
            Ok((None, notes))
        }
        ctx => Ok((ctx, notes)),
    }
}

fn window_error(what: &str, e: impl std::fmt::Display) -> gridtrace::Error {
    gridtrace::Error::InvalidInput(format!(
        "{what}: {e} (the viewer needs a display: an X11 session, or xvfb-run for a virtual one)"
    ))
}

/// The light intensity vector and position as `render --light` takes them: X,Y,Z:R,G,B.
fn light_arg(l: &PointLight) -> String {
    let [x, y, z] = l.position;
    let [r, g, b] = l.intensity;
    format!("{x:?},{y:?},{z:?}:{r:?},{g:?},{b:?}")
}

/// An animated scene being played.
struct Playback {
    animation: Animation,
    /// Animation time of the frame on screen, in seconds.
    time: f32,
    playing: bool,
    last_tick: Instant,
    /// The last update's geometry and build times, in words.
    last_update: Option<String>,
}

/// What a mouse drag moves.
#[derive(Clone, Copy)]
enum Drag {
    Orbit,
    Pan,
    Light,
}

struct App {
    name: String,
    src: Scene,
    grid_args: GridArgs,
    backend: Backend,
    /// The device every structure's tracer shares (`None`: the CPU).
    ctx: Option<Arc<GpuContext>>,
    notes: Vec<String>,
    /// Opened tracers by the structure they trace (`AccelKind::structure_name`), with the
    /// animation time their vertices are at.
    tracers: Vec<(&'static str, Tracer, f32)>,
    accel: AccelKind,
    mode: Mode,
    orbit: Orbit,
    lights: Vec<PointLight>,
    selected_light: usize,
    /// The traced image is the window halved this many times a side.
    scale_steps: u32,
    fly_speed: f32,
    /// Window size in physical pixels.
    size: (u32, u32),
    budget: Duration,
    window: Option<Arc<Window>>,
    presenter: Option<present::Presenter>,
    egui_ctx: egui::Context,
    egui: Option<egui_winit::State>,
    show_overlay: bool,
    refiner: Refiner,
    /// The last finished frame's figures (the refiner's own are reset by each new frame).
    last: Option<progressive::FrameSummary>,
    /// egui asked to be drawn again at once (an animation of its own).
    egui_repaint: bool,
    /// The view changed since the frame being refined was started.
    dirty: bool,
    /// Finished frames' times (ms), oldest first.
    history: VecDeque<f64>,
    /// Script actions still to run, last first.
    script: Option<Vec<Action>>,
    drag: Option<(Drag, (f64, f64))>,
    cursor: (f64, f64),
    modifiers: ModifiersState,
    error: Option<gridtrace::Error>,
    /// The last dropped file's error, shown until the next drop.
    drop_error: Option<String>,
    loader: Option<loader::Loader>,
    shots: u32,
    anim: Option<Playback>,
}

impl App {
    /// Camera and lights from the scene (at start, and when a new file is loaded).
    fn reset_view(&mut self) {
        self.orbit = Orbit::from_camera(&self.src.camera);
        self.lights = self.src.lights.clone();
        self.selected_light = 0;
    }

    /// The traced image's size: the window's, halved `scale_steps` times.
    fn traced_size(&self) -> (u32, u32) {
        let (w, h) = self.size;
        let d = 1u32 << self.scale_steps;
        (w.div_ceil(d).min(MAX_SIDE), h.div_ceil(d).min(MAX_SIDE))
    }

    fn scale(&self) -> f32 {
        1.0 / (1u32 << self.scale_steps) as f32
    }

    /// The tracer of the structure on screen, prepared and uploaded when first asked for, its
    /// vertices at the animation's time.
    fn tracer(&mut self) -> gridtrace::Result<&mut Tracer> {
        let structure = self.accel.structure_name();
        let i = match self.tracers.iter().position(|(s, _, _)| *s == structure) {
            Some(i) => i,
            None => {
                let t0 = Instant::now();
                let scene = crate::common::prepare(&self.src, &self.name, self.accel, &self.grid_args)?;
                let tracer = Tracer::open(scene, self.ctx.as_ref(), self.backend, &mut self.notes)?;
                eprintln!(
                    "{} prepared in {:.0} ms; tracing on {}",
                    structure,
                    t0.elapsed().as_secs_f64() * 1e3,
                    tracer.describe()
                );
                self.tracers.push((structure, tracer, 0.0));
                self.tracers.len() - 1
            }
        };
        let (_, tracer, at) = &mut self.tracers[i];
        if let Some(p) = &mut self.anim
            && *at != p.time
        {
            let u = tracer.update_vertices(&p.animation.positions_at(p.time))?;
            p.last_update = Some(format!(
                "geometry {:.1} ms, build {:.1} ms, {}",
                u.geometry_ms, u.build_ms, u.how
            ));
            *at = p.time;
        }
        Ok(tracer)
    }

    /// The tracer of the structure on screen, if it is open.
    fn current_tracer(&self) -> Option<&Tracer> {
        let structure = self.accel.structure_name();
        self.tracers.iter().find(|(s, _, _)| *s == structure).map(|(_, t, _)| t)
    }

    /// The options of the frame for the current view.
    fn frame_opts(&self) -> RenderOptions {
        let (w, h) = self.traced_size();
        RenderOptions::new(w, h, self.mode, self.accel)
    }

    /// Traces within the budget (all of the frame with `finish`), and puts what changed into
    /// the image texture.
    fn trace(&mut self, finish: bool) -> gridtrace::Result<()> {
        let (w, h) = self.size;
        if w == 0 || h == 0 {
            // Minimised: nothing to trace until the window has an area again (`resized`).
            return Ok(());
        }
        if self.dirty {
            self.refiner.restart(self.frame_opts(), self.budget);
            self.dirty = false;
        }
        if !self.refiner.done() {
            let camera = self.orbit.camera();
            let budget = self.budget;
            self.tracer()?;
            let lights = &self.lights;
            let structure = self.accel.structure_name();
            let tracer = &mut self
                .tracers
                .iter_mut()
                .find(|(s, _, _)| *s == structure)
                .expect("opened above")
                .1;
            let mut trace = |o: &RenderOptions| tracer.render(&camera, lights, o);
            if finish {
                self.refiner.finish(&mut trace)?;
            } else {
                self.refiner.step(budget, &mut trace)?;
            }
            if self.refiner.done() {
                if self.history.len() == HISTORY {
                    self.history.pop_front();
                }
                self.history.push_back(self.refiner.summary().ms);
                self.last = Some(self.refiner.summary().clone());
                self.set_title();
            }
        }
        if self.refiner.take_changed()
            && let Some(p) = &mut self.presenter
        {
            let o = self.refiner.opts();
            p.upload(&self.refiner.display, (o.width, o.height));
        }
        Ok(())
    }

    fn set_title(&self) {
        let (Some(win), Some(s)) = (&self.window, &self.last) else {
            return;
        };
        let tracer = self.current_tracer().map_or(String::new(), |t| t.describe());
        let up = if s.uploaded_bytes > 0 {
            format!(", {} B uploaded", s.uploaded_bytes)
        } else {
            String::new()
        };
        win.set_title(&format!(
            "gridtrace: {} - {} {} - {:.1} ms{up} - {tracer}",
            self.name,
            self.mode.name(),
            self.accel.name(),
            s.ms
        ));
    }

    /// Window pixel positions of the lights' gizmos (`None`: behind the camera).
    fn gizmos(&self) -> Vec<Option<(f32, f32)>> {
        let c = self.orbit.camera();
        let size = (self.size.0.max(1) as f32, self.size.1.max(1) as f32);
        self.lights
            .iter()
            .map(|l| project(&c, size, Vec3::from(l.position)).map(|(x, y, _)| (x, y)))
            .collect()
    }

    fn hud(&self) -> Hud {
        let t = self.current_tracer();
        let (triangles, structure, memory_bytes, paper_model_bytes) = match t {
            Some(t) => (
                t.scene.accel.tris.len(),
                crate::common::describe_structure(&t.scene.accel),
                t.scene.memory().iter().map(|(_, b)| b).sum(),
                t.scene.paper_memory_model(),
            ),
            None => (0, "(not prepared)".into(), 0, None),
        };
        Hud {
            tracer: t.map_or("(none yet)".into(), |t| t.short()),
            notes: self.notes.clone(),
            presenter: self.presenter.as_ref().map_or(String::new(), |p| p.adapter.clone()),
            scene: std::path::Path::new(&self.name)
                .file_name()
                .map_or(self.name.clone(), |f| f.to_string_lossy().into_owned()),
            triangles,
            structure,
            memory_bytes,
            paper_model_bytes,
            mode: self.mode.name(),
            accel: self.accel.name(),
            traced: self.traced_size(),
            scale: self.scale(),
            pixels_per_point: self.egui_ctx.pixels_per_point(),
            last: self.last.clone(),
            progress: self.refiner.progress(),
            lights: self.lights.iter().map(|l| Vec3::from(l.position)).collect(),
            selected_light: self.selected_light,
            fly_speed: self.fly_speed,
            loading: self.loader.as_ref().map(|l| l.describe()),
            error: self.drop_error.clone(),
            animation: self.anim.as_ref().map(|p| {
                format!(
                    "t = {:.2} s, {}{}",
                    p.time,
                    if p.playing { "playing" } else { "paused" },
                    p.last_update.as_ref().map_or(String::new(), |u| format!("; {u}"))
                )
            }),
        }
    }

    /// Runs egui for this pass: the overlay's shapes, ready to draw.
    fn overlay(&mut self) -> Option<present::Overlay> {
        let window = self.window.clone()?;
        let hud = self.hud();
        let gizmos = self.gizmos();
        let show = self.show_overlay;
        let state = self.egui.as_mut()?;
        let input = state.take_egui_input(&window);
        let history = &self.history;
        let out = self.egui_ctx.run_pass(input, |ctx| {
            if show {
                hud.show(ctx, history, &gizmos);
            }
        });
        state.handle_platform_output(&window, out.platform_output);
        self.egui_repaint = out
            .viewport_output
            .get(&egui::ViewportId::ROOT)
            .is_some_and(|v| v.repaint_delay.is_zero());
        let ppp = out.pixels_per_point;
        Some(present::Overlay {
            primitives: self.egui_ctx.tessellate(out.shapes, ppp),
            textures: out.textures_delta,
            pixels_per_point: ppp,
        })
    }

    fn apply(&mut self, action: Action, el: &ActiveEventLoop) -> gridtrace::Result<()> {
        match action {
            Action::Orbit(dx, dy) => {
                self.orbit.drag(dx, dy);
                self.dirty = true;
            }
            Action::Pan(dx, dy) => {
                self.orbit.pan(dx, dy, self.size.1 as f32);
                self.dirty = true;
            }
            Action::Zoom(s) => {
                self.orbit.zoom(s);
                self.dirty = true;
            }
            Action::Fly(f, r, u) => {
                let k = self.fly_speed;
                self.orbit.fly(f * k, r * k, u * k);
                self.dirty = true;
            }
            Action::Frame => {
                let b = self.src.bounds();
                self.orbit.frame(b.min, b.max);
                self.dirty = true;
            }
            Action::SetMode(m) => {
                self.dirty |= m != self.mode;
                self.mode = m;
            }
            Action::NextAccel => {
                self.accel = next_accel(self.accel);
                self.dirty = true;
            }
            Action::Resize(w, h) => {
                if let Some(win) = &self.window {
                    let _ = win.request_inner_size(winit::dpi::PhysicalSize::new(w.max(1), h.max(1)));
                }
                self.resized(w, h);
            }
            Action::NextLight => {
                if !self.lights.is_empty() {
                    self.selected_light = (self.selected_light + 1) % self.lights.len();
                }
            }
            Action::DragLight(dx, dy) => {
                let c = self.orbit.camera();
                let size = (self.size.0.max(1) as f32, self.size.1.max(1) as f32);
                if let Some(l) = self.lights.get_mut(self.selected_light)
                    && let Some((x, y, z)) = project(&c, size, Vec3::from(l.position))
                {
                    l.position = unproject(&c, size, (x + dx, y + dy), z).to_array();
                    self.dirty = true;
                }
            }
            Action::MoveLight(f, r, u) => {
                let offset = self.orbit.view_offset(f, r, u) * self.fly_speed;
                if let Some(l) = self.lights.get_mut(self.selected_light) {
                    l.position = (Vec3::from(l.position) + offset).to_array();
                    self.dirty = true;
                }
            }
            Action::ScaleStep(d) => {
                let s = (self.scale_steps as i32 + d).clamp(0, MAX_SCALE_STEPS as i32) as u32;
                self.dirty |= s != self.scale_steps;
                self.scale_steps = s;
            }
            Action::SpeedStep(d) => {
                self.fly_speed = (self.fly_speed * 2f32.powi(d)).clamp(1.0 / 64.0, 64.0);
            }
            Action::ToggleOverlay => self.show_overlay = !self.show_overlay,
            Action::PlayPause => {
                if let Some(p) = &mut self.anim {
                    p.playing = !p.playing;
                    p.last_tick = Instant::now();
                }
            }
            Action::Drop(path) => {
                if let Some(l) = &self.loader {
                    // One load at a time: a worker thread cannot be stopped half way.
                    let e = format!(
                        "{}: still loading {}; drop it again when that is in",
                        path.display(),
                        l.path.display()
                    );
                    eprintln!("drop {e}");
                    self.drop_error = Some(e);
                } else {
                    println!("drop {}: loading", path.display());
                    self.drop_error = None;
                    self.loader = Some(loader::Loader::start(path, self.accel, self.grid_args.clone()));
                }
            }
            Action::Screenshot(path) => {
                self.trace(true)?;
                let Some(image) = self.refiner.image() else {
                    return Err(gridtrace::Error::InvalidInput(
                        "screenshot: no frame yet (the window has no area)".into(),
                    ));
                };
                image.save_png(&path)?;
                let c = self.orbit.camera();
                let v = |v: Vec3| format!("{:?},{:?},{:?}", v.x, v.y, v.z);
                let lights: Vec<String> = self.lights.iter().map(light_arg).collect();
                println!(
                    "screenshot {} eye={} target={} up={} vfov={:?} lights={} mode={} accel={} res={}x{} ms={:.1}",
                    path.display(),
                    v(c.eye),
                    v(c.target),
                    v(c.up),
                    c.vfov_deg,
                    lights.join(";"),
                    self.mode.name(),
                    self.accel.name(),
                    image.width,
                    image.height,
                    self.last.as_ref().map_or(0.0, |s| s.ms)
                );
            }
            Action::Capture(path) => {
                self.trace(true)?;
                // egui sizes a window from the pass before: one pass on screen first.
                self.present()?;
                let overlay = self.overlay();
                if let (Some(p), Some(o)) = (&mut self.presenter, overlay) {
                    p.capture(o)?
                        .save(&path)
                        .map_err(|e| gridtrace::Error::io(&path, std::io::Error::other(e)))?;
                    println!("capture {}", path.display());
                }
            }
            Action::OverlayText(path) => {
                self.trace(true)?;
                let text = self.hud().lines().join("\n") + "\n";
                std::fs::write(&path, text).map_err(|e| gridtrace::Error::io(&path, e))?;
            }
            Action::Quit => el.exit(),
        }
        Ok(())
    }

    /// A finished load: the new scene replaces the old one; a failed one leaves it and says why.
    fn loaded(&mut self, path: PathBuf, result: gridtrace::Result<loader::Loaded>) -> gridtrace::Result<()> {
        match result {
            Ok(l) => {
                let mut notes = Vec::new();
                let tracer = match Tracer::open(l.prepared, self.ctx.as_ref(), self.backend, &mut notes) {
                    Ok(t) => t,
                    Err(e) => return self.loaded(path, Err(e)),
                };
                println!(
                    "drop {}: loaded {} triangles",
                    path.display(),
                    tracer.scene.accel.tris.len()
                );
                self.notes.extend(notes);
                self.src = l.src;
                self.name = l.name;
                // Prepared for the structure on screen when the file was dropped (G may have
                // been pressed since): keyed by that one.
                self.tracers = vec![(l.accel.structure_name(), tracer, 0.0)];
                self.anim = None;
                self.drop_error = None;
                self.reset_view();
                self.dirty = true;
            }
            Err(e) => {
                // The scene on screen stays; the error is shown until the next drop.
                eprintln!("drop {}: error: {e}", path.display());
                self.drop_error = Some(e.to_string());
            }
        }
        Ok(())
    }

    /// Checks on a file being loaded; true while it is still loading.
    fn poll_loader(&mut self) -> gridtrace::Result<bool> {
        let Some(l) = &mut self.loader else {
            return Ok(false);
        };
        match l.poll() {
            None => Ok(true),
            Some(result) => {
                let path = l.path.clone();
                self.loader = None;
                self.loaded(path, result)?;
                Ok(false)
            }
        }
    }

    /// Moves an animated scene on by the wall time since the last frame (a fixed step in
    /// scripts).
    fn tick_animation(&mut self) {
        let scripted = self.script.is_some();
        if let Some(p) = &mut self.anim
            && p.playing
        {
            let now = Instant::now();
            let dt = if scripted {
                SCRIPT_FRAME_S
            } else {
                now.duration_since(p.last_tick).as_secs_f32().min(MAX_ANIM_STEP_S)
            };
            p.last_tick = now;
            p.time += dt;
            self.dirty = true;
        }
    }

    fn resized(&mut self, w: u32, h: u32) {
        let max = self.presenter.as_ref().map_or(MAX_SIDE, |p| p.max_side()).min(MAX_SIDE);
        if w > max || h > max {
            eprintln!("note: window {w}x{h} is larger than the device allows; tracing {max} pixels a side at most");
        }
        let size = (w.min(max), h.min(max));
        if size != self.size {
            self.size = size;
            self.dirty = true;
            if let Some(p) = &mut self.presenter {
                p.resize(size.0, size.1);
            }
        }
    }

    /// One pass: move an animation on (`tick`) once the frame before is done, trace within
    /// the budget, draw the overlay, present.
    fn redraw(&mut self, tick: bool) -> gridtrace::Result<()> {
        if tick && self.refiner.done() && !self.dirty {
            self.tick_animation();
        }
        self.trace(false)?;
        self.present()
    }

    /// Draws the overlay and presents; a frame the surface could not take is asked for again.
    fn present(&mut self) -> gridtrace::Result<()> {
        let overlay = self.overlay();
        if let (Some(p), Some(o)) = (&mut self.presenter, overlay)
            && !p.present(o)?
            && let Some(w) = &self.window
        {
            w.request_redraw();
        }
        Ok(())
    }

    /// Whether more passes are wanted without input: a frame being refined, a file loading,
    /// an animation playing.
    fn busy(&self) -> bool {
        if self.size.0 == 0 || self.size.1 == 0 {
            // Minimised: nothing to draw until the window has an area again.
            return false;
        }
        self.dirty
            || !self.refiner.done()
            || self.loader.is_some()
            || self.egui_repaint
            || self.anim.as_ref().is_some_and(|p| p.playing)
    }

    fn fail(&mut self, el: &ActiveEventLoop, e: gridtrace::Error) {
        self.error = Some(e);
        el.exit();
    }

    /// The action of a key press, if any.
    fn key_action(&mut self, key: &Key) -> Option<Action> {
        let fast = if self.modifiers.shift_key() { 5.0 } else { 1.0 };
        let name = match key {
            Key::Character(c) if c.eq_ignore_ascii_case("p") => {
                self.shots += 1;
                return Some(Action::Screenshot(format!("gridtrace-view-{}.png", self.shots).into()));
            }
            Key::Character(c) => c.as_str(),
            Key::Named(NamedKey::Escape) => "escape",
            Key::Named(NamedKey::Space) => "space",
            Key::Named(NamedKey::ArrowLeft) => "left",
            Key::Named(NamedKey::ArrowRight) => "right",
            Key::Named(NamedKey::ArrowUp) => "up",
            Key::Named(NamedKey::ArrowDown) => "down",
            Key::Named(NamedKey::PageUp) => "pageup",
            Key::Named(NamedKey::PageDown) => "pagedown",
            _ => return None,
        };
        key_action(name, fast)
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let attrs = Window::default_attributes()
            .with_title(format!("gridtrace: {}", self.name))
            .with_inner_size(winit::dpi::PhysicalSize::new(self.size.0, self.size.1));
        let window = match el.create_window(attrs) {
            Ok(w) => Arc::new(w),
            Err(e) => return self.fail(el, window_error("opening a window", e)),
        };
        match present::Presenter::new(el, window.clone()) {
            Ok(p) => {
                self.egui = Some(egui_winit::State::new(
                    self.egui_ctx.clone(),
                    egui::ViewportId::ROOT,
                    &window,
                    Some(window.scale_factor() as f32),
                    None,
                    Some(p.max_side() as usize),
                ));
                self.presenter = Some(p);
            }
            Err(e) => return self.fail(el, e),
        }
        let s = window.inner_size();
        self.window = Some(window.clone());
        self.resized(s.width, s.height);
        window.request_redraw();
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        // The overlay sees every event first; a press on it, or a drag that started there, is
        // its own.
        let mut consumed = false;
        if let (Some(state), Some(win)) = (&mut self.egui, &self.window) {
            let r = state.on_window_event(win, &event);
            consumed = r.consumed;
            // egui asks to repaint after every redraw as well: following that would redraw
            // forever; what needs another pass is in `busy`.
            if r.repaint && !matches!(event, WindowEvent::RedrawRequested) {
                win.request_redraw();
            }
        }
        let result = match event {
            WindowEvent::CloseRequested => {
                el.exit();
                Ok(())
            }
            WindowEvent::Resized(s) => {
                self.resized(s.width, s.height);
                Ok(())
            }
            WindowEvent::ScaleFactorChanged { .. } => {
                // egui follows the new scale (its state saw the event); the window's physical
                // size arrives as a Resized event.
                self.dirty = true;
                Ok(())
            }
            // A script draws its own passes (about_to_wait), so its animation steps are its own.
            WindowEvent::RedrawRequested => self.redraw(self.script.is_none()),
            WindowEvent::ModifiersChanged(m) => {
                self.modifiers = m.state();
                Ok(())
            }
            WindowEvent::DroppedFile(path) => self.apply(Action::Drop(path), el),
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                if state == ElementState::Pressed && !consumed && !self.egui_ctx.is_pointer_over_egui() {
                    // A press on a light's gizmo (drawn with the overlay) drags the light;
                    // anywhere else it orbits.
                    let ppp = self.egui_ctx.pixels_per_point();
                    let (cx, cy) = (self.cursor.0 as f32, self.cursor.1 as f32);
                    let gizmos = if self.show_overlay { self.gizmos() } else { Vec::new() };
                    let hit = gizmos.iter().position(|g| {
                        g.is_some_and(|(x, y)| ((x - cx).powi(2) + (y - cy).powi(2)).sqrt() <= GIZMO_RADIUS_PT * ppp)
                    });
                    let kind = match hit {
                        Some(i) => {
                            self.selected_light = i;
                            Drag::Light
                        }
                        None => Drag::Orbit,
                    };
                    self.drag = Some((kind, self.cursor));
                } else if state == ElementState::Released {
                    self.drag = None;
                }
                Ok(())
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Right | MouseButton::Middle,
                ..
            } => {
                self.drag = (state == ElementState::Pressed && !consumed && !self.egui_ctx.is_pointer_over_egui())
                    .then_some((Drag::Pan, self.cursor));
                Ok(())
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = (position.x, position.y);
                match self.drag {
                    Some((kind, (x, y))) => {
                        self.drag = Some((kind, self.cursor));
                        let (dx, dy) = ((position.x - x) as f32, (position.y - y) as f32);
                        let action = match kind {
                            Drag::Orbit => Action::Orbit(dx, dy),
                            Drag::Pan => Action::Pan(dx, dy),
                            Drag::Light => Action::DragLight(dx, dy),
                        };
                        self.apply(action, el)
                    }
                    None => Ok(()),
                }
            }
            WindowEvent::MouseWheel { delta, .. } if !consumed => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => (p.y / 40.0) as f32,
                };
                self.apply(Action::Zoom(steps), el)
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed && !consumed => {
                match self.key_action(&event.logical_key) {
                    Some(a) => self.apply(a, el),
                    None => Ok(()),
                }
            }
            _ => Ok(()),
        };
        if let Err(e) = result {
            return self.fail(el, e);
        }
        if self.busy()
            && let Some(w) = &self.window
        {
            w.request_redraw();
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        let loading = match self.poll_loader() {
            Ok(l) => l,
            Err(e) => return self.fail(el, e),
        };
        if self.script.is_none() || self.window.is_none() {
            // Passes keep coming while there is work (`busy`, a file loading among it); when
            // idle, a loader is still polled ten times a second.
            if loading {
                el.set_control_flow(ControlFlow::WaitUntil(Instant::now() + Duration::from_millis(100)));
                if let Some(w) = &self.window {
                    w.request_redraw();
                }
            } else {
                el.set_control_flow(ControlFlow::Wait);
            }
            return;
        }
        // A script runs one action per pass of the event loop, after a pass of tracing (within
        // the budget, as for a person) and presenting; screenshots, captures and the overlay's
        // text finish the frame first, so they show the frame a person would have seen once it
        // was done. Trace and present here rather than wait for a redraw request: a script
        // must not depend on the window system's timing. A file being loaded holds the script
        // until it is in (or has failed).
        if let Err(e) = self.redraw(true) {
            return self.fail(el, e);
        }
        el.set_control_flow(ControlFlow::Poll);
        if loading {
            std::thread::sleep(Duration::from_millis(10));
            return;
        }
        let next = self.script.as_mut().and_then(|s| s.pop()).unwrap_or(Action::Quit);
        if let Err(e) = self.apply(next, el) {
            self.fail(el, e);
        }
    }
}
