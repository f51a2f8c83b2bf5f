//! Where a query runs, and what happens when the GPU fails under it: the rule the renderer's
//! `Tracer` follows, for the query meshes (`rays`, Python's `Mesh` and `Scene`). Under `auto`
//! a GPU fault (a lost device, memory gone) hands the mesh to the CPU for good, the query that
//! met it is answered there, and `gpu_failure` says what happened; under `gpu` the fault is the
//! caller's error. A device limit one query meets (`Error::Limit`: a ray with more hits than
//! a list pass holds) is no fault: under `auto` the CPU answers that query, its record notes
//! the limit, and the next query goes to the GPU again; under `gpu` the limit is the caller's
//! error. Every query goes through `on_backend`, which also keeps its record (`last_query`:
//! the scene's `LastQuery`).

use std::sync::{Arc, Mutex};

use super::{Backend, TraceMesh, locked};
use crate::gpu::{GpuContext, GpuQueryStats, GpuRenderer};
use crate::query_scene::LastQuery;
use crate::{Error, Result};

/// Where a query was answered (`TraceMesh::route`).
pub(crate) enum Answered {
    /// On the GPU, with the batch's statistics.
    Gpu(GpuQueryStats),
    /// On the CPU; `fault` is the GPU's error where the GPU failed under `auto` and the CPU
    /// took the query over (this query only: later ones go to the CPU without one).
    Cpu { fault: Option<String> },
    /// On the CPU, this query alone, because under `auto` its GPU work met a device limit:
    /// the note that says so (`limit_note`).
    OverLimit(String),
}

/// The note of a query that met a device limit under `auto` (`error`, an `Error::Limit`,
/// names the limit) and was answered on the CPU.
pub(crate) fn limit_note(error: &Error) -> String {
    format!("this query was answered on the CPU ({error}); the next query goes to the GPU again")
}

impl TraceMesh {
    /// Answers query `name` on the GPU renderer `backend` gives (`on_gpu`), else on the CPU
    /// (`on_cpu`), which also answers, under `auto`, a query whose GPU work failed; and keeps
    /// the record of an answered query (`last_query`). Every query of the mesh goes through
    /// here.
    pub(super) fn on_backend<T>(
        &self,
        name: &'static str,
        backend: Backend,
        on_gpu: impl FnOnce(&mut GpuRenderer) -> Result<T>,
        on_cpu: impl FnOnce() -> Result<T>,
    ) -> Result<T> {
        let (answer, answered) = self.route(backend, on_gpu, on_cpu)?;
        let record = match answered {
            Answered::Gpu(stats) => LastQuery {
                name,
                device: "gpu",
                gpu: Some(stats),
                note: None,
            },
            Answered::Cpu { fault } => LastQuery {
                name,
                device: "cpu",
                gpu: None,
                note: fault.and_then(|_| self.gpu_failure()),
            },
            Answered::OverLimit(note) => LastQuery {
                name,
                device: "cpu",
                gpu: None,
                note: Some(note),
            },
        };
        *self.last.lock().unwrap_or_else(|p| p.into_inner()) = record;
        Ok(answer)
    }

    /// `on_backend` without the record, saying where the answer came from: the renderer is
    /// held from the GPU's work to the reading of its statistics, so they are this query's.
    pub(super) fn route<T>(
        &self,
        backend: Backend,
        on_gpu: impl FnOnce(&mut GpuRenderer) -> Result<T>,
        on_cpu: impl FnOnce() -> Result<T>,
    ) -> Result<(T, Answered)> {
        let Some(gpu) = self.renderer(backend)? else {
            return Ok((on_cpu()?, Answered::Cpu { fault: None }));
        };
        let mut g = locked(gpu);
        match on_gpu(&mut g) {
            Ok(answer) => Ok((answer, Answered::Gpu(g.last_query_stats().clone()))),
            Err(limit @ Error::Limit { .. }) if backend == Backend::Auto => {
                drop(g);
                // As for a fault below: without the CPU's structure the limit is the caller's.
                if self.scene.accel.check_current().is_err() {
                    return Err(limit);
                }
                Ok((on_cpu()?, Answered::OverLimit(limit_note(&limit))))
            }
            Err(Error::Gpu(e)) if backend == Backend::Auto => {
                drop(g);
                // A grid the GPU rebuilt after `update_vertices` is not the CPU's to trace:
                // then the fault stays the caller's.
                if self.scene.accel.check_current().is_err() {
                    return Err(Error::Gpu(format!(
                        "{e} (and the CPU cannot take over: the mesh's grid was last built on the GPU)"
                    )));
                }
                *self.gpu_failed.lock().unwrap_or_else(|p| p.into_inner()) = Some(format!(
                    "the GPU failed ({e}); this mesh's queries run on the CPU from now on"
                ));
                Ok((on_cpu()?, Answered::Cpu { fault: Some(e) }))
            }
            Err(e) => Err(e),
        }
    }

    /// What the last answered query did: its name (`intersect`, `occluded`,
    /// `closest_points`), the device, the GPU batch's statistics, and on the query that met
    /// a GPU fault or a device limit under `auto` the note that the CPU answered
    /// (`LastQuery`); the default before the first. A query that failed leaves the previous
    /// record.
    pub fn last_query(&self) -> LastQuery {
        self.last.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Why this mesh's `auto` queries moved to the CPU, once a GPU fault sent them there.
    pub fn gpu_failure(&self) -> Option<String> {
        self.gpu_failed.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Whether a GPU fault sent this mesh's `auto` queries to the CPU.
    pub(super) fn failed_over(&self) -> bool {
        self.gpu_failed.lock().unwrap_or_else(|p| p.into_inner()).is_some()
    }

    /// Traces this mesh's `auto` queries on `ctx`'s device, as on a hardware adapter, even
    /// where `auto` passes a software adapter over: how the fault tests use lavapipe (as
    /// `Tracer::open` with a device given). An error if the mesh has opened its GPU already.
    #[doc(hidden)]
    pub fn adopt_device_for_auto(&self, ctx: Arc<GpuContext>) -> Result<()> {
        self.placement.give(ctx)?;
        self.upload_given()
    }

    /// The renderer on the device given to the mesh's placement, made now: an error here (a
    /// device that fails) is the caller's, under `auto` too.
    pub(super) fn upload_given(&self) -> Result<()> {
        let mut notes = Vec::new();
        let placement = self.placement.placement(Backend::Gpu, &mut notes)?;
        let r = placement
            .upload(&self.scene, &mut notes)?
            .ok_or_else(|| Error::Gpu(notes.join("; ")))?;
        let d = format!("gpu: {}", r.context().describe());
        self.gpu
            .set(Ok((Mutex::new(r), d)))
            .map_err(|_| Error::InvalidInput("this mesh has opened its GPU already".into()))
    }
}
