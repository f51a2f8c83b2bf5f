//! Where tracing runs: the one place that turns `--backend auto|gpu|cpu` and what the machine
//! has (an adapter, whether it is a software one, room for the scene) into a CPU or a GPU
//! tracer, with a note for the user on every choice that was not the one asked for. `Tracer`
//! is the one type that owns a prepared scene with where it is traced; render, animate, the
//! viewer and Python trace through it (`placement.rs`: `Placement`, and `open_scene`, the one
//! path from a scene to its tracer), and the ray queries (`query/`, through `placement.rs`) and
//! the benchmarks open their device here.
//!
//! ```
//! use gridtrace::{scene::builtin, AccelKind, AccelParams, Backend, Mode, RenderOptions, Tracer};
//!
//! let accel = AccelKind::ProximityCloud;
//! let scene = builtin::knot_box().prepare_for(accel, &AccelParams::NONE)?;
//! let (mut tracer, notes) = Tracer::open_with(Backend::Cpu, scene)?;
//! assert!(notes.is_empty() && tracer.gpu().is_none());
//! let opts = RenderOptions::new(32, 24, Mode::Shadow);
//! let frame = tracer.render(&tracer.scene.camera.clone(), &tracer.scene.lights.clone(), &opts)?;
//! assert_eq!((frame.image.width, frame.stats.rays.eye), (32, 32 * 24));
//! # Ok::<(), gridtrace::Error>(())
//! ```

use std::sync::Arc;

use crate::accel::{AccelKind, TracedOn};
use crate::gpu::{DeviceImage, GpuContext, GpuRenderStats, GpuRenderer};
use crate::render::{Image, RenderOptions, RenderStats};
use crate::scene::{Camera, PointLight, PreparedScene, RebuildOn};
use crate::{Error, Result};

/// Where rays are traced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Backend {
    /// The GPU when an adapter can be opened and the scene fits it, else the CPU.
    #[default]
    Auto,
    Gpu,
    Cpu,
}

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "auto" => Ok(Backend::Auto),
            "gpu" => Ok(Backend::Gpu),
            "cpu" => Ok(Backend::Cpu),
            _ => Err(format!("backend must be auto, gpu or cpu; got '{s}'")),
        }
    }
}

impl Backend {
    /// Opens the GPU device this backend asks for (`None`: trace on the CPU), with notes for
    /// the user on every choice that was not the one asked for. `gpu` without an adapter is an
    /// error. `auto` falls back to the CPU without an adapter, and passes a software adapter
    /// (lavapipe, SwiftShader, WARP) over: it runs the shaders on the same CPU cores, slower
    /// than the CPU tracer (README's first command, mirror-spheres traced at 512x512 on 2 cores:
    /// 6.3-6.6 s on lavapipe against 0.89-0.97 s on the CPU with the grid, 4.9 s against 0.30 s
    /// with the BVH; 2026-11-26), so `--backend gpu` is the way to use one.
    pub fn open_device(self) -> Result<(Option<Arc<GpuContext>>, Vec<String>)> {
        self.open_device_with(wgpu::InstanceDescriptor::new_without_display_handle)
    }

    /// `open_device`, its instance made from `desc()` (`GpuContext::new_with`): the viewer's
    /// knows the window's display, so that it can present from the tracer's device.
    pub fn open_device_with(
        self,
        desc: impl FnOnce() -> wgpu::InstanceDescriptor,
    ) -> Result<(Option<Arc<GpuContext>>, Vec<String>)> {
        let mut notes = Vec::new();
        let ctx = match self {
            Backend::Cpu => None,
            Backend::Gpu => Some(Arc::new(GpuContext::new_with(desc())?)),
            Backend::Auto => match GpuContext::new_with(desc()) {
                Ok(c) if c.is_software() => {
                    notes.push(format!(
                        "the only adapter is a software rasteriser ({}), slower than the CPU tracer on the same \
                         cores: tracing on the CPU (--backend gpu to use it)",
                        c.info.name
                    ));
                    None
                }
                Ok(c) => Some(Arc::new(c)),
                Err(e) => {
                    notes.push(format!("no usable GPU ({e}); using the CPU"));
                    None
                }
            },
        };
        Ok((ctx, notes))
    }
}

impl Backend {
    /// Whether this backend traces on a GPU when it can: `gpu` always, `cpu` never, `auto` when
    /// the machine has a hardware adapter (`hardware_adapter_present`).
    pub fn traces_on_gpu(self) -> bool {
        match self {
            Backend::Gpu => true,
            Backend::Cpu => false,
            Backend::Auto => hardware_adapter_present(),
        }
    }

    /// `traces_on_gpu` as `AccelChoice::resolve` weighs it, with whether that GPU has ray
    /// queries: for the callers that choose a structure before they open a device.
    pub fn traced_on(self) -> TracedOn {
        if self.traces_on_gpu() {
            TracedOn::Gpu {
                hardware_ray_queries: hardware_ray_queries_present(),
            }
        } else {
            TracedOn::Cpu
        }
    }
}

/// Whether the machine has a hardware GPU adapter (not a software one such as lavapipe), as
/// `Backend::Auto` would use it. Probed once per process by opening a device: callers that
/// decide before they open one (the ray queries choose a structure and keep a mesh) ask here.
pub fn hardware_adapter_present() -> bool {
    hardware_probe().0
}

/// Whether that hardware adapter has ray queries (`hwrt`): what `--accel auto` weighs before
/// it picks `hwrt` where no device is open yet (`Backend::traced_on`). Probed with
/// `hardware_adapter_present`.
pub fn hardware_ray_queries_present() -> bool {
    hardware_probe().1
}

/// (a hardware adapter, with ray queries), probed once per process.
fn hardware_probe() -> (bool, bool) {
    static PRESENT: std::sync::OnceLock<(bool, bool)> = std::sync::OnceLock::new();
    *PRESENT.get_or_init(|| match GpuContext::new() {
        Ok(c) if !c.is_software() => (true, c.hardware_ray_queries()),
        _ => (false, false),
    })
}

/// Where work on `device` (`None`: the CPU) runs, as `AccelChoice::resolve` weighs it: for the
/// callers that opened the device first (`Backend::open_device`).
pub fn traced_on(device: Option<&GpuContext>) -> TracedOn {
    match device {
        None => TracedOn::Cpu,
        Some(c) => TracedOn::Gpu {
            hardware_ray_queries: c.hardware_ray_queries(),
        },
    }
}

/// Where frames are traced, in words: "cpu (N threads)" or "gpu: " and the adapter's
/// description (`None`: the CPU).
pub fn describe_tracer(gpu: Option<&GpuRenderer>) -> String {
    match gpu {
        Some(g) => format!("gpu: {}", g.context().describe()),
        None => describe_cpu(),
    }
}

/// The CPU as every report names it: "cpu (N threads)", the threads of the pool the work runs
/// on (`--threads`, Python's `threads=`, else every core).
pub fn describe_cpu() -> String {
    format!("cpu ({} threads)", rayon::current_num_threads())
}

/// An adapter in a few words: "NAME (BACKEND)", with ", software" for a software rasteriser.
pub fn adapter_words(info: &wgpu::AdapterInfo) -> String {
    format!(
        "{} ({:?}{})",
        info.name,
        info.backend,
        if info.device_type == wgpu::DeviceType::Cpu {
            ", software"
        } else {
            ""
        }
    )
}

/// One rendered frame.
#[derive(Debug, Clone)]
pub struct Frame {
    pub image: Image,
    pub stats: RenderStats,
    /// GPU stage times and tiles, for frames traced on a GPU.
    pub gpu: Option<GpuRenderStats>,
}

/// A frame asked into a device image (`Tracer::render_to_device`).
#[derive(Debug, Clone)]
pub enum Rendered {
    /// Its pixels are in the device image; its figures came back.
    OnDevice(GpuRenderStats),
    /// It was traced on the CPU (no GPU, or the GPU given up): its pixels are here.
    OnHost(Frame),
}

impl Rendered {
    /// The frame's rays and counters, wherever its pixels are.
    pub fn stats(&self) -> &RenderStats {
        match self {
            Rendered::OnDevice(g) => &g.render,
            Rendered::OnHost(f) => &f.stats,
        }
    }

    /// Its GPU figures, where a GPU traced it.
    pub fn gpu(&self) -> Option<&GpuRenderStats> {
        match self {
            Rendered::OnDevice(g) => Some(g),
            Rendered::OnHost(f) => f.gpu.as_ref(),
        }
    }
}

/// A prepared scene owned together with where it is traced (its GPU upload, or the CPU): what
/// every program that renders holds, for one frame or many. It owns the scene, so it can be
/// dropped and replaced (a file dropped on the viewer) and moved (`update_vertices`).
pub struct Tracer {
    pub scene: PreparedScene,
    pub(crate) gpu: Option<GpuRenderer>,
    /// The choice it was opened with: under `auto` a GPU that fails (a lost device, memory
    /// gone) hands the work to the CPU for good, with a note, and the frame is still made.
    backend: Backend,
    /// What happened since the caller last asked (`take_notes`).
    notes: Vec<String>,
}

/// What moving the vertices cost, and how the structure followed.
#[derive(Debug, Clone)]
pub struct Update {
    /// Triangles, normals and bounds of the moved mesh (host).
    pub geometry_ms: f64,
    /// The structure's update: a CPU rebuild or refit, or the GPU build plus uploads.
    pub build_ms: f64,
    /// How the structure was updated, in words.
    pub how: String,
}

impl Tracer {
    /// A tracer of `scene` on `gpu` (`None`: the CPU), as `Tracer::open` (`placement.rs`)
    /// makes it once the scene is placed.
    pub(crate) fn from_parts(scene: PreparedScene, gpu: Option<GpuRenderer>, backend: Backend) -> Tracer {
        Tracer {
            scene,
            gpu,
            backend,
            notes: Vec::new(),
        }
    }

    pub fn gpu(&self) -> Option<&GpuRenderer> {
        self.gpu.as_ref()
    }

    /// The GPU upload, to submit a frame and read it back later (`GpuRenderer::submit_frame`,
    /// `finish_frame`): a browser page cannot block on `render`'s wait, so it submits, yields
    /// to its event loop until the frame `is_ready`, then finishes it.
    pub fn gpu_mut(&mut self) -> Option<&mut GpuRenderer> {
        self.gpu.as_mut()
    }

    /// "cpu (N threads)" or the GPU adapter's description.
    pub fn describe(&self) -> String {
        describe_tracer(self.gpu.as_ref())
    }

    /// The same in a few words: "gpu: NAME (BACKEND)", "software" for a software adapter.
    pub fn short(&self) -> String {
        match &self.gpu {
            Some(g) => format!("gpu: {}", adapter_words(&g.context().info)),
            None => self.describe(),
        }
    }

    /// Switches to another traversal of the same structure (the grid's `grid` and `pc`), on the
    /// CPU's scene and the GPU's upload alike: nothing is built or uploaded. An error for a
    /// traversal of another structure, which needs a scene prepared for it.
    pub fn set_traversal(&mut self, kind: AccelKind) -> Result<()> {
        if let Some(g) = &mut self.gpu {
            g.set_traversal(kind)?;
        }
        self.scene.accel.set_traversal(kind)
    }

    /// One frame (or band of rows, `opts.rows`) from `camera` with `lights`, by the traversal
    /// the scene's structure serves (`Accel::kind`; `set_traversal` switches grid and pc).
    pub fn render(&mut self, camera: &Camera, lights: &[PointLight], opts: &RenderOptions) -> Result<Frame> {
        self.render_with_progress(camera, lights, opts, None)
    }

    /// `render`, with `progress` (CPU only) called with the number of image rows finished.
    pub fn render_with_progress(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
        progress: Option<&(dyn Fn(u32) + Sync)>,
    ) -> Result<Frame> {
        if let Some(g) = &mut self.gpu {
            match g.render(camera, lights, opts) {
                Ok((image, s)) => {
                    return Ok(Frame {
                        image,
                        stats: s.render,
                        gpu: Some(s),
                    });
                }
                Err(e) => self.gpu_failed(e)?,
            }
        }
        let (image, stats) = crate::cpu::render_view(&self.scene, camera, lights, opts, progress)?;
        Ok(Frame {
            image,
            stats,
            gpu: None,
        })
    }

    /// `render`, the pixels left in `target` (`GpuRenderer::render_to_device`: the viewer
    /// presents from it, so the image never crosses to the host) where the frame is traced on
    /// the GPU; a frame traced on the CPU comes back as `render` returns it (`Rendered::OnHost`).
    pub fn render_to_device(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
        target: &DeviceImage,
    ) -> Result<Rendered> {
        if let Some(g) = &mut self.gpu {
            match g.render_to_device(camera, lights, opts, target) {
                Ok(s) => return Ok(Rendered::OnDevice(s)),
                Err(e) => self.gpu_failed(e)?,
            }
        }
        self.render(camera, lights, opts).map(Rendered::OnHost)
    }

    /// The notes of what happened since the last call (the GPU given up for the CPU).
    pub fn take_notes(&mut self) -> Vec<String> {
        std::mem::take(&mut self.notes)
    }

    /// The GPU failed with `e`: under `auto` a device error hands the scene to the CPU for
    /// good (its structure brought up to date first, when the GPU was the one rebuilding it)
    /// and says so; anything else, or any error under `gpu`, is the caller's.
    pub(crate) fn gpu_failed(&mut self, e: Error) -> Result<()> {
        match e {
            Error::Gpu(why) if self.backend == Backend::Auto && self.scene.accel.check_cpu_kind().is_ok() => {
                self.gpu = None;
                if self.scene.accel.structure_stale {
                    let tris = self.scene.accel.tris.clone();
                    self.scene.accel.update(tris)?;
                }
                self.notes
                    .push(format!("the GPU failed ({why}); tracing on the CPU from now on"));
                Ok(())
            }
            e => Err(e),
        }
    }

    /// Moves the mesh's vertices and updates the structure where the scene is traced: the
    /// grids rebuilt on the GPU when there is one (else on the CPU), the BVH refitted. A wrong
    /// length or a NaN is an error that leaves the mesh as it was.
    pub fn update_vertices(&mut self, positions: &[glam::Vec3]) -> Result<Update> {
        let on = if self.gpu.is_some() {
            RebuildOn::Device
        } else {
            RebuildOn::Cpu
        };
        let up = self.scene.update_vertices(positions, on)?;
        let mut build_ms = up.structure_ms;
        let mut how = up.how.to_string();
        let updated = match &mut self.gpu {
            Some(g) => g.update_vertices(&self.scene).map(Some),
            None => Ok(None),
        };
        let updated = match updated {
            Ok(u) => u,
            Err(e) => {
                self.gpu_failed(e)?;
                how = "rebuilt on the CPU (the GPU failed)".into();
                None
            }
        };
        if let Some(u) = updated {
            build_ms += u.structure_upload_ms + u.upload_ms;
            if let Some(b) = &u.build {
                build_ms += b.timings.total_ms;
                how = match &b.cpu_fallback {
                    Some(why) => format!("rebuilt on the CPU ({why})"),
                    None => format!(
                        "rebuilt on the GPU ({})",
                        if b.timings.from_timestamps {
                            "timestamps"
                        } else {
                            "wall clock"
                        }
                    ),
                };
            }
        }
        Ok(Update {
            geometry_ms: up.geometry_ms,
            build_ms,
            how,
        })
    }
}
