//! The paper's traversal: Amanatides-Woo 3D-DDA through the grid, with optional proximity-cloud
//! jumps over empty space, and the closest-hit and any-hit queries on top of it.

use std::ops::ControlFlow;

use glam::{IVec3, Vec3};

use super::{Cell, Grid};
use crate::accel::triangle::{any_in, closest_in};
use crate::accel::{Counters, Hit, Ray, TriAccel};

/// How the DDA crosses empty cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stepping {
    /// One cell at a time (`AccelKind::Grid`).
    EveryCell,
    /// Out of the empty cube around an empty cell in one jump (`AccelKind::ProximityCloud`).
    ProximityJumps,
}

impl Grid {
    /// Closest hit with `t_min < t < t_max`.
    pub fn intersect<C: Counters>(
        &self,
        tris: &[TriAccel],
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stepping: Stepping,
        counters: &mut C,
    ) -> Hit {
        let mut best = Hit { t: t_max, ..Hit::MISS };
        self.walk(ray, t_min, t_max, stepping, counters, |refs, t_cell_exit, counters| {
            closest_in(tris, refs, ray, t_min, &mut best, counters);
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

    /// Any hit with `t_min < t < t_max` (shadow rays): stops at the first one found.
    pub fn occluded<C: Counters>(
        &self,
        tris: &[TriAccel],
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stepping: Stepping,
        counters: &mut C,
    ) -> bool {
        let mut hit = false;
        self.walk(ray, t_min, t_max, stepping, counters, |refs, _, counters| {
            hit = any_in(tris, refs, ray, t_min, t_max, counters);
            if hit {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        });
        hit
    }

    /// Visits the non-empty cells pierced by the ray within `[t_min, t_max]`, front to back,
    /// calling `visit(refs, t_cell_exit)` until it breaks. Proximity jumps are taken for
    /// `Stepping::ProximityJumps` only.
    ///
    /// Boundary distances are recomputed from the integer cell coordinate at every step
    /// (`t = (grid_min + k * cell_size - origin) / dir`) instead of accumulating `t_delta`, so
    /// they do not drift, and re-entering the DDA after a proximity jump is the same computation.
    #[inline]
    pub fn walk<C: Counters>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stepping: Stepping,
        counters: &mut C,
        mut visit: impl FnMut(&[u32], f32, &mut C) -> ControlFlow<()>,
    ) {
        let g = self;
        let inv_dir = ray.dir.recip();
        let Some((t_enter, t_leave)) = g.bounds.clip(ray.origin, inv_dir, t_min, t_max) else {
            return;
        };
        // Plain arrays, not glam vectors: the loop indexes by a runtime axis, which on a Vec3
        // is a three-way branch per access.
        let dims = g.dims.as_ivec3().to_array();
        let grid_min = g.bounds.min.to_array();
        let cell_size = g.cell_size.to_array();
        let origin = ray.origin.to_array();
        let inv = inv_dir.to_array();
        let step = [sign(ray.dir.x), sign(ray.dir.y), sign(ray.dir.z)];
        // Offset of the boundary ahead of a cell: +1 cell when stepping up, 0 when stepping down.
        let ahead = step.map(|s| s.max(0));
        let world_to_grid = |p: Vec3| ((p - g.bounds.min) * g.inv_cell_size).floor().as_ivec3();
        let mut cell = world_to_grid(ray.at(t_enter))
            .clamp(IVec3::ZERO, IVec3::from(dims) - 1)
            .to_array();
        let boundary_t = |axis: usize, k: i32| {
            if step[axis] == 0 {
                f32::INFINITY
            } else {
                (grid_min[axis] + k as f32 * cell_size[axis] - origin[axis]) * inv[axis]
            }
        };
        let next_boundaries = |cell: &[i32; 3]| std::array::from_fn::<f32, 3, _>(|a| boundary_t(a, cell[a] + ahead[a]));
        let mut t_next = next_boundaries(&cell);
        let use_pc = stepping == Stepping::ProximityJumps;
        let (nx, nxy) = (dims[0] as usize, (dims[0] * dims[1]) as usize);
        // Every iteration moves at least one cell forward along some axis, so this bounds the
        // loop even if floating point misbehaves: never a hang.
        let mut budget = (dims[0] + dims[1] + dims[2]) as u32 * 2 + 8;
        loop {
            counters.cell();
            let t_exit = t_next[0].min(t_next[1]).min(t_next[2]);
            let Cell { start, count, dist } =
                g.cells[cell[0] as usize + nx * cell[1] as usize + nxy * cell[2] as usize];
            if count > 0 {
                let refs = &g.refs[start as usize..(start + count) as usize];
                if visit(refs, t_exit.min(t_leave), counters).is_break() {
                    return;
                }
            } else if use_pc && dist >= 2 {
                // The cube of cells within Chebyshev distance dist-1 is empty: leave it at once.
                let k = (dist - 1).min(1 << 20) as i32;
                let t_cube: [f32; 3] = std::array::from_fn(|a| boundary_t(a, cell[a] + ahead[a] + step[a] * k));
                let t_jump = t_cube[0].min(t_cube[1]).min(t_cube[2]);
                if t_jump >= t_leave {
                    return;
                }
                counters.jump();
                let axis = min_position(t_cube);
                // Land in the cell where the ray leaves the cube: the exit axis moves k+1 cells,
                // the others take the cell of the exit point, kept inside the cube's range
                // (rounding at a cube edge must not move the ray sideways out of it).
                let here = IVec3::from(cell);
                let mut next = world_to_grid(ray.at(t_jump)).clamp(here - k, here + k).to_array();
                next[axis] = cell[axis] + step[axis] * (k + 1);
                cell = next;
                if (0..3).any(|a| cell[a] < 0 || cell[a] >= dims[a]) {
                    return;
                }
                t_next = next_boundaries(&cell);
                budget = budget.saturating_sub(1);
                if budget == 0 {
                    return;
                }
                continue;
            }
            if t_exit >= t_leave {
                return;
            }
            let axis = min_position(t_next);
            cell[axis] += step[axis];
            if cell[axis] < 0 || cell[axis] >= dims[axis] {
                return;
            }
            t_next[axis] = boundary_t(axis, cell[axis] + ahead[axis]);
            budget -= 1;
            if budget == 0 {
                return;
            }
        }
    }
}

/// Index of the smallest element, the first on ties (glam's `min_position`; the WGSL
/// `min_position` in common.wgsl is the same).
#[inline(always)]
pub(crate) fn min_position(v: [f32; 3]) -> usize {
    let mut m = v[0];
    let mut i = 0;
    if v[1] < m {
        m = v[1];
        i = 1;
    }
    if v[2] < m {
        i = 2;
    }
    i
}

#[inline(always)]
pub(crate) fn sign(x: f32) -> i32 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}
