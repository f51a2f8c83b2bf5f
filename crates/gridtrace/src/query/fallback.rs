//! Where a query runs, and what happens when the GPU fails under it: the rule the renderer's
//! `Tracer` follows, for the query meshes (`rays`, Python's `Mesh` and `Scene`). Under `auto`
//! a GPU fault (a lost device, memory gone) hands the mesh to the CPU for good, the query that
//! met it is answered there, and `gpu_failure` says what happened; under `gpu` the fault is the
//! caller's error.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};

use super::{Backend, TraceMesh};
use crate::gpu::{GpuContext, GpuRenderer};
use crate::{Error, Result};

impl TraceMesh {
    /// Answers on the GPU renderer `backend` gives (`on_gpu`), else on the CPU (`on_cpu`),
    /// which also answers, under `auto`, a query whose GPU work failed.
    pub(super) fn on_backend<T>(
        &self,
        backend: Backend,
        on_gpu: impl FnOnce(&Mutex<GpuRenderer>) -> Result<T>,
        on_cpu: impl FnOnce() -> Result<T>,
    ) -> Result<T> {
        let Some(gpu) = self.renderer(backend)? else {
            return on_cpu();
        };
        match on_gpu(gpu) {
            Err(Error::Gpu(e)) if backend == Backend::Auto => {
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
                on_cpu()
            }
            r => r,
        }
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
        let d = format!("gpu: {}", ctx.describe());
        let r = GpuRenderer::new(ctx, &self.scene, &self.gpu_variants)?;
        self.gpu
            .set(Ok((Mutex::new(r), d)))
            .map_err(|_| Error::InvalidInput("this mesh has opened its GPU already".into()))?;
        self.auto_on_adopted.store(true, Ordering::Relaxed);
        Ok(())
    }
}
