//! The irregular grid's traversal: look up the cell under the ray, test its triangles, leave
//! its grown box in one step. `shaders/irregular.wgsl` is the same walk, step for step.
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

use glam::Vec3;

use super::IrregularGrid;
use crate::accel::grid::dda::{min_position, sign};
use crate::accel::{Counters, Ray};

impl IrregularGrid {
    /// Visits the non-empty cells along the ray within `[t_min, t_max]`, front to back, calling
    /// `visit(refs, t_cell_exit)` until it returns true.
    #[inline]
    pub fn walk<C: Counters>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        counters: &mut C,
        mut visit: impl FnMut(&[u32], f32, &mut C) -> bool,
    ) {
        let inv_dir = ray.dir.recip();
        let Some((t_enter, t_leave)) = self.bounds.clip(ray.origin, inv_dir, t_min, t_max) else {
            return;
        };
        let dims = self.voxel_dims().as_ivec3().to_array();
        let grid_min = self.bounds.min.to_array();
        let voxel = self.voxel_size.to_array();
        let inv_voxel = self.voxel_size.recip();
        let origin = ray.origin.to_array();
        let inv = inv_dir.to_array();
        let step = ray.dir.to_array().map(sign);
        let world_to_voxel = |p: Vec3| ((p - self.bounds.min) * inv_voxel).floor().as_ivec3().to_array();
        // The parameter where the ray crosses the voxel plane `k` of `axis`: from the integer
        // plane index each time, as the DDA does, so nothing accumulates.
        let plane_t = |axis: usize, k: u32| {
            if step[axis] == 0 {
                f32::INFINITY
            } else {
                (grid_min[axis] + k as f32 * voxel[axis] - origin[axis]) * inv[axis]
            }
        };
        let p = world_to_voxel(ray.at(t_enter));
        let mut v: [i32; 3] = std::array::from_fn(|a| p[a].clamp(0, dims[a] - 1));
        let mut budget = (dims[0] + dims[1] + dims[2]) as u32 + 8;
        loop {
            counters.cell();
            let cell = self.cells[self.cell_at(v.map(|x| x as u32)) as usize];
            // Leave through the face ahead on each axis.
            let face = |a: usize| if step[a] > 0 { cell.max[a] } else { cell.min[a] };
            let t_faces = [plane_t(0, face(0)), plane_t(1, face(1)), plane_t(2, face(2))];
            let t_exit = t_faces[0].min(t_faces[1]).min(t_faces[2]);
            if cell.count > 0 {
                let refs = &self.refs[cell.start as usize..(cell.start + cell.count) as usize];
                if visit(refs, t_exit.min(t_leave), counters) {
                    return;
                }
            }
            if t_exit >= t_leave {
                return;
            }
            let axis = min_position(t_faces);
            let at_exit = world_to_voxel(ray.at(t_exit));
            let mut next = v;
            for a in 0..3 {
                if a == axis {
                    next[a] = if step[a] > 0 {
                        cell.max[a] as i32
                    } else {
                        cell.min[a] as i32 - 1
                    };
                } else if step[a] != 0 {
                    let inside = at_exit[a].clamp(cell.min[a] as i32, cell.max[a] as i32 - 1);
                    next[a] = if step[a] > 0 {
                        inside.max(v[a])
                    } else {
                        inside.min(v[a])
                    };
                }
            }
            if next[axis] < 0 || next[axis] >= dims[axis] {
                return;
            }
            v = next;
            budget -= 1;
            if budget == 0 {
                return;
            }
        }
    }
}
