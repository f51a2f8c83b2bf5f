//! What the last query did (`QueryScene::last_query`): its name, the device that answered and,
//! for GPU work, the batch's statistics (bytes each way, submissions, wall and GPU time). Each
//! public query opens a `Recording`; the GPU paths say when they answered (`answered_on_gpu`),
//! and the outermost recording, when it ends, keeps the record (a query that calls another,
//! `count_intersections_with` calling `count_intersections`, is recorded once, by its own name).

use crate::gpu::GpuQueryStats;

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

/// The record being made: the open recordings' depth, what the GPU answered so far, and the
/// last finished record.
#[derive(Debug, Default)]
pub(super) struct Records {
    depth: u32,
    gpu: Option<GpuQueryStats>,
    last: LastQuery,
}

/// An open query; its end (drop) keeps the record if it is the outermost.
pub(super) struct Recording<'a> {
    scene: &'a QueryScene,
    name: &'static str,
}

impl QueryScene {
    /// Opens the record of query `name` (kept when the returned recording ends).
    pub(super) fn recording(&self, name: &'static str) -> Recording<'_> {
        let mut r = self.records.lock().unwrap_or_else(|p| p.into_inner());
        if r.depth == 0 {
            r.gpu = None;
        }
        r.depth += 1;
        Recording { scene: self, name }
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
        r.depth = r.depth.saturating_sub(1);
        if r.depth == 0 {
            let gpu = r.gpu.take();
            r.last = LastQuery {
                name: self.name,
                device: if gpu.is_some() { "gpu" } else { "cpu" },
                gpu,
            };
        }
    }
}
