//! Where work runs, decided once and carried whole (`Placement`), and the one path from a scene
//! to its tracer (`open_scene`): open the device the backend asks for, pick the structure for
//! the work where it will be traced, prepare the scene, upload it. Render, animate, the viewer,
//! Python's `render` and the browser page go through that path (the viewer and the page through
//! its parts, `Placement::pick` and `Placement::open_scene`, since they keep their placement for
//! later scenes), so that none of them drops a part of the request (`--gpu-variant`, `auto`'s
//! note). The query meshes and scenes place their work here too, their device opened on first
//! need (`QueryPlacement`), so that `auto`'s rules are written once.
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

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use crate::accel::{AccelChoice, AccelKind, AccelParams, AccelSpec, TracedOn, Work};
use crate::backend::{Backend, Tracer, traced_on};
use crate::gpu::{GpuContext, GpuRenderer, GpuVariants};
use crate::scene::{PreparedScene, Scene};
use crate::util::Instant;
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
        let kind = scene.accel.structure_id();
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
        AccelChoice::Kind(named) if named.structure() == accel.structure() => spec.params.clone(),
        _ => AccelParams::NONE,
    };
    scene.prepare_for(accel, &params)
}

/// Where a query mesh or scene places its work, its device opened on first need: a program
/// whose queries run on the CPU never opens one, and `auto` opens one only where the machine
/// has a hardware adapter (`hardware_adapter_present`, probed once a process), so that a
/// software adapter is passed over before anything is compiled for it, as `Placement::open`
/// passes it over. A query may ask another backend than its mesh's (`intersect_with`): the
/// device is opened once, for whichever asked first, and shared; a scene's merged meshes and
/// its two levels share their scene's.
pub(crate) struct QueryPlacement {
    backend: Backend,
    variants: GpuVariants,
    /// The device, opened by the first query that went to a GPU (or given), or why it could
    /// not be opened.
    device: OnceLock<std::result::Result<Arc<GpuContext>, String>>,
    /// A device was given (`given`, `give`): `auto` traces on it even where it is a software
    /// adapter (how the fault tests use lavapipe), as `Tracer::open` does on a placement made
    /// with one.
    given: AtomicBool,
}

impl QueryPlacement {
    pub fn new(backend: Backend, variants: GpuVariants) -> QueryPlacement {
        QueryPlacement {
            backend,
            variants,
            device: OnceLock::new(),
            given: AtomicBool::new(false),
        }
    }

    /// Work placed on `ctx`'s device (`give`).
    pub fn given(backend: Backend, variants: GpuVariants, ctx: Arc<GpuContext>) -> QueryPlacement {
        let p = QueryPlacement::new(backend, variants);
        p.give(ctx).expect("a new placement has no device yet");
        p
    }

    /// Places the work on `ctx`'s device; an error where a device was opened or given already.
    pub fn give(&self, ctx: Arc<GpuContext>) -> Result<()> {
        self.device
            .set(Ok(ctx))
            .map_err(|_| Error::InvalidInput("this mesh has opened its GPU already".into()))?;
        self.given.store(true, Ordering::Relaxed);
        Ok(())
    }

    /// Whether a device was given (`give`).
    pub fn is_given(&self) -> bool {
        self.given.load(Ordering::Relaxed)
    }

    /// The backend the work asked for unless a query says otherwise.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// Where `auto` weighs the work before any device is open (`Backend::traced_on`).
    pub fn traced_on(&self) -> TracedOn {
        self.backend.traced_on()
    }

    /// Whether work asked on `backend` goes to a GPU, without opening one: `gpu` always, `cpu`
    /// never, `auto` where the machine has a hardware adapter or a device was given.
    pub fn traces_on_gpu(&self, backend: Backend) -> bool {
        match backend {
            Backend::Auto => self.is_given() || backend.traces_on_gpu(),
            b => b.traces_on_gpu(),
        }
    }

    /// Where work asked on `backend` runs: on the device (opened now by the first to need it,
    /// by `Backend::open_device`'s rules), or on the CPU where it does not go to a GPU
    /// (`traces_on_gpu`). `gpu` without a device is an error; `auto` without one goes to the
    /// CPU, the reason in `notes`.
    pub fn placement(&self, backend: Backend, notes: &mut Vec<String>) -> Result<Placement> {
        let mut placement = Placement {
            backend,
            device: None,
            variants: self.variants,
        };
        if !self.traces_on_gpu(backend) {
            return Ok(placement);
        }
        let device = self.device.get_or_init(|| match backend.open_device() {
            Ok((Some(ctx), _)) => Ok(ctx),
            Ok((None, why)) => Err(why.join("; ")),
            Err(e) => Err(e.to_string()),
        });
        match (device, backend) {
            (Ok(ctx), _) => placement.device = Some(ctx.clone()),
            (Err(e), Backend::Gpu) => return Err(Error::Gpu(e.clone())),
            (Err(e), _) => notes.push(e.clone()),
        }
        Ok(placement)
    }
}

/// A tracer opened on a placement: here, beside `Placement`, so that `backend.rs` (the
/// backends and the tracer) needs nothing of this file.
impl Tracer {
    /// The scene traced where `placement` says: on its device, or the CPU without one. With
    /// `auto` a scene the device cannot hold (over its buffer limits, or a structure without a
    /// GPU walk) goes to the CPU, with a note (`Placement::upload`).
    pub fn open(scene: PreparedScene, placement: &Placement, notes: &mut Vec<String>) -> Result<Tracer> {
        let gpu = placement.upload(&scene, notes)?;
        let backend = placement.backend;
        if gpu.is_none() {
            // A structure only a GPU traces (`hwrt`) is refused here, before any frame.
            scene.accel.check_cpu_kind().map_err(|e| match backend {
                Backend::Auto => Error::InvalidInput(format!(
                    "{e} (backend auto found no hardware GPU to trace it: {})",
                    notes.join("; ")
                )),
                _ => e,
            })?;
        }
        Ok(Tracer::from_parts(scene, gpu, backend))
    }

    /// Opens the device `backend` asks for and the scene on it, with the default GPU
    /// variants: `Placement::open`, then `open`.
    pub fn open_with(backend: Backend, scene: PreparedScene) -> Result<(Tracer, Vec<String>)> {
        let (placement, mut notes) = Placement::open(backend, GpuVariants::default())?;
        let tracer = Tracer::open(scene, &placement, &mut notes)?;
        Ok((tracer, notes))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Queries on the CPU open no device, nor does `auto` on a machine without a hardware
    /// adapter; a device given is where `auto` and `gpu` trace, even a software one.
    #[test]
    fn queries_open_a_device_only_where_they_trace_on_one() {
        let mut notes = Vec::new();
        let cpu = QueryPlacement::new(Backend::Cpu, GpuVariants::default());
        assert!(cpu.placement(Backend::Cpu, &mut notes).unwrap().device.is_none());
        assert!(cpu.device.get().is_none(), "the CPU opened a device");
        let auto = QueryPlacement::new(Backend::Auto, GpuVariants::default());
        if !crate::backend::hardware_adapter_present() {
            assert!(auto.placement(Backend::Auto, &mut notes).unwrap().device.is_none());
            assert!(auto.device.get().is_none(), "auto opened a software adapter");
        }
        assert!(notes.is_empty(), "{notes:?}");
        let Ok(ctx) = GpuContext::new() else {
            return;
        };
        let ctx = Arc::new(ctx);
        let given = QueryPlacement::given(Backend::Auto, GpuVariants::default(), ctx.clone());
        for backend in [Backend::Auto, Backend::Gpu] {
            let device = given.placement(backend, &mut notes).unwrap().device;
            assert!(device.is_some_and(|d| Arc::ptr_eq(&d, &ctx)), "{backend:?}");
        }
        assert!(given.placement(Backend::Cpu, &mut notes).unwrap().device.is_none());
        assert!(given.give(ctx).is_err(), "a second device given");
    }
}
