//! The paper's traversal: Amanatides-Woo 3D-DDA through the grid, with optional proximity-cloud
//! jumps over empty space, and the closest-hit and any-hit queries on top of it.

use std::ops::ControlFlow;

use glam::{IVec3, Vec3};

use super::{Cell, Grid};
use crate::accel::lattice::{min_position, sign};
use crate::accel::triangle::{any_in, closest_in};
use crate::accel::{Counters, Hit, Ray, TriAccel};

/// Cells a proximity-cloud jump may cross at most, whatever the stored distance (far beyond any
/// grid: 2^26 cells in all, `MAX_CELLS`); keeps `k` and the cell arithmetic in range of i32.
/// The GPU walk takes it from the prelude.
pub const JUMP_CAP: u32 = 1 << 20;

/// How the DDA crosses empty cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stepping {
    /// One cell at a time (`AccelKind::Grid`).
    EveryCell,
    /// Out of the empty cube around an empty cell in one jump (`AccelKind::ProximityCloud`).
    ProximityJumps,
}

impl Grid {
    /// Closest hit in the ray's interval.
    pub fn intersect<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, stepping: Stepping, counters: &mut C) -> Hit {
        let mut best = Hit {
            t: ray.t_max,
            ..Hit::MISS
        };
        self.walk(ray, stepping, counters, |refs, t_cell_exit, counters| {
            closest_in(tris, refs, ray, &mut best, counters);
            // A hit beyond this cell's exit may be beaten by a triangle in a later cell; only a
            // hit inside the cell (or before it) is final.
            if best.tri != u32::MAX && best.t <= t_cell_exit {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        });
        if best.tri == u32::MAX { Hit::MISS } else { best }
    }

    /// Any hit in the ray's interval (shadow rays): stops at the first one found.
    pub fn occluded<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, stepping: Stepping, counters: &mut C) -> bool {
        let mut hit = false;
        self.walk(ray, stepping, counters, |refs, _, counters| {
            hit = any_in(tris, refs, ray, counters);
            if hit {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        });
        hit
    }

    /// Visits the non-empty cells pierced by the ray within its interval, front to back,
    /// calling `visit(refs, t_cell_exit)` until it breaks. Proximity jumps are taken for
    /// `Stepping::ProximityJumps` only.
    #[inline]
    pub fn walk<C: Counters>(
        &self,
        ray: &Ray,
        stepping: Stepping,
        counters: &mut C,
        mut visit: impl FnMut(&[u32], f32, &mut C) -> ControlFlow<()>,
    ) {
        let g = self.lattice();
        let Some(mut c) = g.cursor(ray) else {
            return;
        };
        loop {
            counters.cell();
            let (cell, t_exit) = g.look(self, &c);
            if cell.count > 0 {
                let refs = &self.refs[cell.start as usize..(cell.start + cell.count) as usize];
                if visit(refs, t_exit.min(c.t_leave), counters).is_break() {
                    return;
                }
            }
            if !g.advance(&mut c, &cell, t_exit, stepping, counters) {
                return;
            }
        }
    }
}

/// What the DDA needs of the grid's lattice, in the form its steps use: plain arrays, not glam
/// vectors, where a step indexes by a runtime axis (on a `Vec3` that is a three-way branch per
/// access), and the row strides. Taken once per walk or packet (`Grid::lattice`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Lattice {
    bounds: crate::accel::Aabb,
    inv_cell_size: Vec3,
    grid_min: [f32; 3],
    cell_size: [f32; 3],
    dims: [i32; 3],
    nx: usize,
    nxy: usize,
}

impl Grid {
    #[inline(always)]
    pub(super) fn lattice(&self) -> Lattice {
        let dims = self.dims.as_ivec3().to_array();
        Lattice {
            bounds: self.bounds,
            inv_cell_size: self.inv_cell_size,
            grid_min: self.bounds.min.to_array(),
            cell_size: self.cell_size.to_array(),
            dims,
            nx: dims[0] as usize,
            nxy: (dims[0] * dims[1]) as usize,
        }
    }
}

impl Lattice {
    /// The cursor at the ray's entry into the grid, or `None` if it misses the grid.
    ///
    /// Boundary distances are recomputed from the integer cell coordinate at every step
    /// (`t = (grid_min + k * cell_size - origin) / dir`) instead of accumulating `t_delta`, so
    /// they do not drift, and re-entering the DDA after a proximity jump is the same computation.
    #[inline(always)]
    pub(super) fn cursor(&self, ray: &Ray) -> Option<DdaCursor> {
        let inv_dir = ray.dir.recip();
        let (t_enter, t_leave) = self.bounds.clip(ray.origin, inv_dir, ray.t_min, ray.t_max)?;
        let dims = IVec3::from(self.dims);
        let step = [sign(ray.dir.x), sign(ray.dir.y), sign(ray.dir.z)];
        let mut c = DdaCursor {
            origin: ray.origin.to_array(),
            dir: ray.dir,
            inv: inv_dir.to_array(),
            step,
            // Offset of the boundary ahead of a cell: +1 cell when stepping up, 0 when down.
            ahead: step.map(|s| s.max(0)),
            cell: self
                .world_to_grid(ray.at(t_enter))
                .clamp(IVec3::ZERO, dims - 1)
                .to_array(),
            t_next: [0.0; 3],
            t_leave,
            // Every step moves at least one cell forward along some axis, so this bounds the
            // walk even if floating point misbehaves: never a hang.
            budget: (dims.x + dims.y + dims.z) as u32 * 2 + 8,
        };
        c.t_next = std::array::from_fn(|a| self.boundary_t(&c, a, c.cell[a] + c.ahead[a]));
        Some(c)
    }

    #[inline(always)]
    fn world_to_grid(&self, p: Vec3) -> IVec3 {
        ((p - self.bounds.min) * self.inv_cell_size).floor().as_ivec3()
    }

    /// The ray's parameter at the grid plane `k` across `axis` (infinite if it does not move
    /// along the axis).
    #[inline(always)]
    fn boundary_t(&self, c: &DdaCursor, axis: usize, k: i32) -> f32 {
        if c.step[axis] == 0 {
            f32::INFINITY
        } else {
            (self.grid_min[axis] + k as f32 * self.cell_size[axis] - c.origin[axis]) * c.inv[axis]
        }
    }

    /// The cursor's cell and where the ray leaves it.
    #[inline(always)]
    pub(super) fn look(&self, grid: &Grid, c: &DdaCursor) -> (Cell, f32) {
        let t_exit = c.t_next[0].min(c.t_next[1]).min(c.t_next[2]);
        let at = c.cell[0] as usize + self.nx * c.cell[1] as usize + self.nxy * c.cell[2] as usize;
        (grid.cells[at], t_exit)
    }

    /// Moves the cursor past `cell` (its current cell, which the ray leaves at `t_exit`): out
    /// of the empty cube around it in one jump where the proximity cloud allows, else into the
    /// next cell. False when the ray leaves the grid (or its range, or the step budget is spent).
    #[inline(always)]
    pub(super) fn advance<C: Counters>(
        &self,
        c: &mut DdaCursor,
        cell: &Cell,
        t_exit: f32,
        stepping: Stepping,
        counters: &mut C,
    ) -> bool {
        let dims = self.dims;
        // The structure first: for the plain grid this test is the same every step (predicted),
        // where whether a cell is empty is a coin toss.
        if stepping == Stepping::ProximityJumps && cell.count == 0 && cell.dist >= 2 {
            // The cube of cells within Chebyshev distance dist-1 is empty: leave it at once.
            let k = (cell.dist - 1).min(JUMP_CAP) as i32;
            let t_cube: [f32; 3] =
                std::array::from_fn(|a| self.boundary_t(c, a, c.cell[a] + c.ahead[a] + c.step[a] * k));
            let t_jump = t_cube[0].min(t_cube[1]).min(t_cube[2]);
            if t_jump >= c.t_leave {
                return false;
            }
            counters.jump();
            let axis = min_position(t_cube);
            // Land in the cell where the ray leaves the cube: the exit axis moves k+1 cells,
            // the others take the cell of the exit point, kept inside the cube's range
            // (rounding at a cube edge must not move the ray sideways out of it).
            let here = IVec3::from(c.cell);
            let at = Ray::new(Vec3::from(c.origin), c.dir).at(t_jump);
            let mut next = self.world_to_grid(at).clamp(here - k, here + k).to_array();
            next[axis] = c.cell[axis] + c.step[axis] * (k + 1);
            c.cell = next;
            if (0..3).any(|a| c.cell[a] < 0 || c.cell[a] >= dims[a]) {
                return false;
            }
            c.t_next = std::array::from_fn(|a| self.boundary_t(c, a, c.cell[a] + c.ahead[a]));
            c.budget = c.budget.saturating_sub(1);
            return c.budget != 0;
        }
        if t_exit >= c.t_leave {
            return false;
        }
        let axis = min_position(c.t_next);
        c.cell[axis] += c.step[axis];
        if c.cell[axis] < 0 || c.cell[axis] >= dims[axis] {
            return false;
        }
        c.t_next[axis] = self.boundary_t(c, axis, c.cell[axis] + c.ahead[axis]);
        c.budget -= 1;
        c.budget != 0
    }
}

/// One ray's place in the 3D-DDA, moved a cell (or a proximity jump) at a time by
/// `Lattice::advance`, so that a packet's rays can be walked interleaved (`packet.rs`).
#[derive(Debug, Clone, Copy)]
pub(super) struct DdaCursor {
    // Plain arrays, not glam vectors, where the walk indexes by a runtime axis: on a Vec3 that
    // is a three-way branch per access.
    origin: [f32; 3],
    dir: Vec3,
    inv: [f32; 3],
    step: [i32; 3],
    ahead: [i32; 3],
    /// The cell the ray is in.
    cell: [i32; 3],
    /// Where the ray crosses the next boundary ahead on each axis.
    t_next: [f32; 3],
    pub(super) t_leave: f32,
    budget: u32,
}
