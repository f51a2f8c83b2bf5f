//! What the last query did (`QueryScene::last_query`): its name, the device that answered and,
//! for GPU work, the batch's statistics (bytes each way, submissions, wall and GPU time). Each
//! public query opens a `Recording` (the `_with` form where there are two: the plain one calls
//! it); the GPU paths say when they answered (`on_mesh`, `on_gpu_two_level`), and the
//! recording, when it ends, keeps the record.

use crate::Result;
use crate::gpu::{GpuQueryStats, GpuRenderer};
use crate::query::TraceMesh;

use super::QueryScene;

/// The last query of a scene.
#[derive(Debug, Clone, Default)]
pub struct LastQuery {
    /// The query's name as the Python package calls it (`count_intersections`,
    /// `compute_winding_number`, ...); empty before the first.
    pub name: &'static str,
    /// `"gpu"` or `"cpu"`: where it was answered (under `auto`, the CPU after a GPU fault).
    pub device: &'static str,
    /// The GPU batch's statistics where the GPU answered (the last batch of the query).
    pub gpu: Option<GpuQueryStats>,
}

/// The record being made: what the GPU answered so far, and the last finished record.
#[derive(Debug, Default)]
pub(super) struct Records {
    gpu: Option<GpuQueryStats>,
    last: LastQuery,
}

/// An open query; its end (drop) keeps the record.
pub(super) struct Recording<'a> {
    scene: &'a QueryScene,
    name: &'static str,
}

impl QueryScene {
    /// Opens the record of query `name` (kept when the returned recording ends).
    pub(super) fn recording(&self, name: &'static str) -> Recording<'_> {
        self.records.lock().unwrap_or_else(|p| p.into_inner()).gpu = None;
        Recording { scene: self, name }
    }

    /// `mesh.on_gpu_or_cpu` (the merged mesh decides where, by the scene's backend), the GPU's
    /// answer marked as the open query's (`answered_on_gpu`): every query of the merged mesh
    /// goes through here, as every query of the GPU's two levels goes through
    /// `on_gpu_two_level`.
    pub(super) fn on_mesh<T>(
        &self,
        mesh: &TraceMesh,
        on_gpu: impl FnOnce(&mut GpuRenderer) -> Result<T>,
        on_cpu: impl FnOnce() -> Result<T>,
    ) -> Result<T> {
        mesh.on_gpu_or_cpu(
            |gpu| {
                let answer = on_gpu(gpu)?;
                self.answered_on_gpu(gpu.last_query_stats());
                Ok(answer)
            },
            on_cpu,
        )
    }

    /// The GPU answered (part of) the open query with `stats`.
    pub(super) fn answered_on_gpu(&self, stats: &GpuQueryStats) {
        let mut r = self.records.lock().unwrap_or_else(|p| p.into_inner());
        r.gpu = Some(stats.clone());
    }

    /// What the last query did (`LastQuery`); the default before the first.
    pub fn last_query(&self) -> LastQuery {
        self.records.lock().unwrap_or_else(|p| p.into_inner()).last.clone()
    }
}

impl Drop for Recording<'_> {
    fn drop(&mut self) {
        let mut r = self.scene.records.lock().unwrap_or_else(|p| p.into_inner());
        let gpu = r.gpu.take();
        r.last = LastQuery {
            name: self.name,
            device: if gpu.is_some() { "gpu" } else { "cpu" },
            gpu,
        };
    }
}
