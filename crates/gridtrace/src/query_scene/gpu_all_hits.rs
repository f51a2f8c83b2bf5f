//! Counts and lists of every hit on the GPU (`gpu::AllHits`), where the scene's rays are traced
//! there: on the merged mesh's renderer, or on the two levels' (`gpu_rays.rs`). The answers are
//! the CPU's (`all_hits.rs`: Open3D's rule, nearest first, equal `t` by geometry then face):
//! the device applies the rule with each geometry's first triangle in its numbering, which is
//! the merged mesh's kept faces (geometries in ascending id) or the two levels' instance
//! records (`TopLevel::first_answer`). A ray that cannot hit anything goes up as a stand-in
//! (`STAND_IN`) and its answer is dropped here.

use super::all_hits::Intersections;
use super::batch::{RayOptions, ray_of};
use super::merged::Merged;
use super::rays::RowRays;
use super::{QueryScene, RayPath};
use crate::Result;
use crate::gpu::AllHits;
use crate::gpu::layout::GpuHit;

/// What the device answered, gathered from its runs of rays (`GpuRenderer::all_hits`): each
/// ray's count, and for lists the runs as `Intersections::join` takes them (`GpuHit`s in the
/// device's numbering), a bad ray's (a stand-in's) hits dropped.
pub(super) struct DeviceHits<'a> {
    rows: &'a [[f32; 6]],
    answer: AllHits,
    counts: Vec<u32>,
    parts: Vec<(usize, Vec<u32>, Vec<GpuHit>)>,
}

impl<'a> DeviceHits<'a> {
    pub fn new(rows: &'a [[f32; 6]], answer: AllHits) -> DeviceHits<'a> {
        DeviceHits {
            rows,
            answer,
            counts: vec![0; rows.len()],
            parts: Vec::new(),
        }
    }

    /// Takes a run of rays from `first` on: their counts and, for lists, their hits.
    pub fn take(&mut self, first: usize, counts: &[u32], hits: &[GpuHit]) {
        let mut kept_counts = Vec::with_capacity(counts.len());
        let mut kept = Vec::with_capacity(hits.len());
        let mut at = 0;
        for (k, &c) in counts.iter().enumerate() {
            let valid = ray_of(&self.rows[first + k]).is_some();
            let c_kept = if valid { c } else { 0 };
            self.counts[first + k] = c_kept;
            if self.answer == AllHits::Lists {
                if valid {
                    kept.extend_from_slice(&hits[at..at + c as usize]);
                }
                at += c as usize;
                kept_counts.push(c_kept);
            }
        }
        if self.answer == AllHits::Lists {
            self.parts.push((first, kept_counts, kept));
        }
    }

    /// The answer, each listed hit named by `name` (geometry id, face, uv, t). Each ray's
    /// hits in the CPU's order (`t`, then geometry id, then face): the device's ties at one
    /// `t` come in its numbering, which on the two levels is the instance records' order.
    pub fn answer(mut self, name: impl Fn(&GpuHit) -> (u32, u32, [f32; 2], f32)) -> DeviceAnswer {
        match self.answer {
            AllHits::Counts => DeviceAnswer::Counts(self.counts),
            AllHits::Lists => {
                for (_, counts, hits) in &mut self.parts {
                    let mut at = 0;
                    for &c in counts.iter() {
                        let one = &mut hits[at..at + c as usize];
                        if one.len() > 1 {
                            one.sort_by(|a, b| {
                                let (a, b) = (name(a), name(b));
                                a.3.total_cmp(&b.3).then(a.0.cmp(&b.0)).then(a.1.cmp(&b.1))
                            });
                        }
                        at += c as usize;
                    }
                }
                DeviceAnswer::Lists(Intersections::join(self.rows.len(), self.parts, name))
            }
        }
    }
}

/// Counts or lists, as asked.
pub(super) enum DeviceAnswer {
    Counts(Vec<u32>),
    Lists(Intersections),
}

impl Merged {
    /// Each geometry's first kept face (the GPU's numbering of the merged mesh), ascending:
    /// a kept face belongs to the last geometry whose first is at or before it.
    fn kept_firsts(&self) -> Vec<u32> {
        let Some(mesh) = self.mesh.as_ref() else {
            return Vec::new();
        };
        let kept = mesh.triangle_count() as u32;
        self.spans
            .iter()
            .map(|s| {
                // Kept faces keep the merged order: the first whose merged face is in the span.
                let (mut lo, mut hi) = (0u32, kept);
                while lo < hi {
                    let mid = lo + (hi - lo) / 2;
                    if mesh.original_index(mid) < s.first_face {
                        lo = mid + 1;
                    } else {
                        hi = mid;
                    }
                }
                lo
            })
            .collect()
    }
}

impl QueryScene {
    /// Counts (or lists) of every hit of `rays` with `o` on the GPU, where this scene traces
    /// its rays there; `None` where they are traced on the CPU (the caller's path runs).
    fn all_hits_on_gpu(&self, rays: &[[f32; 6]], o: &RayOptions, answer: AllHits) -> Result<Option<DeviceAnswer>> {
        if !self.traces_on_gpu() {
            return Ok(None);
        }
        let path = match self.ray_path(o)? {
            // The driver's instances (`hwrt`) find closest and any hits only; counts and lists
            // take the merged mesh on the GPU, as before the driver's instances (its BVH's
            // all-hits walk), where it answers these rays, else the CPU's two levels.
            RayPath::Gpu(two) if self.gpu_walks_by_ray_query(&two) => match self.merged_answers(o) {
                true => RayPath::Merged,
                false => return Ok(None),
            },
            path => path,
        };
        match path {
            RayPath::Cpu(_) => Ok(None),
            RayPath::Gpu(two) => self.gpu_or_cpu(|| self.gpu_all_hits(&two, rays, o, answer).map(Some), || Ok(None)),
            RayPath::Merged => {
                let (t_near, t_far, _) = o.uniform().expect("the merged path's rays share one interval");
                let m = self.merged()?;
                let Some(mesh) = m.mesh.as_ref() else {
                    return Ok(Some(DeviceHits::new(rays, answer).answer(|_| unreachable!("no hits"))));
                };
                let firsts = m.kept_firsts();
                self.on_mesh(
                    mesh,
                    |gpu| {
                        let mut out = DeviceHits::new(rays, answer);
                        gpu.all_hits(
                            &RowRays { rows: rays },
                            (t_near, t_far),
                            u32::MAX,
                            &firsts,
                            answer,
                            |first, counts, hits| out.take(first, counts, hits),
                        )?;
                        Ok(Some(out.answer(|h| {
                            let (id, prim) = m.name(h.tri);
                            (id, prim, [h.u, h.v], h.t)
                        })))
                    },
                    || Ok(None),
                )
            }
        }
    }

    /// `count_intersections_with` on the GPU, where the scene traces there.
    pub(super) fn count_on_gpu(&self, rays: &[[f32; 6]], o: &RayOptions) -> Result<Option<Vec<u32>>> {
        Ok(match self.all_hits_on_gpu(rays, o, AllHits::Counts)? {
            Some(DeviceAnswer::Counts(c)) => Some(c),
            _ => None,
        })
    }

    /// `list_intersections_with` on the GPU, where the scene traces there.
    pub(super) fn list_on_gpu(&self, rays: &[[f32; 6]], o: &RayOptions) -> Result<Option<Intersections>> {
        Ok(match self.all_hits_on_gpu(rays, o, AllHits::Lists)? {
            Some(DeviceAnswer::Lists(l)) => Some(l),
            _ => None,
        })
    }
}
