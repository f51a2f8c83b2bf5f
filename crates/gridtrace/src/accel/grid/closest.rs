//! The uniform grid's nearest-point query: its cells in growing Chebyshev shells around the
//! query point (`closest::shells`), with the proximity cloud doing for the search what it does
//! for rays:
//! - the point's cell's distance `d` says every cell within `d - 1` of it is empty, so the
//!   search starts at ring `d` (for a point in empty space, most of the work a plain shell
//!   search would do), which holds a triangle: after it the search is bounded by a true
//!   nearest distance (a bound from the ring's reach alone, `dist + 1` cell diagonals, is
//!   up to twice as far: a ball of up to eight times the cells);
//! - along a row of a ring, an empty cell's distance `k` says the `k - 1` cells after it are
//!   empty too, so the row jumps over them, as a ray does.

use glam::{UVec3, Vec3};

use super::Grid;
use super::proximity::FAR;
use crate::accel::TriAccel;
use crate::accel::binning::cell_margin;
use crate::accel::closest::shells::{Lattice, search};
use crate::accel::closest::{ClosestPoint, box_dist_sq, tri_box_within};
use crate::accel::simd::prefetch;

impl Grid {
    /// The search lattice: the grid's cells, with the margin they were filled with.
    fn closest_lattice(&self) -> Lattice {
        Lattice {
            min: self.bounds.min,
            cell: self.cell_size,
            dims: self.dims.as_ivec3().to_array(),
            margin: cell_margin(self.cell_size, self.bounds),
        }
    }

    /// The point of `tris` (the triangles the grid was built over) nearest to `p`: the answer
    /// of `closest_point_brute`, tie rule included (see `accel::closest`).
    pub fn closest_point(&self, tris: &[TriAccel], p: Vec3) -> ClosestPoint {
        if !p.is_finite() {
            return ClosestPoint::INVALID;
        }
        let mut best = ClosestPoint::NONE;
        let lat = self.closest_lattice();
        let start = self.cells[self.cell_index(UVec3::from_array(lat.cell_of(p).map(|x| x as u32)))];
        if start.dist == FAR {
            // No cell holds a triangle.
            return best;
        }
        // More than any row is long: a jump that far only ends the row.
        let jump_cap = self.dims.max_element().min(i32::MAX as u32);
        let prefetch = |c: [i32; 3]| {
            let i = self.cell_index(UVec3::from_array(c.map(|x| x as u32)));
            // Only an address, never read: an index out of range would be a useless hint.
            prefetch(self.cells.as_ptr().wrapping_add(i) as *const i8);
        };
        search(&lat, p, start.dist, &mut best, prefetch, |c, best| {
            let cell = self.cells[self.cell_index(UVec3::from_array(c.map(|x| x as u32)))];
            if cell.count == 0 {
                return cell.dist.min(jump_cap) as i32;
            }
            let (lo, hi) = lat.cell_box(c);
            if box_dist_sq(p, lo, hi) > best.dist_sq {
                return 1;
            }
            // A cell holds about ten triangles, most of them farther than the best so far
            // (and a triangle in several cells is met again): a box test drops them before
            // the full one (on the Stanford Bunny two thirds of the full tests go).
            for &tri in &self.refs[cell.start as usize..(cell.start + cell.count) as usize] {
                let t = &tris[tri as usize];
                if tri_box_within(t, p, best.dist_sq) {
                    best.offer(t, tri, p);
                }
            }
            1
        });
        best
    }
}
