//! Packets: up to four coherent rays (a 2x2 block of pixels' eye, shadow or mirror rays)
//! walked together, a ray per SIMD lane.
//!
//! Why: a single ray's step is one long chain of dependent operations (voxel -> top cell ->
//! voxel map -> cell -> exit distances -> exit point -> next voxel), about a hundred cycles of
//! latency that no other work fills, and the triangle tests are the smaller part of a ray's
//! cost (docs/benchmarks.md). Sharing only the cell and its triangle tests among the rays of a
//! round gained 6-10%; stepping them in four-lane arithmetic made packets 1.2-1.35x the single
//! rays (docs/benchmarks.md "Packets"): neighbouring camera rays cross the same large cells one
//! after another (3.5 of 4 rays take part in a round on the paper's scenes), so one chain of
//! four-lane operations advances them all, and one `TriAccel4` test (the triangle in every
//! lane, a ray per lane) tests a triangle against all of them.
//!
//! Each ray still goes through exactly the cells its single-ray walk (`walk.rs`) visits: a
//! round takes the cell of the first ray still walking, the rays whose current cell it is
//! take part, the others wait for a round of their own cell. Every lane computes what
//! `face_t` and `advance` compute for it: the same operations in the same order for the face
//! distances and the exit point, voxel coordinates as integers below 2^16 (exact in `f32`),
//! and the exit voxel clamped before it is truncated, with NaN taken to the box's low side,
//! which gives what the scalar saturating cast and clamp give. So the hits and the counts
//! (cells, triangle tests) are bit for bit those of `intersect`, ray by ray (tested).

use glam::{BVec4A, Vec4};

use super::IrregularGrid;
use crate::accel::{Counters, Hit, NoCounters, Ray, TriAccel, TriAccel4};
use crate::util::set_bits as bits;

/// Rays in a packet: the four lanes of `TriAccel4`.
pub const PACKET: usize = 4;

/// The rays of a packet and where they are, a ray per lane.
struct Lanes {
    origin: [Vec4; 3],
    dir: [Vec4; 3],
    inv: [Vec4; 3],
    /// Lanes whose ray moves up / down along each axis (neither: it does not move on it).
    up: [BVec4A; 3],
    down: [BVec4A; 3],
    /// The voxel each ray is in, as exact integers.
    v: [Vec4; 3],
    t_leave: Vec4,
    budget: [u32; PACKET],
}

/// `f32::min` lane by lane: a NaN gives way to the other operand, as there.
#[inline(always)]
fn min_lanes(a: Vec4, b: Vec4) -> Vec4 {
    Vec4::select(a.is_nan_mask(), b, Vec4::select(b.is_nan_mask() | !b.cmplt(a), a, b))
}

/// Lane `i` true where bit `i` of `mask` is set.
#[inline(always)]
fn mask_lanes(mask: u32) -> BVec4A {
    BVec4A::new(mask & 1 != 0, mask & 2 != 0, mask & 4 != 0, mask & 8 != 0)
}

impl IrregularGrid {
    /// Closest hits with `t_min < t < t_max` of up to `PACKET` rays (`rays.len()`), each
    /// counted into its own `counters[i]`: the same hits and counts as `intersect` ray by ray,
    /// faster when the rays are coherent. The hits past `rays.len()` are misses.
    pub fn intersect_packet<C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        self.walk_packet::<false, C>(tris, rays, t_min, [t_max; PACKET], counters)
    }

    /// Whether each of up to `PACKET` rays hits anything with `t_min < t < t_max[i]` (shadow
    /// rays towards a light, each with its own distance): the same answers and counts as
    /// `occluded` ray by ray. Past `rays.len()`: false.
    pub fn occluded_packet<C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        counters: &mut [C],
    ) -> [bool; PACKET] {
        self.walk_packet::<true, C>(tris, rays, t_min, t_max, counters)
            .map(|h| h.is_hit())
    }

    /// The packet walk compiled for AVX2 where the CPU has it (three-operand instructions, no
    /// register copies; the same bits, as the BVH's `interleaved` explains), else the baseline
    /// build.
    fn walk_packet<const ANY: bool, C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        #[cfg(target_arch = "x86_64")]
        if crate::accel::bvh::has_avx2() {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.walk_packet_avx2::<ANY, C>(tris, rays, t_min, t_max, counters) };
        }
        self.walk_packet_body::<ANY, C>(tris, rays, t_min, t_max, counters)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn walk_packet_avx2<const ANY: bool, C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        self.walk_packet_body::<ANY, C>(tris, rays, t_min, t_max, counters)
    }

    /// The packet walk: closest hits, or (`ANY`) any hit per ray, which ends that ray's walk
    /// and its tests at once, as `any_in` does.
    #[inline(always)]
    fn walk_packet_body<const ANY: bool, C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        assert!(
            rays.len() <= PACKET && counters.len() == rays.len(),
            "a packet is up to four rays, a counter each"
        );
        let mut best: [Hit; PACKET] = std::array::from_fn(|i| Hit {
            t: t_max[i],
            ..Hit::MISS
        });
        // Unused lanes hold a ray along +x at the origin and never walk.
        let mut l = Lanes {
            origin: [Vec4::ZERO; 3],
            dir: [Vec4::X, Vec4::ZERO, Vec4::ZERO],
            inv: [Vec4::ONE; 3],
            up: [BVec4A::default(); 3],
            down: [BVec4A::default(); 3],
            v: [Vec4::ZERO; 3],
            t_leave: Vec4::ZERO,
            budget: [0; PACKET],
        };
        // Each walking ray's current cell, and the rays still walking (bit i for rays[i]).
        let mut cell_of = [u32::MAX; PACKET];
        let mut walking = 0u32;
        for (i, ray) in rays.iter().enumerate() {
            for a in 0..3 {
                l.origin[a][i] = ray.origin[a];
                l.dir[a][i] = ray.dir[a];
            }
            if let Some(c) = self.cursor(ray, t_min, t_max[i]) {
                for a in 0..3 {
                    l.inv[a][i] = c.inv[a];
                    l.up[a].set(i, c.step[a] > 0);
                    l.down[a].set(i, c.step[a] < 0);
                    l.v[a][i] = c.v[a] as f32;
                }
                l.t_leave[i] = c.t_leave;
                l.budget[i] = c.budget;
                cell_of[i] = self.voxel_map[self.slot(c.v)];
                walking |= 1 << i;
            }
        }
        let bounds_min = self.bounds.min.to_array().map(Vec4::splat);
        let voxel_size = self.voxel_size.to_array().map(Vec4::splat);
        let inv_voxel_size = self.inv_voxel_size.to_array().map(Vec4::splat);
        let dims = self.voxel_dims().as_vec3().to_array().map(Vec4::splat);
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
            let lo = cell.min.map(|c| Vec4::splat(c as f32));
            let hi = cell.max.map(|c| Vec4::splat(c as f32));
            // `face_t`: the parameter of the grown box's face ahead on each axis.
            let t_faces: [Vec4; 3] = std::array::from_fn(|a| {
                let k = Vec4::select(l.up[a], hi[a], lo[a]);
                let t = (bounds_min[a] + k * voxel_size[a] - l.origin[a]) * l.inv[a];
                Vec4::select(l.up[a] | l.down[a], t, Vec4::INFINITY)
            });
            let t_exit = min_lanes(min_lanes(t_faces[0], t_faces[1]), t_faces[2]);
            let mut finished = 0u32;
            if cell.count > 0 {
                // A lane's tests reach up to its closest hit so far (`t_max` until one, and for
                // any hits, whose first hit ends them). Lanes outside the round test up to
                // `t_min`, which no hit passes (`t > t_min` and `t < t_min` cannot both hold),
                // so they keep their hits.
                let mut testing = round;
                let mut limit = Vec4::select(mask_lanes(round), t_of(&best), Vec4::splat(t_min));
                for &tri in &self.refs[cell.start as usize..(cell.start + cell.count) as usize] {
                    for i in bits(testing) {
                        counters[i].tri_test();
                    }
                    let h = TriAccel4::splat(&tris[tri as usize]).intersect_upto(&l.origin, &l.dir, t_min, limit);
                    for k in bits(h.mask() & testing) {
                        best[k] = h.lane(k).on(tri);
                        if ANY {
                            // As `any_in`: the first hit ends this ray's tests and its walk.
                            testing &= !(1 << k);
                            limit[k] = t_min;
                        } else {
                            // The test passed `t < limit[k]`, this ray's closest hit so far:
                            // as in `closest_in`, a later triangle replaces an earlier one
                            // only if nearer.
                            limit[k] = best[k].t;
                        }
                    }
                    if testing == 0 {
                        break;
                    }
                }
                // As `intersect`: a hit is final inside the (grown) cell, checked after a
                // non-empty cell.
                finished |= if ANY {
                    round & !testing
                } else {
                    bits_hit(&best) & t_of(&best).cmple(min_lanes(t_exit, l.t_leave)).bitmask()
                };
            }
            finished |= t_exit.cmpge(l.t_leave).bitmask();
            // `advance`: into the voxel just past the exit face (`walk.rs` says why so).
            let past1 = t_faces[1].cmplt(t_faces[0]);
            let nearer = Vec4::select(past1, t_faces[1], t_faces[0]);
            let past2 = t_faces[2].cmplt(nearer);
            let on_axis = [!(past1 | past2), past1 & !past2, past2];
            let mut next = l.v;
            let mut leaves = BVec4A::default();
            for a in 0..3 {
                let p = l.origin[a] + l.dir[a] * t_exit;
                // The exit point's voxel clamped into the box: clamping before truncating gives
                // what truncating (saturating, NaN to 0) then clamping does, NaN to `lo`.
                let x = (p - bounds_min[a]) * inv_voxel_size[a];
                let x = Vec4::select(x.is_nan_mask(), lo[a], x);
                let inside = Vec4::select(x.cmplt(lo[a]), lo[a], x);
                let inside = Vec4::select(inside.cmpgt(hi[a] - Vec4::ONE), hi[a] - Vec4::ONE, inside).trunc();
                let ahead = Vec4::select(l.up[a], inside.max(l.v[a]), inside.min(l.v[a]));
                let across = Vec4::select(l.up[a], hi[a], lo[a] - Vec4::ONE);
                next[a] = Vec4::select(on_axis[a], across, Vec4::select(l.up[a] | l.down[a], ahead, l.v[a]));
                leaves |= on_axis[a] & (across.cmplt(Vec4::ZERO) | across.cmpge(dims[a]));
            }
            finished |= leaves.bitmask();
            let moving = round & !finished;
            let move_lanes = mask_lanes(moving);
            for (v, next) in l.v.iter_mut().zip(next) {
                *v = Vec4::select(move_lanes, next, *v);
            }
            walking &= !(round & finished);
            for i in bits(moving) {
                l.budget[i] -= 1;
                if l.budget[i] == 0 {
                    walking &= !(1 << i);
                } else {
                    let v = [l.v[0][i] as i32, l.v[1][i] as i32, l.v[2][i] as i32];
                    cell_of[i] = self.voxel_map[self.slot(v)];
                }
            }
        }
        best.map(|h| if h.tri == u32::MAX { Hit::MISS } else { h })
    }
}

/// The hits' `t`, a lane each.
#[inline(always)]
fn t_of(best: &[Hit; PACKET]) -> Vec4 {
    Vec4::from_array(best.map(|h| h.t))
}

/// Bit `i` set where `best[i]` is a hit.
#[inline(always)]
fn bits_hit(best: &[Hit; PACKET]) -> u32 {
    best.iter()
        .enumerate()
        .fold(0, |m, (i, h)| m | (h.is_hit() as u32) << i)
}

/// Directions closer than this (cosine of about 1.1 degrees) count as coherent: neighbouring
/// pixels of a camera are a tenth of a degree apart at 512 pixels over 60 degrees, so four in
/// a row pass, and rays that merely share an origin (from a point in all directions) do not.
const COHERENT_COS: f32 = 0.9998;

impl IrregularGrid {
    /// Whether four rays will walk together: origins within one virtual voxel of the first's
    /// on every axis (one point for a camera's rays, neighbouring hit points for their shadow
    /// or mirror rays) and directions within about a degree. Such a packet mostly shares its
    /// cells; any other quad would walk apart and pay for the packet's bookkeeping. (The
    /// answers do not depend on it.)
    fn coherent(&self, quad: &[Ray]) -> bool {
        let (o, d) = (quad[0].origin, quad[0].dir);
        quad[1..].iter().all(|r| {
            (r.origin - o).abs().cmple(self.voxel_size).all()
                && r.dir.dot(d) >= COHERENT_COS * (r.dir.length() * d.length())
        })
    }

    /// Closest hits (`ANY = false`) or any hits of a batch, handed to `finish(i, hit)` for each
    /// `rays[i]` in no particular order, as `interleaved` does: runs of quads that walk
    /// together (`coherent`: an image's rays in row order from Python, their shadow rays
    /// towards a light) go as packets, the rest through the interleaved single-ray walk. The
    /// same answers either way.
    pub(crate) fn batch<const ANY: bool>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        mut finish: impl FnMut(usize, Hit),
    ) {
        let quad_at = |i: usize| i + PACKET <= rays.len() && self.coherent(&rays[i..i + PACKET]);
        let mut i = 0;
        while i < rays.len() {
            while quad_at(i) {
                let mut c = [NoCounters; PACKET];
                let hits = self.walk_packet::<ANY, _>(tris, &rays[i..i + PACKET], t_min, [t_max; PACKET], &mut c);
                for (k, hit) in hits.into_iter().enumerate() {
                    finish(i + k, hit);
                }
                i += PACKET;
            }
            let start = i;
            while i < rays.len() && !quad_at(i) {
                i += 1;
            }
            self.interleaved::<ANY>(tris, &rays[start..i], t_min, t_max, |j, hit| finish(start + j, hit));
        }
    }
}
