//! The contract every acceleration structure keeps: what `Accel` (and through it the renderers,
//! the ray queries, the benchmarks and the tests) asks of a structure, and nothing more. A new
//! structure is a folder that implements `AccelStructure`, one arm of `accel::Structure` (and of
//! its `dispatch!`), and one entry of the registry (`registry.rs`): nothing above `accel/` names
//! it.
//!
//! Walks take the triangles they were built over (`Accel::tris`, in the order hits name them):
//! a structure that keeps its own copy (the BVH's leaf blocks) ignores them.

use glam::Vec3;

use super::binning::grid_bounds;
use super::closest::{ClosestPoint, closest_point_brute};
use super::{Aabb, AccelParams, Counters, Hit, NoCounters, PACKET, Ray, TriAccel};
use crate::Result;

/// One acceleration structure over triangles: its build, its update when the triangles move and
/// what it reports. Its walks are `Walks`, apart: a structure may leave them to another it keeps
/// (`hwrt`, whose CPU-side walks are its BVH's; `Accel`'s `walk!` says which).
///
/// A structure knows the traversal it serves (`Structure::kind`): only the uniform grid serves
/// two (`grid` steps every cell, `pc` jumps), and it keeps which in its `stepping`.
pub trait AccelStructure: Sized {
    /// Builds over `tris` (checked finite by the caller or refused by the build), reading its
    /// own keys of `params` (`AccelParams::read`: an unknown key or a bad value is an error that
    /// names them) and keeping what it read, for `params` and `update`.
    fn build(tris: &[TriAccel], params: &AccelParams) -> Result<Self>;

    /// The parameters it was built with, as `build` reads them (empty for a structure that
    /// takes none).
    fn params(&self) -> AccelParams {
        AccelParams::NONE
    }

    /// The triangles moved (same count and order): rebuilt as it was built by default; a
    /// structure that can do better (the BVH's refit) says so. On an error nothing has changed.
    /// Returns what was done, in a word.
    fn update(&mut self, tris: &[TriAccel]) -> Result<&'static str> {
        *self = Self::build(tris, &self.params())?;
        Ok("rebuilt")
    }

    /// The box every ray set over these triangles is drawn from (`binning::grid_bounds`, the
    /// same for every structure over the same triangles).
    fn bounds(&self, tris: &[TriAccel]) -> Aabb {
        // The triangles were checked finite when the structure was built.
        grid_bounds(tris).unwrap_or(Aabb::EMPTY)
    }

    /// Bytes of each array the structure traverses, the triangles not included.
    fn memory(&self) -> Vec<(&'static str, usize)>;

    /// The structure in a few words (one line: what `render` prints after the build).
    fn summary(&self) -> String;

    /// The structure's statistics, a line each (`gridtrace info`), as `label  value`.
    fn info_lines(&self, _tris: &[TriAccel]) -> Result<Vec<(String, String)>> {
        Ok(vec![("structure".into(), self.summary())])
    }
}

/// A structure's walks over the triangles it was built over (pbrt-v4's `Intersect` and
/// `IntersectP`, plus the counts, lists and nearest points): each ray in its own interval
/// (`Ray::t_min`, `Ray::t_max`; the mask is the top level's, not read here).
///
/// The packet and batch defaults run the single-ray walk ray by ray; a structure overrides them
/// when it has something faster that gives the same hits and counts bit for bit (the shared
/// tests check it for every structure).
pub trait Walks {
    /// Closest hit in the ray's interval (`ray.t_min <= t < ray.t_max`), `Hit::MISS` for none.
    fn intersect<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> Hit;

    /// Whether anything is hit in the ray's interval (stops at the first hit found).
    fn occluded<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> bool;

    /// Closest hits of up to `PACKET` coherent rays (a 4x2 block of pixels), each in its own
    /// interval and counted into its own `counters[i]`; misses past `rays.len()`.
    fn intersect_packet<C: Counters>(&self, tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [Hit; PACKET] {
        check_packet(rays.len(), counters.len());
        let mut out = [Hit::MISS; PACKET];
        for ((o, r), c) in out.iter_mut().zip(rays).zip(counters.iter_mut()) {
            *o = self.intersect(tris, r, c);
        }
        out
    }

    /// Any hits of up to `PACKET` rays, each in its own interval; false past `rays.len()`.
    fn occluded_packet<C: Counters>(&self, tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [bool; PACKET] {
        check_packet(rays.len(), counters.len());
        let mut out = [false; PACKET];
        for (i, (r, c)) in rays.iter().zip(counters.iter_mut()).enumerate() {
            out[i] = self.occluded(tris, r, c);
        }
        out
    }

    /// Closest hits of a batch handed to `f(i, hit, normal)` in any order, with the hit
    /// triangle's unnormalised geometric normal (zero for a miss); each ray in its own
    /// interval. On this thread.
    fn intersect_batch_each(&self, tris: &[TriAccel], rays: &[Ray], f: impl FnMut(usize, Hit, Vec3)) {
        intersect_ray_by_ray(self, tris, rays, f)
    }

    /// `intersect_batch_each` for the two levels' streams (`query_scene/streamed_rays.rs`):
    /// one instance's share of a work item's rays, in ray order, each up to its closest hit so
    /// far. A structure whose batch walk bets on neighbouring rays being coherent (the BVH's
    /// packets) says here that these are not.
    fn intersect_stream_each(&self, tris: &[TriAccel], rays: &[Ray], f: impl FnMut(usize, Hit, Vec3)) {
        self.intersect_batch_each(tris, rays, f)
    }

    /// The point of the mesh nearest to `p` (`closest.rs`: the nearest, then the smallest
    /// triangle index; `ClosestPoint::INVALID` for a point that is not finite). Default: every
    /// triangle (`closest_point_brute`); a structure overrides it with its own search.
    fn closest_point(&self, tris: &[TriAccel], p: Vec3) -> ClosestPoint {
        closest_point_brute(tris, p)
    }

    /// The nearest points of a batch, `out[i]` for `points[i]`: `closest_point`'s answers. On
    /// this thread. Default: point by point; a structure overrides it where it can interleave
    /// the searches.
    fn closest_points_batch(&self, tris: &[TriAccel], points: &[[f32; 3]], out: &mut [ClosestPoint]) {
        for (o, p) in out.iter_mut().zip(points) {
            *o = self.closest_point(tris, Vec3::from(*p));
        }
    }

    /// Every hit in the ray's interval, each triangle at most once, appended to `out` in no
    /// particular order (count and list queries: `query_scene`). A ray through an edge or a
    /// vertex shared by several triangles hits each of them that the triangle test accepts
    /// (`TriAccel::intersect` widens its bounds so that at least one does). Default: every
    /// triangle tested (`all_hits_brute`); a structure overrides it with its own walk, which
    /// must report the very hits brute force reports (the same triangle test, so the same
    /// bits).
    fn all_hits(&self, tris: &[TriAccel], ray: &Ray, out: &mut Vec<Hit>) {
        all_hits_brute(tris, ray, out)
    }

    /// How many triangles each ray of a batch hits in its interval, into `out` (`out[i]` for
    /// `rays[i]`): the number of hits `all_hits` lists. On this thread. Default: `all_hits` ray
    /// by ray; a structure overrides it with a walk that counts without listing.
    fn count_hits_batch(&self, tris: &[TriAccel], rays: &[Ray], out: &mut [u32]) {
        let mut hits = Vec::new();
        for (r, o) in rays.iter().zip(out) {
            hits.clear();
            self.all_hits(tris, r, &mut hits);
            *o = hits.len() as u32;
        }
    }

    /// Any-hit answers of a batch into `out` (`out[i]` for `rays[i]`). On this thread.
    fn occluded_batch(&self, tris: &[TriAccel], rays: &[Ray], out: &mut [bool]) {
        for (r, o) in rays.iter().zip(out) {
            *o = self.occluded(tris, r, &mut NoCounters);
        }
    }
}

/// `intersect_batch_each` one ray at a time (`intersect`): the default, and what a structure
/// whose batch walk does not apply takes.
pub(crate) fn intersect_ray_by_ray<S: Walks + ?Sized>(
    s: &S,
    tris: &[TriAccel],
    rays: &[Ray],
    mut f: impl FnMut(usize, Hit, Vec3),
) {
    for (i, r) in rays.iter().enumerate() {
        let hit = s.intersect(tris, r, &mut NoCounters);
        f(i, hit, hit_normal(tris, &hit));
    }
}

/// Whether the rays share the start of their intervals, which a packet walk that tests its
/// lanes from one `t_min` needs (a NaN start is shared with nothing: such rays walk singly,
/// and miss).
#[inline]
pub(crate) fn same_start(rays: &[Ray]) -> bool {
    rays.iter().all(|r| r.t_min == rays[0].t_min)
}

/// The packet rules every packet walk checks: at most `PACKET` rays, a counter each.
#[inline]
pub(crate) fn check_packet(rays: usize, counters: usize) {
    assert!(rays <= PACKET, "a packet holds at most {PACKET} rays, got {rays}");
    assert_eq!(rays, counters, "one counter per ray");
}

/// The geometric normal (`TriAccel::normal`, unnormalised) of a hit's triangle; zero for a
/// miss.
#[inline]
pub fn hit_normal(tris: &[TriAccel], hit: &Hit) -> Vec3 {
    if hit.is_hit() {
        tris[hit.tri as usize].normal()
    } else {
        Vec3::ZERO
    }
}

/// The oracle of `AccelStructure::all_hits`: every triangle tested, hits in triangle order.
pub fn all_hits_brute(tris: &[TriAccel], ray: &Ray, out: &mut Vec<Hit>) {
    for (i, t) in tris.iter().enumerate() {
        if let Some(h) = t.intersect(ray.origin, ray.dir, ray.t_min, ray.t_max) {
            out.push(h.on(i as u32));
        }
    }
}

/// Keeps one hit per triangle among `out[from..]`: for walks that meet a triangle in several
/// cells. The same triangle test on the same ray gives the same bits wherever it runs, so the
/// copies are identical and any one may stay. Sorted by triangle.
pub(crate) fn dedup_hits(out: &mut Vec<Hit>, from: usize) {
    out[from..].sort_unstable_by_key(|h| h.tri);
    let mut keep = from;
    for i in from..out.len() {
        if keep == from || out[keep - 1].tri != out[i].tri {
            out[keep] = out[i];
            keep += 1;
        }
    }
    out.truncate(keep);
}
