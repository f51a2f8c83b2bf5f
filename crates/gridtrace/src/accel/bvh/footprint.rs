//! How wide a packet's rays have spread by the time they reach the scene, against the size of
//! the BVH's leaves: the second half of the packet route's decision (`BvhAccel::traced`), after
//! `coherent`'s cone.
//!
//! Why: `coherent`'s 8-degree cone is an angle, and whether a packet pays depends on a length.
//! A packet pays where its rays share nodes and leaves: one box test of the packet per node
//! and one sort, where the single walks pay eight. Rays a fixed angle apart end that many
//! leaves apart in proportion to how far they travel, so a far camera's neighbouring pixels
//! share the upper nodes only, and the packet, searching each node as far as its farthest ray
//! (a ray that misses searches to infinity), enters the union of the rays' leaves and tests
//! every triangle there against all eight rays; the interleaved single walks overlap eight
//! rays' memory waits instead. So the cone a packet must fit is narrowed, packet by packet, to
//! keep its rays within `FOOTPRINT_LEAVES` mean leaf diagonals of each other where they reach
//! the scene's box. The same test sends a packet that spans two image rows (its rays a row's
//! width apart) to the single walks wherever it is far enough for that to matter.
//!
//! Measured (2026-12-05, `examples/carried_packets.rs`, the flat mesh's `cast_rays`, medians of
//! 15 rounds, three alternating runs each, a shared 2-core machine; `GRIDTRACE_BVH_FOOTPRINT=inf`
//! for the route before this test, `GRIDTRACE_BVH_PACKETS=0` for single walks only):
//! - 10 Stanford Bunnies, 320x240 from 8 diagonals (a packet's rows 14 leaves wide at the
//!   Bunnies): before 11.2-15.4 ms, now 3.6-4.2, single walks 3.5-3.9. Every packet walks
//!   singly now.
//! - 1 Bunny from 8 diagonals: before 1.2-2.2 ms, now 2.1-2.3, single walks 1.2-2.3 (most
//!   packets miss the Bunny: a packet is as cheap as eight single walks there).
//! - 1 Bunny filling the frame (1.2 diagonals): 320x240 (1.75 leaves: packets kept) before
//!   7.2-7.8 ms, now 7.2-8.2, single walks 7.1-8.0; 1024x768 (0.55 leaves) before 56.5-57.2,
//!   now 56.0-58.2, single walks 73-75: the packets win there and are kept.
//! - Stanford Dragon (871k triangles, leaves a third of the Bunny's against its size) from 1.2
//!   diagonals, 640x480: before 57.8-58.0 ms, now 21.4-41.9, single walks 20.4-40.8 (the
//!   machine's load moved between the two runs; each run's three alternate); 1024x768: before
//!   100.5-105.6, now 101.1, single walks 94.9-95.6; from 8 diagonals, 320x240: before
//!   2.9-4.8, now 2.3-2.4, single walks 2.1-2.2.
//!
//! - The two levels' batches with `GRIDTRACE_BVH_PACKETS=all` (`BvhAccel::traced`: they walk
//!   singly by default), 10 Bunnies from 8 diagonals, where 203 of 1,322 packets spanned two
//!   rows: before 10.9-12.9 ms, now 3.2, single walks 2.7-4.0; from 1.5 diagonals 4.6-4.7,
//!   now 4.4-4.5, single walks 4.3-4.5.
//!
//! The crossover on one Bunny, 320x240, packets before this test against single walks: equal at
//! 1.2 diagonals (1.75 leaves), single walks 12-15% faster from 2 diagonals (3.2 leaves) on.
//! Hence 2 leaves.

use glam::Vec3;

use super::build::Bvh;

/// A packet takes the packet walk when its rays' spread where they reach the scene's box
/// (`sin` of the widest angle to its first ray, times the distance from its first origin to
/// the box) is at most this many mean leaf diagonals (`leaf_size`). `GRIDTRACE_BVH_FOOTPRINT`
/// (read once) overrides it, for measuring (`inf`: any spread, the route before this test);
/// the answers are the same either way.
pub(super) const FOOTPRINT_LEAVES: f32 = 2.0;

/// The mean diagonal of the binary tree's leaf boxes: the scale of `FOOTPRINT_LEAVES`.
pub(super) fn leaf_size(bvh: &Bvh) -> f32 {
    let (sum, n) = bvh
        .nodes
        .iter()
        .filter(|n| n.is_leaf())
        .fold((0.0f64, 0usize), |(s, k), n| {
            let d = (Vec3::from(n.max) - Vec3::from(n.min)).max(Vec3::ZERO).length();
            (s + d as f64, k + 1)
        });
    if n == 0 { 0.0 } else { (sum / n as f64) as f32 }
}

/// The cone (the square of its half angle's cosine) that keeps a packet starting at `origin`
/// within `FOOTPRINT_LEAVES` leaves of `leaf` where it reaches the scene's box `lo..hi`: rays
/// at an angle `a` to the first are `sin(a) * dist` apart at distance `dist`, so the test
/// `sin(a)^2 * dist^2 <= reach^2` is `cos(a)^2 >= 1 - reach^2 / dist^2`, the same test as
/// `coherent`'s cone (`coherent_within` takes the narrower), at no cost a ray. Origins inside
/// the box (a camera in a room) are at distance zero: any cone (1 - infinity).
pub(super) fn cone_cos_sq(origin: Vec3, lo: Vec3, hi: Vec3, leaf: f32) -> f32 {
    let dist_sq = (lo - origin).max(origin - hi).max(Vec3::ZERO).length_squared();
    let reach = footprint_leaves() * leaf;
    1.0 - reach * reach / dist_sq
}

/// `FOOTPRINT_LEAVES`, or `GRIDTRACE_BVH_FOOTPRINT` where the environment sets a number.
fn footprint_leaves() -> f32 {
    static K: std::sync::OnceLock<f32> = std::sync::OnceLock::new();
    *K.get_or_init(|| {
        std::env::var("GRIDTRACE_BVH_FOOTPRINT")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(FOOTPRINT_LEAVES)
    })
}
