//! Closest-point batches: the nearest point of the mesh to each of the caller's points, through
//! the scene's structure's search on the GPU (`shaders/closest_point.wgsl`, calling the walk
//! file's `NAME_closest_point`: rings of cells on the grids, branch and bound on the BVH, the
//! cells of the irregular grid, every triangle for brute force). The points go up as 12 bytes
//! each and into the ray queue the kernel reads (as ray origins), in the ray batches' pipelined
//! chunks (`queries.rs`), and the answers come back as the CPU's `ClosestPoint`s, with
//! `last_query_stats` as for ray batches.
//!
//! The GPU returns the triangle and the barycentrics; the host rebuilds the point and its
//! squared distance from them as the CPU does (`v0 + u e1 + v e2`), so the distance is always
//! the distance to the point reported. A point with a non-finite coordinate never reaches the
//! device: it gets `ClosestPoint::INVALID` (NaN distance), as on the CPU.

use glam::Vec3;

use super::constants::MISS;
use super::layout::GpuHit;
use super::queries::{Bounds, ChunkAnswers, Query, WireSource};
use super::renderer::GpuRenderer;
use crate::accel::TriAccel;
use crate::accel::closest::ClosestPoint;
use crate::{Error, Result};

/// Closest points of a batch with the search's work per point.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GpuClosestPoints {
    /// One per query point, as `AccelStructure::closest_point` answers it (`tri` indexes the
    /// triangles the scene was uploaded with).
    pub closest: Vec<ClosestPoint>,
    /// Cells or nodes visited plus triangles measured, per point (0 for a point that was not
    /// finite: it was not searched).
    pub work: Vec<u32>,
    /// Loop iterations of the search, per point, as the lattice searches (grid, proximity cloud,
    /// irregular grid) count them (`point_steps` in the WGSL; 0 for the other walks and for a
    /// point that was not searched). llvmpipe before Mesa 25 silently ends an invocation's
    /// loops after 65,535 iterations in all: a search that needs more gives a wrong answer
    /// there, which the tests guard against by holding this count under that budget.
    pub steps: Vec<u32>,
}

impl GpuRenderer {
    /// The nearest point of the mesh to each of `points`, searched with the structure's walk; `tris`
    /// are the triangles this renderer's scene was uploaded with (the points are rebuilt from
    /// them).
    pub fn closest_points(&mut self, tris: &[TriAccel], points: &[[f32; 3]]) -> Result<Vec<ClosestPoint>> {
        Ok(self.closest_points_counted(tris, points)?.closest)
    }

    /// `closest_points` with each point's search work.
    pub fn closest_points_counted(&mut self, tris: &[TriAccel], points: &[[f32; 3]]) -> Result<GpuClosestPoints> {
        let mut out = GpuClosestPoints {
            closest: Vec::with_capacity(points.len()),
            work: Vec::with_capacity(points.len()),
            steps: Vec::with_capacity(points.len()),
        };
        // One pipelined batch (`queries.rs`): the points go up as 12 bytes each, and come back
        // as the answers, then the work the kernel wrote to each item's accumulation texel.
        self.batch(
            &PointRows { points },
            Bounds {
                interval: (0.0, f32::INFINITY),
                mask: u32::MAX,
            },
            Query::ClosestPoint,
            |first, answers| {
                let ChunkAnswers::Points { hits, work } = answers else {
                    return;
                };
                let work = work.iter().map(|a| (a[0] as u32, a[1] as u32));
                for ((p, h), (w, steps)) in points[first..].iter().zip(hits).zip(work) {
                    let p = Vec3::from(*p);
                    let (c, w, steps) = if !p.is_finite() {
                        (ClosestPoint::INVALID, 0, 0)
                    } else if h.tri == MISS || h.tri as usize >= tris.len() {
                        (ClosestPoint::NONE, w, steps)
                    } else {
                        (answer(&tris[h.tri as usize], *h, p), w, steps)
                    };
                    out.closest.push(c);
                    out.work.push(w);
                    out.steps.push(steps);
                }
            },
        )?;
        Ok(out)
    }
}

/// Query points on the wire, 12 bytes each; a point that is not finite goes as the origin (its
/// answer is the host's).
pub(super) struct PointRows<'a> {
    pub points: &'a [[f32; 3]],
}

impl WireSource for PointRows<'_> {
    fn len(&self) -> usize {
        self.points.len()
    }
    fn stride(&self) -> usize {
        3
    }
    fn write(&self, first: usize, out: wgpu::WriteOnly<'_, [u8]>) -> bool {
        let (out, _) = out.into_chunks::<12>();
        let n = out.len();
        out.write_iter(self.points[first..first + n].iter().map(|p| {
            let p = if Vec3::from(*p).is_finite() { *p } else { [0.0; 3] };
            bytemuck::cast::<[f32; 3], [u8; 12]>(p)
        }));
        true
    }
    fn invalid(&self) -> Error {
        Error::InvalidInput("every query point is answered".into())
    }
}

/// The CPU's answer for the GPU's triangle and barycentrics at `p`: the point and its squared
/// distance computed as `closest_on_triangle` computes them.
fn answer(t: &TriAccel, h: GpuHit, p: Vec3) -> ClosestPoint {
    let (e1, e2) = t.edges();
    let point = Vec3::from(t.v0) + e1 * h.u + e2 * h.v;
    ClosestPoint {
        point,
        dist_sq: (p - point).length_squared(),
        tri: h.tri,
        u: h.u,
        v: h.v,
    }
}
