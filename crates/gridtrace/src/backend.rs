//! Where tracing runs: the one place that turns `--backend auto|gpu|cpu` and what the machine
//! has (an adapter; room for the scene) into a CPU or a GPU renderer. Every structure runs on
//! both.
//! The CLI, Python and the ray queries come through here (the benchmarks time each backend on
//! its own, so they open both explicitly).
//!
//! ```
//! use gridtrace::{scene::builtin, AccelKind, Backend, Mode, RenderOptions, Renderer, Resolution};
//!
//! let accel = AccelKind::ProximityCloud;
//! let scene = builtin::knot_box().prepare_for(accel, Resolution::default())?;
//! let (mut renderer, notes) = Renderer::open(Backend::Cpu, &scene, accel)?;
//! assert!(notes.is_empty() && renderer.gpu().is_none());
//! let opts = RenderOptions::new(32, 24, Mode::Shadow, accel);
//! let frame = renderer.render(&scene.camera, &scene.lights, &opts, None)?;
//! assert_eq!((frame.image.width, frame.stats.rays.eye), (32, 32 * 24));
//! # Ok::<(), gridtrace::Error>(())
//! ```

use std::sync::Arc;

use crate::accel::AccelKind;
use crate::gpu::{GpuContext, GpuRenderStats, GpuRenderer};
use crate::render::{Image, RenderOptions, RenderStats};
use crate::scene::{Camera, PointLight, PreparedScene};
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
    /// error; `auto` falls back to the CPU.
    pub fn open_device(self) -> Result<(Option<Arc<GpuContext>>, Vec<String>)> {
        let mut notes = Vec::new();
        let ctx = match self {
            Backend::Cpu => None,
            Backend::Gpu => Some(Arc::new(GpuContext::new()?)),
            Backend::Auto => match GpuContext::new() {
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
    /// The scene uploaded to the device `ctx` that this backend opened (`open_device`), or
    /// `None` to trace it on the CPU: with `auto`, a scene the GPU cannot hold (over its buffer
    /// limits) is traced on the CPU, with a note; with `gpu` that is an error that says so.
    pub fn upload(
        self,
        ctx: Arc<GpuContext>,
        scene: &PreparedScene,
        notes: &mut Vec<String>,
    ) -> Result<Option<GpuRenderer>> {
        match GpuRenderer::new(ctx, scene) {
            Ok(gpu) => Ok(Some(gpu)),
            Err(e) if self == Backend::Auto => {
                notes.push(format!("the GPU cannot trace this scene ({e}); using the CPU"));
                Ok(None)
            }
            Err(Error::Gpu(m)) => Err(Error::Gpu(format!(
                "{m}; use --backend cpu (or auto) to trace it on the CPU"
            ))),
            Err(e) => Err(e),
        }
    }
}

/// Where frames are traced, in words: "cpu (N threads)" or "gpu: " and the adapter's
/// description (`None`: the CPU).
pub fn describe_tracer(gpu: Option<&GpuRenderer>) -> String {
    match gpu {
        Some(g) => format!("gpu: {}", g.context().describe()),
        None => format!("cpu ({} threads)", rayon::current_num_threads()),
    }
}

/// A scene ready to render frames on the CPU or a GPU. The scene stays where it is (on the GPU:
/// uploaded once); each frame takes its own camera and lights.
pub enum Renderer<'s> {
    Cpu(&'s PreparedScene),
    Gpu {
        gpu: Box<GpuRenderer>,
        scene: &'s PreparedScene,
    },
}

/// One rendered frame.
#[derive(Debug, Clone)]
pub struct Frame {
    pub image: Image,
    pub stats: RenderStats,
    /// GPU stage times and tiles, for frames traced on a GPU.
    pub gpu: Option<GpuRenderStats>,
}

impl<'s> Renderer<'s> {
    /// Opens the renderer for `backend` and `accel` over `scene`, with notes for the user on
    /// what was chosen instead of what was asked for. With `auto`, a scene the GPU cannot hold
    /// (over its buffer limits) is traced on the CPU; with `gpu` that is an error that says so.
    pub fn open(backend: Backend, scene: &'s PreparedScene, accel: AccelKind) -> Result<(Renderer<'s>, Vec<String>)> {
        scene.accel.check_serves(accel)?;
        let (ctx, mut notes) = backend.open_device()?;
        let gpu = match ctx {
            Some(ctx) => backend.upload(ctx, scene, &mut notes)?,
            None => None,
        };
        Ok(match gpu {
            Some(gpu) => (
                Renderer::Gpu {
                    gpu: Box::new(gpu),
                    scene,
                },
                notes,
            ),
            None => (Renderer::Cpu(scene), notes),
        })
    }

    /// "cpu (N threads)" or the GPU adapter's description.
    pub fn describe(&self) -> String {
        describe_tracer(self.gpu())
    }

    pub fn gpu(&self) -> Option<&GpuRenderer> {
        match self {
            Renderer::Gpu { gpu, .. } => Some(gpu),
            Renderer::Cpu(_) => None,
        }
    }

    /// One frame from `camera` with `lights`. `progress` (CPU only) is called with the number of
    /// image rows finished.
    pub fn render(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
        progress: Option<&(dyn Fn(u32) + Sync)>,
    ) -> Result<Frame> {
        match self {
            Renderer::Cpu(scene) => {
                let (image, stats) = crate::cpu::render_view(scene, camera, lights, opts, progress)?;
                Ok(Frame {
                    image,
                    stats,
                    gpu: None,
                })
            }
            Renderer::Gpu { gpu, .. } => {
                let (image, s) = gpu.render(camera, lights, opts)?;
                Ok(Frame {
                    image,
                    stats: s.render,
                    gpu: Some(s),
                })
            }
        }
    }
}
