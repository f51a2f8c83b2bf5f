//! gridtrace in a web page: the library built to wasm32, its scenes, structures and tracers
//! exported to the page's script (`web/`) through wasm-bindgen.
//!
//! Nothing here traces: the page opens a built-in scene or a mesh from bytes with `render`'s
//! choices (`params`), prepares it with the library's structures and traces it with the
//! library's tracers: the GPU frame path on WebGPU (the paper's streaming kernels; WebGPU has
//! no ray queries) or, without WebGPU, the CPU tracer on the page's one thread.
//!
//! A browser's page may not block, so a frame is three calls: `submit` (the GPU frame is
//! submitted and its readback asked for; a CPU frame is traced there and then), `ready` (the
//! page yields to its event loop until it holds: WebGPU completes the readback only there) and
//! `finish` (the pixels, RGBA, for the canvas).

use std::sync::Arc;

use gridtrace::gpu::{FrameInFlight, GpuContext, GpuVariants};
use gridtrace::scene::orbit::Orbit;
use gridtrace::scene::{Camera, PointLight, Scene};
use gridtrace::util::Instant;
use gridtrace::{Backend, Mode, PixelFormat, Placement, RenderOptions, Tracer, Work};
use wasm_bindgen::prelude::*;

pub mod params;

pub use params::PageParams;

/// A WebGPU device, opened once (`openWebGpu`) and handed to `Page::open`.
#[wasm_bindgen]
pub struct WebGpu(Arc<GpuContext>);

/// Opens the browser's WebGPU adapter and a device with the limits the kernels need (an error
/// saying which limit falls short, or that there is no adapter).
#[wasm_bindgen(js_name = openWebGpu)]
pub async fn open_webgpu() -> Result<WebGpu, JsError> {
    let ctx = GpuContext::new_async(wgpu::InstanceDescriptor::new_without_display_handle())
        .await
        .map_err(js_error)?;
    Ok(WebGpu(Arc::new(ctx)))
}

#[wasm_bindgen]
impl WebGpu {
    /// The adapter, as `render` prints it.
    pub fn describe(&self) -> String {
        self.0.describe()
    }
}

/// The built-in scenes' names (the registry `gridtrace render --scene` reads).
#[wasm_bindgen]
pub fn scenes() -> Vec<String> {
    gridtrace::scene::builtin::SCENES
        .iter()
        .map(|(n, _)| n.to_string())
        .collect()
}

/// The modes' names, as `--mode` takes them.
#[wasm_bindgen]
pub fn modes() -> Vec<String> {
    Mode::ALL.iter().map(|m| m.name().to_string()).collect()
}

/// The structures' names, `auto` first, as `--accel` takes them (the structure registry).
#[wasm_bindgen]
pub fn accels() -> Vec<String> {
    let names = gridtrace::accel::registry::ENTRIES.iter().map(|e| e.name.to_string());
    std::iter::once("auto".to_string()).chain(names).collect()
}

/// The `backend` parameter of a query (`auto`, `gpu` or `cpu`), so that the page opens WebGPU
/// only where it is wanted; an error for a query `Page::open` would refuse.
#[wasm_bindgen(js_name = backendOf)]
pub fn backend_of(query: &str) -> Result<String, JsError> {
    let p = PageParams::from_query(query).map_err(|e| JsError::new(&e))?;
    Ok(match p.backend {
        Backend::Auto => "auto",
        Backend::Gpu => "gpu",
        Backend::Cpu => "cpu",
    }
    .into())
}

/// A frame for the canvas: RGBA bytes, 8-bit sRGB, row by row from the top.
#[wasm_bindgen]
pub struct Frame {
    width: u32,
    height: u32,
    rgba: Vec<u8>,
    ms: f64,
    mrays_per_s: f64,
    stages: String,
}

#[wasm_bindgen]
impl Frame {
    #[wasm_bindgen(getter)]
    pub fn width(&self) -> u32 {
        self.width
    }
    #[wasm_bindgen(getter)]
    pub fn height(&self) -> u32 {
        self.height
    }
    /// The pixels (a copy, for an `ImageData`).
    pub fn rgba(&self) -> Vec<u8> {
        self.rgba.clone()
    }
    /// From `submit` to the pixels in host memory (ms, the page's clock).
    #[wasm_bindgen(getter)]
    pub fn ms(&self) -> f64 {
        self.ms
    }
    /// Rays traced (eye, shadow, reflection) per second over `ms`, in millions.
    #[wasm_bindgen(getter, js_name = mraysPerS)]
    pub fn mrays_per_s(&self) -> f64 {
        self.mrays_per_s
    }
    /// A WebGPU frame's time per kernel stage on the GPU, from timestamp queries, as a line for
    /// the overlay; without them (a browser that gives none) the line says so; empty on the CPU.
    #[wasm_bindgen(getter)]
    pub fn stages(&self) -> String {
        self.stages.clone()
    }
}

/// The overlay's line of GPU stage times (see `Frame::stages`).
fn stage_line(t: &gridtrace::gpu::GpuTimings) -> String {
    if !t.from_timestamps {
        return "GPU stage times: this browser gives no timestamp queries".to_string();
    }
    let stages: Vec<String> = t.stages_ms.iter().map(|(s, ms)| format!("{s} {ms:.2}")).collect();
    format!("GPU {:.2} ms: {} (ms)", t.total_ms, stages.join(", "))
}

/// A scene prepared and placed (WebGPU or the CPU) with the page's choices, and the frame
/// being made.
#[wasm_bindgen]
pub struct Page {
    params: PageParams,
    device: Option<Arc<GpuContext>>,
    tracer: Tracer,
    /// The frame's camera: the query's until the pointer moves it (then `orbit`'s), so that the
    /// first frame is `render`'s to the bit.
    camera: Camera,
    orbit: Orbit,
    lights: Vec<PointLight>,
    /// The scene's name and what was built, for the overlay.
    summary: String,
    notes: Vec<String>,
    pending: Option<Pending>,
}

/// A frame between `submit` and `finish`.
enum Pending {
    Gpu(FrameInFlight, Instant),
    Done(Box<gridtrace::Frame>, Instant),
}

/// A library error as the page's exception (its message becomes `dataset.error`).
fn js_error(e: gridtrace::Error) -> JsError {
    JsError::new(&e.to_string())
}

#[wasm_bindgen]
impl Page {
    /// The built-in scene the query names (`PageParams`), prepared with its structure and
    /// placed on `gpu` (the device `openWebGpu` opened; `None`: the browser has no WebGPU, or
    /// the query asked for the CPU). `backend=gpu` without a device is an error; `auto` with a
    /// scene the device cannot hold traces on the CPU, with a note.
    pub fn open(query: &str, gpu: Option<WebGpu>) -> Result<Page, JsError> {
        let params = PageParams::from_query(query).map_err(|e| JsError::new(&e))?;
        let scene = gridtrace::scene::builtin::scene(&params.scene).expect("PageParams checks the scene's name");
        let name = params.scene.clone();
        Page::with_scene(params, gpu.map(|g| g.0), scene, &name)
    }

    /// The page's scene replaced by a mesh file's bytes (OBJ, PLY, glTF/GLB, STL, OFF; the
    /// format from `name`'s extension), auto-framed over a floor as `render --mesh` frames it,
    /// on the same device; the query's camera options are left out (they were for the scene
    /// before).
    #[wasm_bindgen(js_name = openMesh)]
    pub fn open_mesh(&mut self, name: &str, bytes: &[u8]) -> Result<(), JsError> {
        let mesh = gridtrace::io::parse_mesh(bytes, std::path::Path::new(name)).map_err(js_error)?;
        let scene = gridtrace::scene::builtin::mesh_scene(mesh, true);
        let params = PageParams {
            eye: None,
            target: None,
            up: None,
            vfov: None,
            ..self.params.clone()
        };
        *self = Page::with_scene(params, self.device.clone(), scene, name)?;
        Ok(())
    }

    fn with_scene(
        params: PageParams,
        device: Option<Arc<GpuContext>>,
        scene: Scene,
        name: &str,
    ) -> Result<Page, JsError> {
        let backend = match (params.backend, &device) {
            (Backend::Gpu, None) => {
                return Err(JsError::new(
                    "backend=gpu: this browser gave no WebGPU device (backend=auto or cpu traces on the CPU)",
                ));
            }
            (Backend::Cpu, _) | (_, None) => Backend::Cpu,
            (b, Some(_)) => b,
        };
        let placement = match (backend, &device) {
            (Backend::Cpu, _) | (_, None) => Placement::cpu(),
            (b, Some(d)) => Placement {
                backend: b,
                device: Some(d.clone()),
                variants: GpuVariants::default(),
            },
        };
        // The library's path, in its parts (the device was opened asynchronously above).
        let mut notes = Vec::new();
        let kind = placement.pick(&params.accel, Work::Render, &mut notes);
        let (tracer, build_ms) = placement
            .open_scene(&scene, kind, &params.accel, &mut notes)
            .map_err(js_error)?;
        let summary = format!(
            "{name}: {} triangles, {}, built in {build_ms:.1} ms",
            tracer.scene.accel.tris.len(),
            tracer.scene.accel.summary()
        );
        let camera = params.camera(&tracer.scene.camera);
        let lights = tracer.scene.lights.clone();
        Ok(Page {
            params,
            device,
            tracer,
            camera,
            orbit: Orbit::from_camera(&camera),
            lights,
            summary,
            notes,
            pending: None,
        })
    }

    /// `webgpu` or `cpu`: where the frames are traced.
    pub fn backend(&self) -> String {
        if self.tracer.gpu().is_some() { "webgpu" } else { "cpu" }.into()
    }

    /// The scene, its structure and the tracer, in words.
    pub fn describe(&self) -> String {
        format!("{}; {}", self.summary, self.tracer.describe())
    }

    /// What was chosen other than asked (the structure `auto` picked, the CPU for a scene the
    /// device cannot hold), one per line.
    pub fn notes(&self) -> String {
        self.notes.join("\n")
    }

    /// Orbits the camera about its target by a drag of (dx, dy) canvas pixels (as the viewer).
    pub fn orbit(&mut self, dx: f32, dy: f32) {
        self.orbit.drag(dx, dy);
        self.camera = self.orbit.camera();
    }

    /// Pans by a drag of (dx, dy) canvas pixels: the point at the target's depth follows the
    /// pointer.
    pub fn pan(&mut self, dx: f32, dy: f32) {
        self.orbit.pan(dx, dy, self.params.res.1 as f32);
        self.camera = self.orbit.camera();
    }

    /// Zooms by wheel steps (positive: closer).
    pub fn zoom(&mut self, steps: f32) {
        self.orbit.zoom(steps);
        self.camera = self.orbit.camera();
    }

    /// Zooms by a two-finger pinch: `spread` is the fingers' new distance apart over the old.
    pub fn pinch(&mut self, spread: f32) {
        self.orbit.pinch(spread);
        self.camera = self.orbit.camera();
    }

    /// The frame's camera as URL parameters (`eye=X,Y,Z&target=X,Y,Z&up=X,Y,Z&vfov=D`, each
    /// number as it round-trips): with them the page, or `gridtrace render` given the same
    /// values as options, traces this view again.
    pub fn view(&self) -> String {
        let c = &self.camera;
        let v = |p: glam::Vec3| format!("{},{},{}", p.x, p.y, p.z);
        format!(
            "eye={}&target={}&up={}&vfov={}",
            v(c.eye),
            v(c.target),
            v(c.up),
            c.vfov_deg
        )
    }

    fn options(&self) -> RenderOptions {
        let (w, h) = self.params.res;
        RenderOptions::new(w, h, self.params.mode).with_pixels(PixelFormat::Srgb8)
    }

    /// Starts a frame of the page's camera: on WebGPU it is submitted (`ready` says when it
    /// has come back); on the CPU it is traced here, on the page's thread.
    pub fn submit(&mut self) -> Result<(), JsError> {
        let opts = self.options();
        let t0 = Instant::now();
        let (camera, lights) = (self.camera, self.lights.clone());
        let pending = match self.tracer.gpu_mut() {
            Some(gpu) => Pending::Gpu(gpu.submit_frame(&camera, &lights, &opts, None).map_err(js_error)?, t0),
            None => Pending::Done(
                Box::new(self.tracer.render(&camera, &lights, &opts).map_err(js_error)?),
                t0,
            ),
        };
        self.pending = Some(pending);
        Ok(())
    }

    /// Whether the frame `submit` started can be finished without waiting.
    pub fn ready(&self) -> bool {
        match &self.pending {
            Some(Pending::Gpu(f, _)) => f.is_ready(),
            Some(Pending::Done(..)) => true,
            None => false,
        }
    }

    /// The frame `submit` started, once `ready`.
    pub fn finish(&mut self) -> Result<Frame, JsError> {
        let (image, stats, stages, t0) = match self.pending.take() {
            None => return Err(JsError::new("finish: no frame was submitted")),
            Some(Pending::Done(f, t0)) => (f.image, f.stats, String::new(), t0),
            Some(Pending::Gpu(f, t0)) => {
                let gpu = self.tracer.gpu_mut().expect("a GPU frame comes from the GPU tracer");
                let (image, stats) = gpu.finish_frame(f).map_err(js_error)?;
                (
                    image.expect("a frame without a device image comes to the host"),
                    stats.render,
                    stage_line(&stats.timings),
                    t0,
                )
            }
        };
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let image = if self.params.mode == Mode::Heat {
            image.heat_to_color()
        } else {
            image
        };
        let rgba = image
            .to_rgb8()
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect();
        Ok(Frame {
            width: image.width,
            height: image.height,
            rgba,
            ms,
            mrays_per_s: stats.rays.total() as f64 / (ms * 1e3).max(1e-9),
            stages,
        })
    }
}
