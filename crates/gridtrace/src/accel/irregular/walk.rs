//! The irregular grid's traversal: look up the cell under the ray, test its triangles, leave
//! its grown box in one step. `gpu/walks/irregular/irregular.wgsl` is the same walk, step for step.
//!
//! Why it terminates and misses nothing, in floating point:
//! - The next voxel is not found by evaluating the exit point and rounding (the point lies on
//!   a face and could round back into the cell just left, forever). On the exit axis it is the
//!   voxel just past the grown box's face, computed in integers; on the other two axes it is
//!   the exit point's voxel clamped into the box's range (the exact exit point is inside the
//!   box) and never behind the current voxel in the ray's direction (the ray moves
//!   monotonically along every axis). So each step moves the voxel strictly forward on one axis
//!   and never back on any: at most `sum(voxel dims)` steps. A step budget still bounds the
//!   loop, as in the DDA.
//! - Where rounding puts the ray one voxel off near a face, the cells there were filled with
//!   boxes grown by `cell_margin`, so a triangle that close to the face is in both cells.
//!
//! The walk is a `Cursor` moved one cell at a time, so that the batch queries can interleave
//! rays (`interleaved`) with the same arithmetic as the single-ray walk: their answers are
//! identical.

use glam::{Vec3, Vec4};

use super::{CellView, IrregularGrid, LEVEL_BITS};
use crate::accel::lattice::{min_position, sign};
use crate::accel::simd::prefetch;
use crate::accel::{Counters, Hit, Ray, TriAccel, TriAccel4};

/// Rays in flight in a batch: enough to cover the three dependent loads of a step (voxel map,
/// cell, references) and the triangles.
const LANES: usize = 8;

/// One ray's place in the grid.
#[derive(Debug, Clone, Copy)]
pub(super) struct Cursor {
    origin: [f32; 3],
    dir: Vec3,
    pub(super) inv: [f32; 3],
    pub(super) step: [i32; 3],
    /// The voxel the ray is in.
    pub(super) v: [i32; 3],
    pub(super) t_leave: f32,
    pub(super) budget: u32,
}

/// Where a lane of the batch walk is: what it asked memory for last.
#[derive(Debug, Clone, Copy)]
enum Stage {
    /// The voxel-map entry of the cursor's voxel (at this slot).
    Map(usize),
    /// The cell.
    Cell(u32),
    /// The cell's references (with the cell's exit distances).
    Refs(CellView, [f32; 3]),
    /// Their triangles.
    Tris(CellView, [f32; 3]),
}

/// One ray of the batch walk.
struct Lane {
    ray: usize,
    c: Cursor,
    best: Hit,
    stage: Stage,
}

impl IrregularGrid {
    /// The cursor at the ray's entry into the grid, or `None` if it misses the grid.
    #[inline(always)]
    pub(super) fn cursor(&self, ray: &Ray) -> Option<Cursor> {
        let (t_min, t_max) = (ray.t_min, ray.t_max);
        let inv_dir = ray.dir.recip();
        let (t_enter, t_leave) = self.bounds.clip(ray.origin, inv_dir, t_min, t_max)?;
        let dims = self.voxel_dims().as_ivec3().to_array();
        let p = self.world_to_voxel(ray.at(t_enter));
        Some(Cursor {
            origin: ray.origin.to_array(),
            dir: ray.dir,
            inv: inv_dir.to_array(),
            step: ray.dir.to_array().map(sign),
            v: std::array::from_fn(|a| p[a].clamp(0, dims[a] - 1)),
            t_leave,
            budget: (dims[0] + dims[1] + dims[2]) as u32 + 8,
        })
    }

    /// Truncation, not floor: the two differ only below zero, and every use clamps to a range
    /// of non-negative voxels. (`floor` is a libm call on baseline x86-64.)
    #[inline(always)]
    fn world_to_voxel(&self, p: Vec3) -> [i32; 3] {
        ((p - self.bounds.min) * self.inv_voxel_size).as_ivec3().to_array()
    }

    /// The voxel-map slot of voxel `v` (inside the grid).
    #[inline(always)]
    pub(super) fn slot(&self, v: [i32; 3]) -> usize {
        let s = self.shift;
        let t = self.top_dims;
        let top = [v[0] as u32 >> s, v[1] as u32 >> s, v[2] as u32 >> s];
        let entry = self.entries[(top[0] + t.x * (top[1] + t.y * top[2])) as usize];
        let level = entry & ((1 << LEVEL_BITS) - 1);
        let mask = (1u32 << s) - 1;
        let drop = s - level;
        let local = [v[0] as u32 & mask, v[1] as u32 & mask, v[2] as u32 & mask].map(|x| x >> drop);
        ((entry >> LEVEL_BITS) + local[0] + (local[1] << level) + (local[2] << (2 * level))) as usize
    }

    /// Where the ray leaves the cell's grown box on each axis: the parameter of the box's face
    /// ahead, from the integer plane index each time as the DDA does, so nothing accumulates
    /// (infinite on an axis the ray does not move along).
    #[inline(always)]
    fn face_t(&self, c: &Cursor, cell: &CellView) -> [f32; 3] {
        std::array::from_fn(|a| {
            if c.step[a] == 0 {
                f32::INFINITY
            } else {
                let k = if c.step[a] > 0 { cell.max[a] } else { cell.min[a] };
                (self.bounds.min[a] + k as f32 * self.voxel_size[a] - c.origin[a]) * c.inv[a]
            }
        })
    }

    /// Moves the cursor into the voxel just past the cell's exit face (see the module notes);
    /// false when the ray leaves the grid there (or the step budget is spent).
    #[inline(always)]
    fn advance(&self, c: &mut Cursor, cell: &CellView, t_faces: [f32; 3], t_exit: f32) -> bool {
        let dims = self.voxel_dims().as_ivec3().to_array();
        let axis = min_position(t_faces);
        let p = Ray::new(Vec3::from(c.origin), c.dir).at(t_exit);
        let at_exit = self.world_to_voxel(p);
        let mut next = c.v;
        for a in 0..3 {
            if a == axis {
                next[a] = if c.step[a] > 0 {
                    cell.max[a] as i32
                } else {
                    cell.min[a] as i32 - 1
                };
            } else if c.step[a] != 0 {
                let inside = at_exit[a].clamp(cell.min[a] as i32, cell.max[a] as i32 - 1);
                next[a] = if c.step[a] > 0 {
                    inside.max(c.v[a])
                } else {
                    inside.min(c.v[a])
                };
            }
        }
        if next[axis] < 0 || next[axis] >= dims[axis] {
            return false;
        }
        c.v = next;
        c.budget -= 1;
        c.budget > 0
    }

    /// Visits the non-empty cells along the ray within its interval, front to back, calling
    /// `visit(refs, t_cell_exit)` until it returns true.
    #[inline]
    pub fn walk<C: Counters>(&self, ray: &Ray, counters: &mut C, mut visit: impl FnMut(&[u32], f32, &mut C) -> bool) {
        let Some(mut c) = self.cursor(ray) else {
            return;
        };
        loop {
            counters.cell();
            let cell = self.cell(self.voxel_map[self.slot(c.v)]);
            let t_faces = self.face_t(&c, &cell);
            let t_exit = t_faces[0].min(t_faces[1]).min(t_faces[2]);
            if cell.count > 0 {
                let refs = &self.refs[cell.start as usize..(cell.start + cell.count) as usize];
                if visit(refs, t_exit.min(c.t_leave), counters) {
                    return;
                }
            }
            if t_exit >= c.t_leave || !self.advance(&mut c, &cell, t_faces, t_exit) {
                return;
            }
        }
    }

    /// Closest hits (`ANY = false`) or any hits of a batch, handed to `finish(i, hit)` for each
    /// `rays[i]` in no particular order: the same answers as `intersect`/`occluded`, ray by
    /// ray, faster on incoherent rays. `LANES` rays are walked at once, a stage of a step each
    /// in turn, and each stage prefetches what its ray reads next (the voxel-map entry, then
    /// the cell, then the references, then the triangles): incoherent rays wait on memory for
    /// most of their time, and by a lane's next turn its data has arrived. The BVH's batch
    /// query does the same (`BvhAccel::intersect_batch`).
    pub(crate) fn interleaved<const ANY: bool>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        mut finish: impl FnMut(usize, Hit),
    ) {
        let mut next = 0;
        // The next ray that enters the grid, as a lane; rays that miss the grid finish at once.
        let start = |next: &mut usize, finish: &mut dyn FnMut(usize, Hit)| -> Option<Lane> {
            while *next < rays.len() {
                let i = *next;
                *next += 1;
                if let Some(c) = self.cursor(&rays[i]) {
                    let slot = self.slot(c.v);
                    prefetch(self.voxel_map.as_ptr().wrapping_add(slot) as *const i8);
                    return Some(Lane {
                        ray: i,
                        c,
                        best: Hit {
                            t: rays[i].t_max,
                            ..Hit::MISS
                        },
                        stage: Stage::Map(slot),
                    });
                }
                finish(i, Hit::MISS);
            }
            None
        };
        let mut lanes: [Option<Lane>; LANES] = std::array::from_fn(|_| start(&mut next, &mut finish));
        let done = |l: &Lane| if l.best.is_hit() { l.best } else { Hit::MISS };
        while lanes.iter().any(Option::is_some) {
            for slot_of_lane in lanes.iter_mut() {
                let Some(l) = slot_of_lane else { continue };
                // Whether the ray is finished after this stage.
                let mut finished = false;
                match l.stage {
                    Stage::Map(slot) => {
                        let id = self.voxel_map[slot];
                        let at = self.cells.as_ptr().wrapping_add(id as usize) as *const i8;
                        // The 16-byte cell and the next one's start (where its references
                        // end): 32 bytes, which may straddle two lines.
                        prefetch(at);
                        prefetch(at.wrapping_add(31));
                        l.stage = Stage::Cell(id);
                    }
                    Stage::Cell(id) => {
                        let cell = self.cell(id);
                        let t_faces = self.face_t(&l.c, &cell);
                        if cell.count > 0 {
                            prefetch(self.refs.as_ptr().wrapping_add(cell.start as usize) as *const i8);
                            l.stage = Stage::Refs(cell, t_faces);
                        } else {
                            finished = !self.step_on(l, &cell, t_faces);
                        }
                    }
                    Stage::Refs(cell, t_faces) => {
                        for &tri in &self.refs[cell.start as usize..(cell.start + cell.count) as usize] {
                            let at = tris.as_ptr().wrapping_add(tri as usize) as *const i8;
                            prefetch(at);
                            prefetch(at.wrapping_add(std::mem::size_of::<TriAccel>() - 1));
                        }
                        l.stage = Stage::Tris(cell, t_faces);
                    }
                    Stage::Tris(cell, t_faces) => {
                        let t_exit = t_faces[0].min(t_faces[1]).min(t_faces[2]);
                        let o4 = l.c.origin.map(Vec4::splat);
                        let d4 = l.c.dir.to_array().map(Vec4::splat);
                        // Four triangles per test (`TriAccel4`, bit for bit the scalar test):
                        // the closest lane, the first on ties, is what the scalar loop keeps.
                        for chunk in self.refs[cell.start as usize..(cell.start + cell.count) as usize].chunks(4) {
                            let mut four: [TriAccel; 4] = bytemuck::Zeroable::zeroed();
                            for (f, &tri) in four.iter_mut().zip(chunk) {
                                *f = tris[tri as usize];
                            }
                            let ray = &rays[l.ray];
                            let t_far = if ANY { ray.t_max } else { l.best.t };
                            let hits = TriAccel4::pack(&four[..chunk.len()]).intersect(&o4, &d4, ray.t_min, t_far);
                            let mut mask = hits.mask();
                            while mask != 0 {
                                let k = mask.trailing_zeros() as usize;
                                mask &= mask - 1;
                                if hits.t[k] < l.best.t || ANY {
                                    l.best = hits.lane(k).on(chunk[k]);
                                }
                            }
                            if ANY && l.best.is_hit() {
                                break;
                            }
                        }
                        // As `intersect`: a hit is final inside the (grown) cell; any hit is.
                        finished = (l.best.is_hit() && (ANY || l.best.t <= t_exit.min(l.c.t_leave)))
                            || !self.step_on(l, &cell, t_faces);
                    }
                }
                if finished {
                    finish(l.ray, done(l));
                    *slot_of_lane = start(&mut next, &mut finish);
                }
            }
        }
    }

    /// After a cell: the lane moves to the next one and asks for its voxel-map entry; false
    /// when the ray is done.
    #[inline(always)]
    fn step_on(&self, l: &mut Lane, cell: &CellView, t_faces: [f32; 3]) -> bool {
        let t_exit = t_faces[0].min(t_faces[1]).min(t_faces[2]);
        if t_exit >= l.c.t_leave || !self.advance(&mut l.c, cell, t_faces, t_exit) {
            return false;
        }
        let slot = self.slot(l.c.v);
        prefetch(self.voxel_map.as_ptr().wrapping_add(slot) as *const i8);
        l.stage = Stage::Map(slot);
        true
    }
}
