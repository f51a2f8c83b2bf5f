//! Where work runs, decided once and carried whole (`Placement`), and the one path from a scene
//! to its tracer (`open_scene`): open the device the backend asks for, pick the structure for
//! the work where it will be traced, prepare the scene, upload it. Render, animate, the viewer,
//! Python's `render` and the browser page go through that path (the viewer and the page through
//! its parts, `Placement::pick` and `Placement::open_scene`, since they keep their placement for
//! later scenes), so that none of them drops a part of the request (`--gpu-variant`, `auto`'s
//! note).
//!
//! ```
//! use gridtrace::{scene::builtin, AccelSpec, Backend, Work};
//!
//! let spec: AccelSpec = "auto".parse().unwrap();
//! let opened = gridtrace::open_scene(&builtin::knot_box(), &spec, Work::Render, Backend::Cpu, Default::default())?;
//! assert!(opened.tracer.gpu().is_none());
//! // `auto` says what it picked and why.
//! assert!(opened.notes.iter().any(|n| n.contains(opened.accel.name())), "{:?}", opened.notes);
//! # Ok::<(), gridtrace::Error>(())
//! ```

use std::sync::Arc;
use crate::util::Instant;

use crate::accel::{AccelChoice, AccelKind, AccelParams, AccelSpec, TracedOn, Work};
use crate::backend::{Backend, Tracer, traced_on};
use crate::gpu::{GpuContext, GpuRenderer, GpuVariants};
use crate::scene::{PreparedScene, Scene};
use crate::{Error, Result};

/// Where work is traced, decided once and carried whole: the backend asked for, the device it
/// opened (`None`: the CPU) and the GPU variants the kernels are compiled with. Frames
/// (`Tracer::open`, `open_scene`) and the queries (`QueryPlacement`) place their work through it.
#[derive(Clone, Default)]
pub struct Placement {
    pub backend: Backend,
    /// The device `backend` opened (`Backend::open_device`); `None`: the CPU.
    pub device: Option<Arc<GpuContext>>,
    /// The GPU kernels and layouts (`--gpu-variant`), where the work runs on a GPU.
    pub variants: GpuVariants,
}

impl Placement {
    /// Opens the device `backend` asks for (`Backend::open_device`), with notes for the user on
    /// every choice that was not the one asked for.
    pub fn open(backend: Backend, variants: GpuVariants) -> Result<(Placement, Vec<String>)> {
        Placement::open_with(backend, variants, wgpu::InstanceDescriptor::new_without_display_handle)
    }

    /// `open`, the device's instance made from `desc()` (`Backend::open_device_with`): the
    /// viewer's knows the window's display, so that it can present from the tracer's device.
    pub fn open_with(
        backend: Backend,
        variants: GpuVariants,
        desc: impl FnOnce() -> wgpu::InstanceDescriptor,
    ) -> Result<(Placement, Vec<String>)> {
        let (device, notes) = backend.open_device_with(desc)?;
        Ok((
            Placement {
                backend,
                device,
                variants,
            },
            notes,
        ))
    }

    /// `backend` on a device the caller opened, with the default GPU variants.
    pub fn on_device(backend: Backend, device: Arc<GpuContext>) -> Placement {
        Placement {
            backend,
            device: Some(device),
            variants: GpuVariants::default(),
        }
    }

    /// Everything on the CPU.
    pub fn cpu() -> Placement {
        Placement {
            backend: Backend::Cpu,
            ..Placement::default()
        }
    }

    /// Where its work runs, as `AccelChoice::resolve` weighs it.
    pub fn traced_on(&self) -> TracedOn {
        traced_on(self.device.as_deref())
    }

    /// The scene uploaded to the device, or `None` to trace it on the CPU (no device, or, with
    /// `auto`, a scene the GPU cannot hold: over its buffer limits, or a structure without a
    /// GPU walk, with a note); with `gpu` the latter are errors that say so.
    pub fn upload(&self, scene: &PreparedScene, notes: &mut Vec<String>) -> Result<Option<GpuRenderer>> {
        let Some(ctx) = &self.device else {
            return Ok(None);
        };
        let kind = scene.accel.structure_name();
        if !crate::accel::registry::ENTRIES
            .iter()
            .any(|e| e.structure == kind && e.gpu)
        {
            let why = format!("'{kind}' has no GPU walk");
            return match self.backend {
                Backend::Auto => {
                    notes.push(format!("{why}; using the CPU"));
                    Ok(None)
                }
                _ => Err(Error::Gpu(format!(
                    "{why}; use --backend cpu (or auto) to trace it on the CPU"
                ))),
            };
        }
        let cpu_traces = scene.accel.check_cpu_kind().is_ok();
        match GpuRenderer::new(ctx.clone(), scene, &self.variants) {
            Ok(gpu) => Ok(Some(gpu)),
            Err(e) if self.backend == Backend::Auto && cpu_traces => {
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


/// A scene opened along the one path (`open_scene`).
pub struct OpenedScene {
    pub tracer: Tracer,
    /// Where it was placed, for the scenes opened after it (the viewer's other structures).
    pub placement: Placement,
    /// The traversal it was prepared for (`auto` resolved).
    pub accel: AccelKind,
    /// The structure's build (preparing the scene), in milliseconds.
    pub build_ms: f64,
    /// For the user: every choice that was not the one asked for, and `auto`'s pick and why.
    pub notes: Vec<String>,
}

/// The one path from a scene to its tracer: opens the device `backend` asks for with the GPU
/// `variants` (`Placement::open`), picks the structure `spec` names or `auto`'s for `work`
/// where that device traces (`Placement::pick`), prepares the scene and uploads it
/// (`Placement::open_scene`). Every note on the way is kept (`OpenedScene::notes`).
pub fn open_scene(
    scene: &Scene,
    spec: &AccelSpec,
    work: Work,
    backend: Backend,
    variants: GpuVariants,
) -> Result<OpenedScene> {
    let (placement, mut notes) = Placement::open(backend, variants)?;
    let accel = placement.pick(spec, work, &mut notes);
    let (tracer, build_ms) = placement.open_scene(scene, accel, spec, &mut notes)?;
    Ok(OpenedScene {
        tracer,
        placement,
        accel,
        build_ms,
        notes,
    })
}

impl Placement {
    /// The traversal `spec` names, or `auto`'s pick for `work` where this placement traces
    /// (`AccelChoice::resolve`), its note (what it picked and why) pushed to `notes`.
    pub fn pick(&self, spec: &AccelSpec, work: Work, notes: &mut Vec<String>) -> AccelKind {
        let (kind, note) = spec.resolve(self.traced_on(), work);
        notes.extend(note);
        kind
    }

    /// `scene` prepared for `accel` (`prepare`) and traced where this placement says
    /// (`Tracer::open`), with the build's milliseconds.
    pub fn open_scene(
        &self,
        scene: &Scene,
        accel: AccelKind,
        spec: &AccelSpec,
        notes: &mut Vec<String>,
    ) -> Result<(Tracer, f64)> {
        let t0 = Instant::now();
        let prepared = prepare(scene, accel, spec)?;
        let build_ms = t0.elapsed().as_secs_f64() * 1e3;
        Ok((Tracer::open(prepared, self, notes)?, build_ms))
    }
}

/// `scene` prepared for `accel`, with `spec`'s build parameters where it named a traversal of
/// the same structure and the structure's defaults otherwise (the viewer's G cycle moves to
/// structures the parameters were not written for).
pub fn prepare(scene: &Scene, accel: AccelKind, spec: &AccelSpec) -> Result<PreparedScene> {
    let params = match spec.choice {
        AccelChoice::Kind(named) if named.structure_name() == accel.structure_name() => spec.params.clone(),
        _ => AccelParams::NONE,
    };
    scene.prepare_for(accel, &params)
}

