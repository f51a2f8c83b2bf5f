//! A sensor's scan on the scene's GPU (`sensor::scan` with a backend that traces on a GPU): the
//! rays made on the device (`GpuRenderer::scan`: the sensor's table once, its poses each scan)
//! on whichever GPU path `cast_rays` takes, the GPU's two levels or the merged mesh's renderer,
//! and the hits named as `cast_rays` names them. For a range alone only `t` comes down (4
//! bytes a ray); ids and normals need the hits (16).

use super::batch::{NameHit, RayHits, RayOptions, write_gpu_hits};
use super::{QueryScene, RayPath};
use crate::Result;
use crate::gpu::{Answer, ChunkAnswers, GpuRenderer, ScanRays};

/// Writes a chunk's answers (from ray `first`) into `out`, naming each hit with `name` (`t`
/// alone for `Answer::Range`, ids and normals left as `RayHits::misses` made them).
pub(super) fn take_scan_answers(out: &mut RayHits, first: usize, answers: ChunkAnswers<'_>, name: &NameHit) {
    match answers {
        ChunkAnswers::Range(ts) => out.t_hit[first..first + ts.len()].copy_from_slice(ts),
        ChunkAnswers::HitsUv(hits) => write_gpu_hits(out, first, hits, |_| true, name),
        _ => {}
    }
}

/// `GpuRenderer::scan` of `s` for a range alone or the hits, with the interval `cast_rays`
/// takes by default.
pub(super) fn scan_with(
    gpu: &mut GpuRenderer,
    s: &ScanRays,
    range_only: bool,
    take: impl FnMut(usize, ChunkAnswers<'_>),
) -> Result<()> {
    let answer = if range_only {
        Answer::Range
    } else {
        Answer::Hits { uv: true }
    };
    gpu.scan(s, (0.0, f32::INFINITY), answer, take)
}

impl QueryScene {
    /// Whether the scene's queries trace on a GPU: its placement's choice
    /// (`QueryPlacement::traces_on_gpu`: `auto` may still fall back to the CPU, or trace on a
    /// device a test gave it); not once a GPU fault sent `auto` to the CPU.
    pub(crate) fn traces_on_gpu(&self) -> bool {
        self.placement.traces_on_gpu(self.opts.backend) && !self.failed_over()
    }

    /// What the last ray batch on this scene's GPU took (wall and GPU time, submissions, bytes
    /// each way), on the path its rays take (`ray_path`); `None` where they are traced on the
    /// CPU, or before the first.
    pub fn last_gpu_batch(&self) -> Result<Option<crate::gpu::GpuQueryStats>> {
        if !self.traces_on_gpu() {
            return Ok(None);
        }
        Ok(match self.ray_path(&RayOptions::default())? {
            RayPath::Cpu(_) => None,
            RayPath::Gpu(_) => self.two_level_batch_stats(),
            RayPath::Merged => self.merged()?.mesh.as_ref().and_then(|m| m.last_gpu_batch()),
        })
    }

    /// The closest hits of a scan's rays (`cast_rays`' default interval), traced on the GPU with
    /// the rays made there; with `range_only` only `t` is answered (ids `INVALID_ID`, normals
    /// zero). `None` where this scene's rays are not traced on a GPU: the caller makes the rays
    /// and casts them.
    pub(crate) fn scan_on_gpu(&self, s: &ScanRays, range_only: bool) -> Result<Option<RayHits>> {
        if !self.traces_on_gpu() {
            return Ok(None);
        }
        let n = s.len();
        match self.ray_path(&RayOptions::default())? {
            RayPath::Cpu(_) => Ok(None),
            RayPath::Gpu(two) => self.gpu_or_cpu(|| self.gpu_scan(&two, s, range_only).map(Some), || Ok(None)),
            RayPath::Merged => {
                let m = self.merged()?;
                let Some(mesh) = m.mesh.as_ref() else {
                    return Ok(Some(RayHits::misses(n)));
                };
                self.on_mesh(
                    mesh,
                    |gpu| {
                        let mut out = RayHits::misses(n);
                        scan_with(gpu, s, range_only, |first, answers| {
                            take_scan_answers(&mut out, first, answers, &|h, t, g, p, uv, nrm| {
                                super::rays::write_hit(&m, h, t, g, p, uv, nrm)
                            })
                        })?;
                        Ok(Some(out))
                    },
                    || Ok(None),
                )
            }
        }
    }
}
