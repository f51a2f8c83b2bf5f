//! What the last query did (`QueryScene::last_query`, `TraceMesh::last_query`): its name, the
//! device that answered, for GPU work the batch's statistics (bytes each way, submissions,
//! wall and GPU time), and the note of a GPU fault the CPU took over from. Each public query
//! of a scene opens a `Recording` (the `_with` form where there are two: the plain one calls
//! it); the GPU paths say when they answered (`on_mesh`, `on_gpu_two_level`), and the
//! recording, when it ends, keeps the record. A `TraceMesh` records in `on_backend`, the one
//! place its queries choose a device (`query/fallback.rs`).
//!
//! A scene's fault rule (the mesh's is `query/fallback.rs`'s): under `auto` the first GPU
//! fault (a lost device, memory gone) hands the scene to the CPU for good, the query that met
//! it is answered there and its record carries the note; later queries run on the CPU
//! without one (`gpu_failure` keeps the reason). Under `gpu` the fault is the caller's error.
//! A device limit (`Error::Limit`: a ray with more hits than a list pass holds) is no fault:
//! under `auto` the CPU answers the query that met it, its record's note names the limit, and
//! the next query goes to the GPU again; under `gpu` the limit is the caller's error.

use std::sync::Arc;

use crate::gpu::{GpuContext, GpuQueryStats, GpuRenderer};
use crate::placement::QueryPlacement;
use crate::query::{Answered, Backend, TraceMesh, limit_note};
use crate::{Error, Result};

use super::QueryScene;

/// The last query of a scene or a mesh.
#[derive(Debug, Clone, Default)]
pub struct LastQuery {
    /// The query's name as the Python package calls it (`count_intersections`,
    /// `compute_winding_number`, `intersect`, ...); empty before the first.
    pub name: &'static str,
    /// `"gpu"` or `"cpu"`: where it was answered (under `auto`, the CPU after a GPU fault, or
    /// for a query that met a device limit).
    pub device: &'static str,
    /// The GPU batch's statistics where the GPU answered (the last batch of the query).
    pub gpu: Option<GpuQueryStats>,
    /// Set on the query that met a GPU fault under `auto` and was answered on the CPU: what
    /// failed, and that the CPU answers from now on. `None` on every other query, the later
    /// ones on the CPU included (the reason stays in `gpu_failure`). Set too on a query that
    /// met a device limit under `auto` (`Error::Limit`), naming the limit: the CPU answered
    /// that query alone.
    pub note: Option<String>,
}

/// The record being made: what the GPU answered so far, a fault's note, and the last finished
/// record; and the scene's GPU failure, once there is one.
#[derive(Debug, Default)]
pub(super) struct Records {
    gpu: Option<GpuQueryStats>,
    note: Option<String>,
    last: LastQuery,
    /// Why this scene's `auto` queries left the GPU for good.
    failed: Option<String>,
}

/// An open query; its end (drop) keeps the record.
pub(super) struct Recording<'a> {
    scene: &'a QueryScene,
    name: &'static str,
}

impl QueryScene {
    fn records(&self) -> std::sync::MutexGuard<'_, Records> {
        self.records.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Opens the record of query `name` (kept when the returned recording ends).
    pub(super) fn recording(&self, name: &'static str) -> Recording<'_> {
        let mut r = self.records();
        r.gpu = None;
        r.note = None;
        Recording { scene: self, name }
    }

    /// `mesh`'s GPU or CPU (the merged mesh decides where, by the scene's backend), the GPU's
    /// answer marked as the open query's (`answered_on_gpu`) and a fault the CPU took over
    /// made the scene's (`gpu_fault`): every query of the merged mesh goes through here, as
    /// every query of the GPU's two levels goes through `on_gpu_two_level`. A scene whose GPU
    /// failed answers on the CPU at once.
    pub(super) fn on_mesh<T>(
        &self,
        mesh: &TraceMesh,
        on_gpu: impl FnOnce(&mut GpuRenderer) -> Result<T>,
        on_cpu: impl FnOnce() -> Result<T>,
    ) -> Result<T> {
        if self.failed_over() {
            return on_cpu();
        }
        let (answer, answered) = mesh.on_gpu_or_cpu(on_gpu, on_cpu)?;
        match answered {
            Answered::Gpu(stats) => self.answered_on_gpu(&stats),
            Answered::Cpu { fault: Some(why) } => self.gpu_fault(&why),
            Answered::Cpu { fault: None } => {}
            Answered::OverLimit(note) => self.over_limit(note),
        }
        Ok(answer)
    }

    /// The query `on_gpu` on the GPU's two levels; under `auto`, a GPU that fails hands the
    /// scene to the CPU (`gpu_fault`) and the query to `on_cpu`, and a device limit the query
    /// meets hands this query alone to `on_cpu` (`over_limit`), as the merged mesh's queries
    /// do (`on_mesh`).
    pub(super) fn gpu_or_cpu<T>(
        &self,
        on_gpu: impl FnOnce() -> Result<T>,
        on_cpu: impl FnOnce() -> Result<T>,
    ) -> Result<T> {
        match on_gpu() {
            Err(limit @ Error::Limit { .. }) if self.opts.backend == Backend::Auto => {
                self.over_limit(limit_note(&limit));
                on_cpu()
            }
            Err(Error::Gpu(e)) if self.opts.backend == Backend::Auto => {
                self.gpu_fault(&e);
                on_cpu()
            }
            r => r,
        }
    }

    /// The open query met a device limit under `auto` and is answered on the CPU: its record
    /// says so with `note` (which names the limit); the scene stays on the GPU.
    fn over_limit(&self, note: String) {
        self.records().note.get_or_insert(note);
    }

    /// The GPU failed under `auto` with `why` (the error's words): the scene's queries run on
    /// the CPU from now on, and the open query's record says so (the first fault only: a
    /// scene already on the CPU meets no other).
    pub(super) fn gpu_fault(&self, why: &str) {
        let mut r = self.records();
        if r.failed.is_none() {
            r.failed = Some(why.to_string());
            r.note = Some(format!(
                "the GPU failed ({why}); this scene's queries run on the CPU from now on"
            ));
        }
    }

    /// Why this scene's `auto` queries moved to the CPU, once a GPU fault sent them there.
    pub fn gpu_failure(&self) -> Option<String> {
        self.records().failed.clone()
    }

    /// Whether a GPU fault sent this scene's `auto` queries to the CPU.
    pub(super) fn failed_over(&self) -> bool {
        self.opts.backend == Backend::Auto && self.records().failed.is_some()
    }

    /// The GPU answered (part of) the open query with `stats`.
    pub(super) fn answered_on_gpu(&self, stats: &GpuQueryStats) {
        self.records().gpu = Some(stats.clone());
    }

    /// What the last query did (`LastQuery`); the default before the first.
    pub fn last_query(&self) -> LastQuery {
        self.records().last.clone()
    }

    /// Traces this scene's GPU work on `ctx`'s device: under `gpu` instead of a device it
    /// opens, under `auto` as on a hardware adapter even where `auto` passes a software
    /// adapter over. How the fault tests put a scene on lavapipe and inject faults into its
    /// device (as `TraceMesh::adopt_device_for_auto`). Both GPU paths use it: the two levels'
    /// renderer and the merged mesh's (made on it when the mesh is built).
    #[doc(hidden)]
    pub fn adopt_device(&mut self, ctx: Arc<GpuContext>) {
        self.placement = Arc::new(QueryPlacement::given(self.opts.backend, self.opts.gpu_variants, ctx));
        // A merged mesh built before traces where it was told to: build it again.
        *self.merged.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
    }
}

impl Drop for Recording<'_> {
    fn drop(&mut self) {
        let mut r = self.scene.records();
        let gpu = r.gpu.take();
        // A query the GPU answered in part before a fault (a signed distance's closest points,
        // then its winding numbers) was finished on the CPU: it is the CPU's.
        let note = r.note.take();
        let gpu = if note.is_some() { None } else { gpu };
        r.last = LastQuery {
            name: self.name,
            device: if gpu.is_some() { "gpu" } else { "cpu" },
            gpu,
            note,
        };
    }
}
