//! `gridtrace view`: the interactive tracer in a window (winit), the paper's point. The scene is
//! prepared and uploaded once; a frame is traced only when the camera, mode, structure or size
//! changes, by the same `Renderer` as `render` (GPU, or the CPU with `--backend cpu` or when no
//! GPU is usable; the title says which), and presented on the window's surface.
//!
//! This first form presents by copying the traced image into the surface texture (a queue
//! write on a presentation device of its own, so the CPU and GPU tracers present alike); the
//! GPU tracer's frame goes through host memory on the way. Controls: drag to orbit, wheel to
//! zoom, WASD + QE to fly, F to frame the scene, 1-4 for cast/shadow/trace/heat, G for the next
//! structure (grid, pc, bvh), P for a screenshot, Esc to quit. `--script FILE` replays the same actions from a file (script.rs).

mod controls;
mod present;
mod script;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use clap::Args;
use gridtrace::scene::PreparedScene;
use gridtrace::{AccelKind, Mode, RenderOptions, Renderer};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::common::{Backend, GridArgs, SceneArgs, backend_parser, mode_parser, parse_res};
use controls::{Action, Orbit, fly_key, mode_key, next_accel};

#[derive(Args)]
pub struct ViewArgs {
    #[command(flatten)]
    scene: SceneArgs,
    #[command(flatten)]
    grid: GridArgs,
    /// The first mode: cast, shadow, trace or heat (keys 1-4 switch).
    #[arg(long, default_value = "shadow", value_parser = mode_parser())]
    mode: Mode,
    /// Window size in physical pixels, WxH or N.
    #[arg(long, value_name = "WxH|N", default_value = "800x600", value_parser = parse_res, allow_hyphen_values = true)]
    res: (u32, u32),
    /// Where to trace: auto (GPU if present, else CPU), gpu or cpu.
    #[arg(long, default_value = "auto", value_parser = backend_parser())]
    backend: Backend,
    /// Replay actions from this file, then exit (see `gridtrace view` in the README).
    #[arg(long)]
    script: Option<PathBuf>,
}

/// The largest image the tracers take per side (`RenderOptions::validate`).
const MAX_SIDE: u32 = 16384;

pub fn run(a: ViewArgs) -> gridtrace::Result<()> {
    let (scene, name) = a.scene.load(true)?;
    let script = match &a.script {
        Some(p) => Some(script::load(p)?),
        None => None,
    };
    let grid_scene = crate::common::prepare(&scene, &name, AccelKind::Grid, &a.grid)?;
    // The viewer keeps its scenes for the life of the process: renderers borrow them.
    let grid_scene: &'static PreparedScene = Box::leak(Box::new(grid_scene));
    let orbit = Orbit::from_camera(&grid_scene.camera);
    let event_loop = EventLoop::new().map_err(|e| window_error("opening the event loop", e))?;
    event_loop.set_control_flow(ControlFlow::Wait);
    let mut app = App {
        name,
        scene_src: scene,
        grid_args: a.grid.clone(),
        grid_scene,
        own_scenes: Vec::new(),
        renderers: Vec::new(),
        backend: a.backend,
        accel: a.grid.accel,
        mode: a.mode,
        orbit,
        size: a.res,
        window: None,
        presenter: None,
        frame: None,
        dirty: true,
        script: script.map(|s| s.into_iter().rev().collect()),
        drag: None,
        cursor: (0.0, 0.0),
        error: None,
        shots: 0,
    };
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

/// The frame on screen.
struct Frame {
    image: gridtrace::Image,
    ms: f64,
}

struct App {
    name: String,
    scene_src: gridtrace::scene::Scene,
    grid_args: crate::common::GridArgs,
    grid_scene: &'static PreparedScene,
    /// The scenes prepared for structures other than the grid, when first asked for.
    own_scenes: Vec<(AccelKind, &'static PreparedScene)>,
    /// Opened renderers, by the structure they trace (`AccelKind::structure_name`).
    renderers: Vec<(&'static str, Renderer<'static>)>,
    backend: Backend,
    accel: AccelKind,
    mode: Mode,
    orbit: Orbit,
    /// Window (and image) size in physical pixels.
    size: (u32, u32),
    window: Option<Arc<Window>>,
    presenter: Option<present::Presenter>,
    frame: Option<Frame>,
    /// The view changed since the frame on screen was traced.
    dirty: bool,
    /// Script actions still to run, last first.
    script: Option<Vec<Action>>,
    drag: Option<(f64, f64)>,
    cursor: (f64, f64),
    error: Option<gridtrace::Error>,
    shots: u32,
}

impl App {
    fn scene_for(&mut self, accel: AccelKind) -> gridtrace::Result<&'static PreparedScene> {
        if accel.uses_grid() {
            return Ok(self.grid_scene);
        }
        if let Some((_, s)) = self.own_scenes.iter().find(|(k, _)| *k == accel) {
            return Ok(s);
        }
        let s: &'static PreparedScene = Box::leak(Box::new(crate::common::prepare(
            &self.scene_src,
            &self.name,
            accel,
            &self.grid_args,
        )?));
        self.own_scenes.push((accel, s));
        Ok(s)
    }

    /// Traces the current view if it changed.
    fn trace(&mut self) -> gridtrace::Result<()> {
        let (w, h) = self.size;
        if !self.dirty {
            return Ok(());
        }
        if w == 0 || h == 0 {
            // Minimised: nothing to trace until the window has an area again (`resized`).
            self.dirty = false;
            return Ok(());
        }
        let accel = self.accel;
        let structure = accel.structure_name();
        if !self.renderers.iter().any(|(b, _)| *b == structure) {
            let scene = self.scene_for(accel)?;
            let (r, notes) = Renderer::open(self.backend, scene, accel)?;
            for n in notes {
                eprintln!("note: {n}");
            }
            self.renderers.push((structure, r));
        }
        let camera = self.orbit.camera();
        let opts = RenderOptions::new(w.min(MAX_SIDE), h.min(MAX_SIDE), self.mode, accel);
        let r = &mut self.renderers.iter_mut().find(|(b, _)| *b == structure).unwrap().1;
        let t0 = Instant::now();
        let f = r.render(&camera, &self.grid_scene.lights, &opts, None)?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let describe = r.describe();
        // What this frame sent to the device: uniforms and lights only (the scene stays there).
        let up = f
            .gpu
            .as_ref()
            .map_or(String::new(), |g| format!(", {} B uploaded", g.uploaded_bytes));
        if let Some(win) = &self.window {
            win.set_title(&format!(
                "gridtrace: {} - {} {} - {ms:.1} ms{up} - {describe}",
                self.name,
                self.mode.name(),
                accel.name()
            ));
        }
        self.frame = Some(Frame { image: f.image, ms });
        self.dirty = false;
        Ok(())
    }

    fn apply(&mut self, action: Action, el: &ActiveEventLoop) -> gridtrace::Result<()> {
        match action {
            Action::Orbit(dx, dy) => {
                self.orbit.drag(dx, dy);
                self.dirty = true;
            }
            Action::Zoom(s) => {
                self.orbit.zoom(s);
                self.dirty = true;
            }
            Action::Fly(f, r, u) => {
                self.orbit.fly(f, r, u);
                self.dirty = true;
            }
            Action::Frame => {
                let b = self.grid_scene.accel.bounds();
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
            Action::Screenshot(path) => {
                self.trace()?;
                let Some(f) = &self.frame else {
                    return Err(gridtrace::Error::InvalidInput(
                        "screenshot: no frame yet (the window has no area)".into(),
                    ));
                };
                f.image.save_png(&path)?;
                let c = self.orbit.camera();
                let v = |v: glam::Vec3| format!("{:?},{:?},{:?}", v.x, v.y, v.z);
                println!(
                    "screenshot {} eye={} target={} up={} vfov={:?} mode={} accel={} res={}x{} ms={:.1}",
                    path.display(),
                    v(c.eye),
                    v(c.target),
                    v(c.up),
                    c.vfov_deg,
                    self.mode.name(),
                    self.accel.name(),
                    f.image.width,
                    f.image.height,
                    f.ms
                );
            }
            Action::Quit => el.exit(),
        }
        Ok(())
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

    fn redraw(&mut self) -> gridtrace::Result<()> {
        self.trace()?;
        if let (Some(p), Some(f)) = (&mut self.presenter, &self.frame) {
            p.present(&f.image)?;
        }
        Ok(())
    }

    fn fail(&mut self, el: &ActiveEventLoop, e: gridtrace::Error) {
        self.error = Some(e);
        el.exit();
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
            Ok(p) => self.presenter = Some(p),
            Err(e) => return self.fail(el, e),
        }
        let s = window.inner_size();
        self.window = Some(window.clone());
        self.resized(s.width, s.height);
        window.request_redraw();
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let result = match event {
            WindowEvent::CloseRequested => {
                el.exit();
                Ok(())
            }
            WindowEvent::Resized(s) => {
                self.resized(s.width, s.height);
                Ok(())
            }
            WindowEvent::RedrawRequested => self.redraw(),
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                self.drag = (state == ElementState::Pressed).then_some(self.cursor);
                Ok(())
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = (position.x, position.y);
                match self.drag {
                    Some((x, y)) => {
                        self.drag = Some(self.cursor);
                        self.apply(Action::Orbit((position.x - x) as f32, (position.y - y) as f32), el)
                    }
                    None => Ok(()),
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => (p.y / 40.0) as f32,
                };
                self.apply(Action::Zoom(steps), el)
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                let action = match &event.logical_key {
                    Key::Named(NamedKey::Escape) => Some(Action::Quit),
                    Key::Character(c) => match c.as_str() {
                        "g" | "G" => Some(Action::NextAccel),
                        "f" | "F" => Some(Action::Frame),
                        "p" | "P" => {
                            self.shots += 1;
                            Some(Action::Screenshot(format!("gridtrace-view-{}.png", self.shots).into()))
                        }
                        k => mode_key(k)
                            .map(Action::SetMode)
                            .or_else(|| fly_key(k).map(|(f, r, u)| Action::Fly(f, r, u))),
                    },
                    _ => None,
                };
                match action {
                    Some(a) => self.apply(a, el),
                    None => Ok(()),
                }
            }
            _ => Ok(()),
        };
        if let Err(e) = result {
            return self.fail(el, e);
        }
        if self.dirty
            && let Some(w) = &self.window
        {
            w.request_redraw();
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        // A script runs one action per pass of the event loop, after the frame before it was
        // traced and presented, so a screenshot shows what a person would have seen.
        if self.script.is_none() || self.window.is_none() {
            return;
        }
        // Trace and present here rather than wait for a redraw request: a script must not
        // depend on the window system's timing.
        if let Err(e) = self.redraw() {
            return self.fail(el, e);
        }
        let next = self.script.as_mut().and_then(|s| s.pop()).unwrap_or(Action::Quit);
        if let Err(e) = self.apply(next, el) {
            return self.fail(el, e);
        }
        el.set_control_flow(ControlFlow::Poll);
    }
}
