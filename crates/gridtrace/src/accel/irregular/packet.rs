//! Packets: up to eight coherent rays (a 4x2 block of pixels' eye, shadow or mirror rays)
//! walked together, a ray per SIMD lane: eight lanes (`simd::F8`: one AVX register where the
//! CPU has AVX2, two NEON registers on aarch64), two packets of four in SSE registers elsewhere
//! (`lanes.rs`: the walk is written once for both).
//!
//! Why: a single ray's step is one long chain of dependent operations (voxel -> top cell ->
//! voxel map -> cell -> exit distances -> exit point -> next voxel), about a hundred cycles of
//! latency that no other work fills, and the triangle tests are the smaller part of a ray's
//! cost (docs/benchmarks.md). Sharing only the cell and its triangle tests among the rays of a
//! round gained 6-10%; stepping them in four-lane arithmetic made packets 1.2-1.35x the single
//! rays (docs/benchmarks-history.md "Packets"): neighbouring camera rays cross the same large cells one
//! after another (3.5 of 4 rays take part in a round on the paper's scenes), so one chain of
//! four-lane operations advances them all, and one lane-parallel triangle test (the triangle
//! in every lane, a ray per lane) tests a triangle against all of them. Eight lanes in AVX
//! registers made camera rays another 1.1-1.4x faster than four (docs/benchmarks-history.md "Packets
//! of eight"): the same chain advances twice the rays, at about the same cost per instruction.
//!
//! Each ray still goes through exactly the cells its single-ray walk (`walk.rs`) visits: a
//! round takes the cell of the first ray still walking, the rays whose current cell it is
//! take part, the others wait for a round of their own cell. Every lane computes what
//! `face_t` and `advance` compute for it: the same operations in the same order for the face
//! distances and the exit point, voxel coordinates as integers below 2^16 (exact in `f32`),
//! and the exit voxel clamped before it is truncated, with NaN taken to the box's low side,
//! which gives what the scalar saturating cast and clamp give. So the hits and the counts
//! (cells, triangle tests) are bit for bit those of `intersect`, ray by ray (tested).

use super::IrregularGrid;
use glam::Vec4;

use crate::accel::contract::same_start;
use crate::accel::lanes::{Lanes, Mask, load3, splat3};
use crate::accel::{Counters, Hit, LaneRay, NoCounters, PACKET, Ray, TriAccel, intersect_lanes};
use crate::util::set_bits as bits;

/// The rays of a packet and where they are, a ray per lane.
struct Walkers<const N: usize, L: Lanes<N>> {
    origin: [L; 3],
    dir: [L; 3],
    /// The rays prepared for the watertight triangle test, once per packet.
    tri_ray: LaneRay<N, L>,
    inv: [L; 3],
    /// Lanes whose ray moves up / down along each axis (neither: it does not move on it).
    up: [L::Mask; 3],
    down: [L::Mask; 3],
    /// The voxel each ray is in, as exact integers.
    v: [L; 3],
    t_leave: L,
    budget: [u32; N],
}

/// `f32::min` lane by lane: a NaN gives way to the other operand, as there.
#[inline(always)]
fn min_lanes<const N: usize, L: Lanes<N>>(a: L, b: L) -> L {
    L::select(a.is_nan(), b, L::select(b.is_nan() | !b.lt(a), a, b))
}

impl IrregularGrid {
    /// Closest hits of up to `PACKET` rays (`rays.len()`), each in its own interval and
    /// counted into its own `counters[i]`: the same hits and counts as `intersect` ray by ray,
    /// faster when the rays are coherent. The hits past `rays.len()` are misses.
    pub fn intersect_packet<C: Counters>(&self, tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [Hit; PACKET] {
        self.walk_packet::<false, C>(tris, rays, counters, false)
    }

    /// Whether each of up to `PACKET` rays hits anything in its interval (shadow rays towards
    /// a light, each with its own distance): the same answers and counts as `occluded` ray by
    /// ray. Past `rays.len()`: false.
    pub fn occluded_packet<C: Counters>(&self, tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [bool; PACKET] {
        self.walk_packet::<true, C>(tris, rays, counters, false)
            .map(|h| h.is_hit())
    }

    /// A packet walked as two packets of four (what CPUs without AVX2 run), whatever the CPU:
    /// closest hits, or (`ANY`) any hits (as `Hit::is_hit`), each ray in its interval. For
    /// tests, and for measuring the widths against each other (`--example irregular_packets`).
    #[doc(hidden)]
    pub fn packet_in_fours<const ANY: bool, C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        self.walk_packet::<ANY, C>(tris, rays, counters, true)
    }

    /// The packet walk: eight rays in eight lanes where the CPU runs them (`simd::has_wide`;
    /// on x86-64 compiled for AVX2:
    /// three-operand instructions, the same bits, as the BVH's `interleaved` explains), else
    /// (or with `fours`) as two packets of four in SSE registers. Hits and counts are the
    /// single-ray walk's either way.
    ///
    /// The lanes test triangles from one `t_min` (the packet's; each lane has its own far
    /// limit): rays whose intervals start apart walk singly (`walk_singly`).
    fn walk_packet<const ANY: bool, C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        counters: &mut [C],
        fours: bool,
    ) -> [Hit; PACKET] {
        // Checked here for both paths (`walk_fours` would otherwise zip them silently).
        assert!(
            rays.len() <= PACKET && counters.len() == rays.len(),
            "a packet is up to {PACKET} rays, a counter each"
        );
        if !same_start(rays) {
            return self.walk_singly::<ANY, C>(tris, rays, counters);
        }
        if crate::accel::simd::has_wide() {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            return unsafe { self.walk_packet_wide::<ANY, C>(tris, rays, counters, fours) };
        }
        self.walk_fours::<ANY, C>(tris, rays, counters)
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    unsafe fn walk_packet_wide<const ANY: bool, C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        counters: &mut [C],
        fours: bool,
    ) -> [Hit; PACKET] {
        if fours {
            return self.walk_fours::<ANY, C>(tris, rays, counters);
        }
        // `F8` is for the eight-lane build only: this function is compiled for it.
        self.walk_lanes::<PACKET, crate::accel::lanes::F8, ANY, C>(tris, rays, counters)
    }

    /// The packet's rays walked one by one (`intersect`, `occluded`), with `walk_packet`'s
    /// answers: for `ANY` a hit stands for "occluded" (`Hit::is_hit`), at the interval's start.
    fn walk_singly<const ANY: bool, C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        let mut hits = [Hit::MISS; PACKET];
        for ((h, r), c) in hits.iter_mut().zip(rays).zip(counters.iter_mut()) {
            *h = match ANY {
                false => self.intersect(tris, r, c),
                true if self.occluded(tris, r, c) => Hit {
                    t: r.t_min,
                    tri: 0,
                    ..Hit::MISS
                },
                true => Hit::MISS,
            };
        }
        hits
    }

    /// A packet as two packets of four (`Vec4` lanes).
    #[inline(always)]
    fn walk_fours<const ANY: bool, C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        let mut hits = [Hit::MISS; PACKET];
        for (h, (rays, counters)) in rays.chunks(4).zip(counters.chunks_mut(4)).enumerate() {
            let got = self.walk_lanes::<4, Vec4, ANY, C>(tris, rays, counters);
            hits[4 * h..4 * h + 4].copy_from_slice(&got);
        }
        hits
    }

    /// The packet walk: closest hits, or (`ANY`) any hit per ray, which ends that ray's walk
    /// and its tests at once, as `any_in` does. A round takes the cell of the first ray still
    /// walking: its rays test the cell's triangles together (`test_cell_lanes`) and step to
    /// their next voxels together (`next_voxels`, `move_lanes`). The rays share their
    /// intervals' start (`walk_packet` checks), which the lanes' triangle tests take as one.
    #[inline(always)]
    fn walk_lanes<const N: usize, L: Lanes<N>, const ANY: bool, C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        counters: &mut [C],
    ) -> [Hit; N] {
        assert!(
            rays.len() <= N && counters.len() == rays.len(),
            "a packet is up to {N} rays, a counter each"
        );
        let t_min = rays.first().map_or(0.0, |r| r.t_min);
        // Lanes past the rays' count search nothing (`t_max = t_min`: an empty interval).
        let mut best: [Hit; N] = std::array::from_fn(|i| Hit {
            t: rays.get(i).map_or(t_min, |r| r.t_max),
            ..Hit::MISS
        });
        let (mut l, mut cell_of, mut walking) = self.start_lanes::<N, L>(rays);
        let lattice = VoxelLanes {
            bounds_min: splat3(self.bounds.min.to_array()),
            voxel_size: splat3(self.voxel_size.to_array()),
            inv_voxel_size: splat3(self.inv_voxel_size.to_array()),
            dims: splat3(self.voxel_dims().as_vec3().to_array()),
        };
        while walking != 0 {
            let id = cell_of[walking.trailing_zeros() as usize];
            let mut round = 0u32;
            for i in bits(walking) {
                if cell_of[i] == id {
                    round |= 1 << i;
                }
            }
            for i in bits(round) {
                counters[i].cell();
            }
            let cell = self.cell(id);
            let lo: [L; 3] = splat3([cell.min[0] as f32, cell.min[1] as f32, cell.min[2] as f32]);
            let hi: [L; 3] = splat3([cell.max[0] as f32, cell.max[1] as f32, cell.max[2] as f32]);
            let t_faces = face_ts(&l, &lo, &hi, &lattice);
            let t_exit = min_lanes(min_lanes(t_faces[0], t_faces[1]), t_faces[2]);
            let mut finished = 0u32;
            if cell.count > 0 {
                let refs = &self.refs[cell.start as usize..(cell.start + cell.count) as usize];
                finished |= test_cell_lanes::<N, L, ANY, C>(tris, refs, round, t_min, &l, t_exit, &mut best, counters);
            }
            finished |= t_exit.ge(l.t_leave).bits();
            let (next, leaves) = next_voxels(&l, &t_faces, t_exit, &lo, &hi, &lattice);
            finished |= leaves.bits();
            self.move_lanes(
                &mut l,
                next,
                round & !finished,
                round & finished,
                &mut walking,
                &mut cell_of,
            );
        }
        best.map(|h| if h.tri == u32::MAX { Hit::MISS } else { h })
    }

    /// The packet's rays as lanes at their first voxels (`cursor`), with each walking ray's
    /// cell and the rays that walk (bit i for `rays[i]`; a ray that misses the box does not).
    /// Unused lanes hold a ray along +x at the origin and never walk.
    #[inline(always)]
    fn start_lanes<const N: usize, L: Lanes<N>>(&self, rays: &[Ray]) -> (Walkers<N, L>, [u32; N], u32) {
        let (mut origin, mut dir, mut inv, mut v) = ([[0.0; N]; 3], [[0.0; N]; 3], [[1.0; N]; 3], [[0.0; N]; 3]);
        dir[0] = [1.0; N];
        let (mut up, mut down, mut t_leave, mut budget) = ([0u32; 3], [0u32; 3], [0.0; N], [0u32; N]);
        let mut cell_of = [u32::MAX; N];
        let mut walking = 0u32;
        for (i, ray) in rays.iter().enumerate() {
            for a in 0..3 {
                origin[a][i] = ray.origin[a];
                dir[a][i] = ray.dir[a];
            }
            if let Some(c) = self.cursor(ray) {
                for a in 0..3 {
                    inv[a][i] = c.inv[a];
                    up[a] |= ((c.step[a] > 0) as u32) << i;
                    down[a] |= ((c.step[a] < 0) as u32) << i;
                    v[a][i] = c.v[a] as f32;
                }
                t_leave[i] = c.t_leave;
                budget[i] = c.budget;
                cell_of[i] = self.voxel_map[self.slot(c.v)];
                walking |= 1 << i;
            }
        }
        let (origin, dir) = (load3(origin), load3(dir));
        let walkers = Walkers {
            tri_ray: LaneRay::new(&origin, &dir),
            origin,
            dir,
            inv: load3(inv),
            // Not `map` with a closure: closures do not inherit `#[target_feature]` (`splat3`).
            up: [
                L::Mask::from_bits(up[0]),
                L::Mask::from_bits(up[1]),
                L::Mask::from_bits(up[2]),
            ],
            down: [
                L::Mask::from_bits(down[0]),
                L::Mask::from_bits(down[1]),
                L::Mask::from_bits(down[2]),
            ],
            v: load3(v),
            t_leave: L::from_array(t_leave),
            budget,
        };
        (walkers, cell_of, walking)
    }

    /// Moves the rays of `moving` into their `next` voxels and out of the walk those of
    /// `finished`, or that ran out of budget; a ray that moves gets its new cell.
    #[inline(always)]
    fn move_lanes<const N: usize, L: Lanes<N>>(
        &self,
        l: &mut Walkers<N, L>,
        next: [L; 3],
        moving: u32,
        finished: u32,
        walking: &mut u32,
        cell_of: &mut [u32; N],
    ) {
        let move_lanes = L::Mask::from_bits(moving);
        for (v, next) in l.v.iter_mut().zip(next) {
            *v = L::select(move_lanes, next, *v);
        }
        *walking &= !finished;
        let voxels = [l.v[0].to_array(), l.v[1].to_array(), l.v[2].to_array()];
        for i in bits(moving) {
            l.budget[i] -= 1;
            if l.budget[i] == 0 {
                *walking &= !(1 << i);
            } else {
                let v = [voxels[0][i] as i32, voxels[1][i] as i32, voxels[2][i] as i32];
                cell_of[i] = self.voxel_map[self.slot(v)];
            }
        }
    }
}

/// The virtual voxels' lattice in lanes (every lane the same).
struct VoxelLanes<L> {
    bounds_min: [L; 3],
    voxel_size: [L; 3],
    inv_voxel_size: [L; 3],
    dims: [L; 3],
}

/// `face_t` lane by lane: the parameter of the grown box `lo..hi` (voxels) face ahead on each
/// axis; infinity on an axis the ray does not move along.
#[inline(always)]
fn face_ts<const N: usize, L: Lanes<N>>(
    l: &Walkers<N, L>,
    lo: &[L; 3],
    hi: &[L; 3],
    lattice: &VoxelLanes<L>,
) -> [L; 3] {
    let mut t_faces = [L::INFINITY; 3];
    for a in 0..3 {
        let k = L::select(l.up[a], hi[a], lo[a]);
        let t = (lattice.bounds_min[a] + k * lattice.voxel_size[a] - l.origin[a]) * l.inv[a];
        t_faces[a] = L::select(l.up[a] | l.down[a], t, L::INFINITY);
    }
    t_faces
}

/// Tests a cell's triangles (`refs`) against the rays of `round`, keeping each ray's closest
/// hit in `best` (`ANY`: its first, which ends its tests); returns the rays of the round that
/// are done (as `intersect`: a hit is final inside the grown cell, checked after a non-empty
/// cell).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn test_cell_lanes<const N: usize, L: Lanes<N>, const ANY: bool, C: Counters>(
    tris: &[TriAccel],
    refs: &[u32],
    round: u32,
    t_min: f32,
    l: &Walkers<N, L>,
    t_exit: L,
    best: &mut [Hit; N],
    counters: &mut [C],
) -> u32 {
    // A lane's tests reach up to its closest hit so far (`t_max` until one, and for any hits,
    // whose first hit ends them). Lanes outside the round test up to `t_min`, which no hit
    // passes (`t >= t_min` and `t < t_min` cannot both hold), so they keep their hits.
    let mut testing = round;
    let mut limit = L::select(L::Mask::from_bits(round), t_of(best), L::splat(t_min));
    for &tri in refs {
        for i in bits(testing) {
            counters[i].tri_test();
        }
        let t = &tris[tri as usize];
        let corners = (&splat3(t.v0), &splat3(t.v1), &splat3(t.v2));
        let h = intersect_lanes(corners, &l.tri_ray, t_min, limit);
        let hits = h.mask() & testing;
        if hits != 0 {
            let mut limits = limit.to_array();
            for k in bits(hits) {
                best[k] = h.lane(k).on(tri);
                if ANY {
                    // As `any_in`: the first hit ends this ray's tests and its walk.
                    testing &= !(1 << k);
                    limits[k] = t_min;
                } else {
                    // The test passed `t < limit[k]`, this ray's closest hit so far: as in
                    // `closest_in`, a later triangle replaces an earlier one only if nearer.
                    limits[k] = best[k].t;
                }
            }
            limit = L::from_array(limits);
        }
        if testing == 0 {
            break;
        }
    }
    if ANY {
        round & !testing
    } else {
        bits_hit(best) & t_of::<N, L>(best).le(min_lanes(t_exit, l.t_leave)).bits()
    }
}

/// `advance` lane by lane: the voxel just past the exit face (`walk.rs` says why so), and the
/// lanes whose exit leaves the lattice.
#[inline(always)]
fn next_voxels<const N: usize, L: Lanes<N>>(
    l: &Walkers<N, L>,
    t_faces: &[L; 3],
    t_exit: L,
    lo: &[L; 3],
    hi: &[L; 3],
    lattice: &VoxelLanes<L>,
) -> ([L; 3], L::Mask) {
    let past1 = t_faces[1].lt(t_faces[0]);
    let nearer = L::select(past1, t_faces[1], t_faces[0]);
    let past2 = t_faces[2].lt(nearer);
    let on_axis = [!(past1 | past2), past1 & !past2, past2];
    let mut next = l.v;
    let mut leaves = L::Mask::from_bits(0);
    for a in 0..3 {
        let p = l.origin[a] + l.dir[a] * t_exit;
        // The exit point's voxel clamped into the box: clamping before truncating gives what
        // truncating (saturating, NaN to 0) then clamping does, NaN to `lo`.
        let x = (p - lattice.bounds_min[a]) * lattice.inv_voxel_size[a];
        let x = L::select(x.is_nan(), lo[a], x);
        let inside = L::select(x.lt(lo[a]), lo[a], x);
        let top = hi[a] - L::ONE;
        let inside = L::select(inside.gt(top), top, inside).trunc_small();
        let ahead = L::select(l.up[a], inside.max(l.v[a]), inside.min(l.v[a]));
        let across = L::select(l.up[a], hi[a], lo[a] - L::ONE);
        next[a] = L::select(on_axis[a], across, L::select(l.up[a] | l.down[a], ahead, l.v[a]));
        leaves = leaves | (on_axis[a] & (across.lt(L::ZERO) | across.ge(lattice.dims[a])));
    }
    (next, leaves)
}

/// The hits' `t`, a lane each.
#[inline(always)]
fn t_of<const N: usize, L: Lanes<N>>(best: &[Hit; N]) -> L {
    let mut t = [0.0; N];
    for (t, h) in t.iter_mut().zip(best) {
        *t = h.t;
    }
    L::from_array(t)
}

/// Bit `i` set where `best[i]` is a hit.
#[inline(always)]
fn bits_hit<const N: usize>(best: &[Hit; N]) -> u32 {
    best.iter()
        .enumerate()
        .fold(0, |m, (i, h)| m | (h.is_hit() as u32) << i)
}

/// Directions closer than this (cosine of about 1.1 degrees) count as coherent: neighbouring
/// pixels of a camera are a tenth of a degree apart at 512 pixels over 60 degrees, so eight in
/// a row pass, and rays that merely share an origin (from a point in all directions) do not.
const COHERENT_COS: f32 = 0.9998;

impl IrregularGrid {
    /// Whether a packet's rays will walk together: origins within one virtual voxel of the
    /// first's on every axis (one point for a camera's rays, neighbouring hit points for their
    /// shadow or mirror rays) and directions within about a degree. Such a packet mostly
    /// shares its cells; any other would walk apart and pay for the packet's bookkeeping. (The
    /// answers do not depend on it.)
    fn coherent(&self, packet: &[Ray]) -> bool {
        let (o, d) = (packet[0].origin, packet[0].dir);
        packet[1..].iter().all(|r| {
            (r.origin - o).abs().cmple(self.voxel_size).all()
                && r.dir.dot(d) >= COHERENT_COS * (r.dir.length() * d.length())
        })
    }

    /// Closest hits (`ANY = false`) or any hits of a batch, handed to `finish(i, hit)` for each
    /// `rays[i]` in no particular order, as `interleaved` does: runs of packets that walk
    /// together (`coherent`: an image's rays in row order from Python, their shadow rays
    /// towards a light) go as packets, the rest through the interleaved single-ray walk. The
    /// same answers either way.
    pub(crate) fn batch<const ANY: bool>(&self, tris: &[TriAccel], rays: &[Ray], mut finish: impl FnMut(usize, Hit)) {
        let packet_at = |i: usize| {
            i + PACKET <= rays.len() && same_start(&rays[i..i + PACKET]) && self.coherent(&rays[i..i + PACKET])
        };
        let mut i = 0;
        while i < rays.len() {
            while packet_at(i) {
                let mut c = [NoCounters; PACKET];
                let hits = self.walk_packet::<ANY, _>(tris, &rays[i..i + PACKET], &mut c, false);
                for (k, hit) in hits.into_iter().enumerate() {
                    finish(i + k, hit);
                }
                i += PACKET;
            }
            let start = i;
            while i < rays.len() && !packet_at(i) {
                i += 1;
            }
            self.interleaved::<ANY>(tris, &rays[start..i], |j, hit| finish(start + j, hit));
        }
    }
}
