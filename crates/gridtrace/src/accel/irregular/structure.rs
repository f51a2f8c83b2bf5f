//! The irregular grid under the structure contract: packets in SIMD lanes, batches that take
//! runs of coherent rays as packets.

use glam::Vec3;

use super::{IrregularGrid, IrregularParams, IrregularStats};
use crate::Result;
use crate::accel::contract::{AccelStructure, Walks, dedup_hits, hit_normal, intersect_ray_by_ray};
use crate::accel::{Aabb, AccelParams, Counters, Hit, NoCounters, PACKET, Ray, TriAccel, dims_str};
use crate::util::fmt_bytes;

impl AccelStructure for IrregularGrid {
    /// The keys of `IrregularParams::KEYS` (`top=0.12,cell=2,alpha=1,merge=8,expand=3`).
    fn build(tris: &[TriAccel], params: &AccelParams) -> Result<IrregularGrid> {
        IrregularGrid::build(tris, IrregularParams::from_params(params)?)
    }

    fn params(&self) -> AccelParams {
        self.params.to_params()
    }

    fn bounds(&self, _tris: &[TriAccel]) -> Aabb {
        self.bounds
    }

    fn memory(&self) -> Vec<(&'static str, usize)> {
        IrregularGrid::memory(self)
    }

    fn summary(&self) -> String {
        let s = &self.stats;
        format!(
            "irregular top {} x {} levels, {} cells, {:.2} refs/tri, {} (built in {:.1} ms)",
            dims_str(s.top_dims),
            s.max_level,
            s.cells,
            s.refs_per_triangle(),
            fmt_bytes(self.bytes()),
            s.build_ms()
        )
    }

    fn info_lines(&self, tris: &[TriAccel]) -> Result<Vec<(String, String)>> {
        let s = &self.stats;
        let v = self.voxel_dims();
        let mut lines = vec![
            (
                "irregular grid".to_string(),
                format!(
                    "top {} cells, up to {} levels below (virtual {}x{}x{} voxels)",
                    dims_str(s.top_dims),
                    s.max_level,
                    v.x,
                    v.y,
                    v.z
                ),
            ),
            (
                "cells".into(),
                format!(
                    "{} ({} before merging), {:.1}% empty",
                    s.cells,
                    s.initial_cells,
                    s.empty_cells as f64 * 100.0 / s.cells.max(1) as f64
                ),
            ),
            (
                "references".into(),
                format!("{} ({:.2} per triangle)", s.references, s.refs_per_triangle()),
            ),
            ("build".into(), format!("{:.2} ms", s.build_ms())),
        ];
        for (phase, ms) in IrregularStats::PHASES.iter().zip(s.phase_ms) {
            lines.push((format!("  {phase}"), format!("{ms:>9.2} ms")));
        }
        // What `memory_bound` says before a build, beside what this one made.
        let m = IrregularGrid::memory_bound(tris, self.params)?;
        lines.push((
            "bound".into(),
            format!(
                "at most {} cells before merging, {} references, structure {}, build peak {}",
                m.initial_cells,
                m.references,
                fmt_bytes(m.structure_bytes as usize),
                fmt_bytes(m.build_peak_bytes as usize)
            ),
        ));
        Ok(lines)
    }
}

/// The irregular grid's walks: packets in SIMD lanes (`packet.rs`), batches that take runs of
/// coherent rays as packets and interleave the rest (`walk.rs`).
impl Walks for IrregularGrid {
    #[inline]
    fn intersect<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> Hit {
        IrregularGrid::intersect(self, tris, ray, counters)
    }

    #[inline]
    fn occluded<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> bool {
        IrregularGrid::occluded(self, tris, ray, counters)
    }

    #[inline]
    fn intersect_packet<C: Counters>(&self, tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [Hit; PACKET] {
        IrregularGrid::intersect_packet(self, tris, rays, counters)
    }

    #[inline]
    fn occluded_packet<C: Counters>(&self, tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [bool; PACKET] {
        IrregularGrid::occluded_packet(self, tris, rays, counters)
    }

    #[inline]
    fn intersect_batch_each(&self, tris: &[TriAccel], rays: &[Ray], mut f: impl FnMut(usize, Hit, Vec3)) {
        self.batch::<false>(tris, rays, |i, hit| f(i, hit, hit_normal(tris, &hit)))
    }

    /// Ray by ray: a stream's rays are one instance's share of a work item's, each up to its
    /// own closest hit so far, which the packets (one limit for all, when they were measured)
    /// were not made for.
    fn intersect_stream_each(&self, tris: &[TriAccel], rays: &[Ray], f: impl FnMut(usize, Hit, Vec3)) {
        intersect_ray_by_ray(self, tris, rays, f)
    }

    fn occluded_batch(&self, tris: &[TriAccel], rays: &[Ray], out: &mut [bool]) {
        self.batch::<true>(tris, rays, |i, hit| out[i] = hit.is_hit())
    }

    /// Every cell the ray crosses (no early exit), each triangle tested where it is met, kept
    /// once (`dedup_hits`): brute force's set, as the closest-hit walk finds brute force's hit.
    fn all_hits(&self, tris: &[TriAccel], ray: &Ray, out: &mut Vec<Hit>) {
        let from = out.len();
        self.walk(ray, &mut NoCounters, |refs, _, _| {
            for &r in refs {
                if let Some(h) = tris[r as usize].intersect(ray.origin, ray.dir, ray.t_min, ray.t_max) {
                    out.push(h.on(r));
                }
            }
            false
        });
        dedup_hits(out, from);
    }

    /// Branch and bound over the structure's own cells or nodes (`closest.rs`).
    fn closest_point(&self, tris: &[TriAccel], p: glam::Vec3) -> crate::accel::closest::ClosestPoint {
        IrregularGrid::closest_point(self, tris, p)
    }
}
