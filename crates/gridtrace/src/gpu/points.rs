//! Closest-point batches: the nearest point of the mesh to each of the caller's points, through
//! the scene's structure's search on the GPU (`shaders/closest_point.wgsl`, calling the walk
//! file's `NAME_closest_point`: rings of cells on the grids, branch and bound on the BVH, the
//! cells of the irregular grid, every triangle for brute force). The points go into the ray
//! queue the kernel reads (as ray origins), in chunks that fit the work buffers, all in one
//! submission with one wait (`queries.rs`), and the answers come back as the CPU's
//! `ClosestPoint`s, with `last_query_stats` as for ray batches.
//!
//! The GPU returns the triangle and the barycentrics; the host rebuilds the point and its
//! squared distance from them as the CPU does (`v0 + u e1 + v e2`), so the distance is always
//! the distance to the point reported. A point with a non-finite coordinate never reaches the
//! device: it gets `ClosestPoint::INVALID` (NaN distance), as on the CPU.

use glam::Vec3;

use super::constants::MISS;
use super::layout::{GpuHit, RayRec};
use super::queries::Query;
use super::renderer::GpuRenderer;
use crate::Result;
use crate::accel::closest::ClosestPoint;
use crate::accel::{AccelKind, TriAccel};

/// Closest points of a batch with the search's work per point.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GpuClosestPoints {
    /// One per query point, as `AccelStructure::closest_point` answers it (`tri` indexes the
    /// triangles the scene was uploaded with).
    pub closest: Vec<ClosestPoint>,
    /// Cells or nodes visited plus triangles measured, per point (0 for a point that was not
    /// finite: it was not searched).
    pub work: Vec<u32>,
}

impl GpuRenderer {
    /// The nearest point of the mesh to each of `points`, searched with `kind`'s walk; `tris`
    /// are the triangles this renderer's scene was uploaded with (the points are rebuilt from
    /// them).
    pub fn closest_points(
        &mut self,
        tris: &[TriAccel],
        points: &[[f32; 3]],
        kind: AccelKind,
    ) -> Result<Vec<ClosestPoint>> {
        Ok(self.closest_points_counted(tris, points, kind)?.closest)
    }

    /// `closest_points` with each point's search work.
    pub fn closest_points_counted(
        &mut self,
        tris: &[TriAccel],
        points: &[[f32; 3]],
        kind: AccelKind,
    ) -> Result<GpuClosestPoints> {
        let mut out = GpuClosestPoints {
            closest: Vec::with_capacity(points.len()),
            work: Vec::with_capacity(points.len()),
        };
        let rec = |i: usize| {
            let p = points[i];
            RayRec {
                // A stand-in for a point that is not finite (its answer is the host's).
                origin: if Vec3::from(p).is_finite() { p } else { [0.0; 3] },
                pixel: 0,
                dir: [0.0, 0.0, 1.0],
                t_max: f32::INFINITY,
                weight: [1.0; 3],
                t_min: 0.0,
            }
        };
        // One submission and one wait for the whole batch (`queries.rs`): the answers, then
        // the work the kernel wrote to each item's accumulation texel.
        self.batch(points.len(), rec, kind, Query::ClosestPoint, |raw| {
            let hits: &[GpuHit] = bytemuck::cast_slice(raw[0]);
            let work = bytemuck::cast_slice::<u8, [f32; 4]>(raw[1]).iter().map(|a| a[0] as u32);
            let at = out.closest.len();
            for ((p, h), w) in points[at..].iter().zip(hits).zip(work) {
                let p = Vec3::from(*p);
                let (c, w) = if !p.is_finite() {
                    (ClosestPoint::INVALID, 0)
                } else if h.tri == MISS || h.tri as usize >= tris.len() {
                    (ClosestPoint::NONE, w)
                } else {
                    (answer(&tris[h.tri as usize], *h, p), w)
                };
                out.closest.push(c);
                out.work.push(w);
            }
        })?;
        Ok(out)
    }
}

/// The CPU's answer for the GPU's triangle and barycentrics at `p`: the point and its squared
/// distance computed as `closest_on_triangle` computes them.
fn answer(t: &TriAccel, h: GpuHit, p: Vec3) -> ClosestPoint {
    let point = Vec3::from(t.v0) + Vec3::from(t.e1) * h.u + Vec3::from(t.e2) * h.v;
    ClosestPoint {
        point,
        dist_sq: (p - point).length_squared(),
        tri: h.tri,
        u: h.u,
        v: h.v,
    }
}
