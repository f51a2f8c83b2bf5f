//! `gridtrace view`: the interactive tracer in a window (winit), the paper's point. The scene is
//! prepared and uploaded once; per frame only the camera, the lights and the pass uniforms go to
//! the device. Frames are traced by the same tracers as `render` (GPU, or the CPU with
//! `--backend cpu` or when no GPU is usable; the overlay and title say which), in bands within a
//! time budget (progressive.rs), so input is answered between bands however slow a frame is, and
//! presented with an egui overlay (present.rs, overlay.rs).
//!
//! Module map: this file holds the options, the start and the viewer's state (`App`); what the
//! state does is in app.rs (actions, the tracers, loads, animation), pass.rs (one pass: trace
//! within the budget, overlay, present) and window.rs (window events to actions). Beside them:
//! controls.rs (actions, the orbit camera, projection for the light gizmos), script.rs
//! (`--script`), progressive.rs (bands, preview, the display image), present.rs (the surface, the
//! image from the tracer's device or a host texture, egui), blit.rs (the blit's pipeline and
//! bindings), overlay.rs (what the overlay says, as lines), loader.rs (dropped files on a worker
//! thread), headless.rs (`--headless`: frames along an orbit, timed).

mod app;
mod blit;
mod controls;
mod headless;
mod loader;
mod overlay;
mod pass;
mod present;
mod progressive;
mod script;
mod window;

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::Args;
use clap::builder::TypedValueParser;
use glam::Vec3;
use gridtrace::scene::animated::Animation;
use gridtrace::scene::{PointLight, Scene};
use gridtrace::{AccelKind, Backend, Mode, PixelFormat, Placement, RenderOptions, Rendered};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, ModifiersState, NamedKey};
use winit::window::{Window, WindowId};

use crate::common::{AccelArgs, GpuVariantArgs, SceneArgs, backend_parser, mode_parser, parse_res};
use controls::{Action, MAX_SCALE_STEPS, Orbit, key_action, next_accel, project, unproject};
use gridtrace::Tracer;
use overlay::{GIZMO_RADIUS_PT, HISTORY, Hud};
use progressive::Refiner;

#[derive(Args)]
pub struct ViewArgs {
    #[command(flatten)]
    scene: SceneArgs,
    #[command(flatten)]
    pub(crate) accel_args: AccelArgs,
    /// The first mode: cast, shadow, trace or heat (keys 1-4 switch).
    #[arg(long, default_value = "shadow", value_parser = mode_parser())]
    mode: Mode,
    /// Window size in physical pixels, WxH or N (with --headless: the image size).
    #[arg(long, value_name = "WxH|N", default_value = "800x600", value_parser = parse_res, allow_hyphen_values = true)]
    res: (u32, u32),
    /// Where to trace: auto (GPU if present, else CPU), gpu or cpu.
    #[arg(long, default_value = "auto", value_parser = backend_parser())]
    backend: Backend,
    #[command(flatten)]
    gpu: GpuVariantArgs,
    /// Trace 1/2^N of the window's pixels a side (0-3; keys [ and ] change it): speed for
    /// sharpness.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=MAX_SCALE_STEPS as i64), allow_hyphen_values = true)]
    scale: u32,
    /// Milliseconds of tracing per presented frame: a frame that takes longer is traced in
    /// bands over several, with a coarse preview first, and input is handled between them.
    #[arg(long, default_value_t = 30.0, value_name = "MS", allow_hyphen_values = true)]
    budget_ms: f64,
    /// Replay actions from this file, one a line (key 2, drag DX DY, zoom N, screenshot F.png,
    /// ...: the README's "The viewer"; an example in examples/view-script.txt), then exit. The
    /// window opens as without a script: it needs a display (or xvfb-run -a).
    #[arg(long, conflicts_with = "headless")]
    script: Option<PathBuf>,
    /// No window: trace --frames frames along a camera orbit with the lights circling the other
    /// way, and print per-frame times (first, median, p95, best) and Mrays/s.
    #[arg(long)]
    headless: bool,
    /// With --headless: frames to trace.
    #[arg(long, default_value_t = 60, requires = "headless", value_parser = clap::value_parser!(u32).range(1..=100_000), allow_hyphen_values = true)]
    frames: u32,
    /// With --headless: bring every GPU frame to the host (as `render` does) instead of leaving
    /// it on the device as the window presents it.
    #[arg(long, requires = "headless")]
    readback: bool,
    /// With --headless: frames the GPU may have in flight. 2 (the default) prepares and
    /// submits frame N+1 before it waits for frame N; 1 traces them one by one.
    #[arg(long, requires = "headless", default_value_t = gridtrace::frames::DEFAULT_IN_FLIGHT,
          value_parser = clap::value_parser!(u64).range(1..=16).map(|n| n as usize), allow_hyphen_values = true)]
    in_flight: usize,
    /// With --headless: move the camera round its orbit (one turn over the frames); without
    /// it the view stays and only the lights move.
    #[arg(long, requires = "headless")]
    orbit: bool,
}

/// The largest image the tracers take per side (`RenderOptions::validate`).
const MAX_SIDE: u32 = gridtrace::render::MAX_IMAGE_SIDE;
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
    // The event loop first: the tracer's device is opened from an instance that knows the
    // window system's display, so that the window can be presented from it (present.rs).
    let event_loop = EventLoop::new().map_err(|e| window_error("opening the event loop", e))?;
    let display = event_loop.owned_display_handle();
    let (placement, mut notes) = Placement::open_with(a.backend, a.gpu.gpu_variant, || {
        wgpu::InstanceDescriptor::new_with_display_handle(Box::new(display))
    })?;
    let accel = placement.pick(&a.accel_args.spec()?, gridtrace::Work::Render, &mut notes);
    for n in &notes {
        eprintln!("note: {n}");
    }
    let orbit = Orbit::from_camera(&src.camera);
    let mut app = App {
        name,
        src,
        accel_args: a.accel_args.clone(),
        placement,
        notes,
        tracers: Vec::new(),
        accel,
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
    app.open_tracer()?;
    event_loop.set_control_flow(ControlFlow::Wait);
    event_loop
        .run_app(&mut app)
        .map_err(|e| window_error("running the event loop", e))?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
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
    accel_args: AccelArgs,
    /// Where every structure's tracer traces: the device they share (`None`: the CPU) and
    /// `--gpu-variant`'s kernels.
    placement: Placement,
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
