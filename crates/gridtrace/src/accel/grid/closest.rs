//! The uniform grid's nearest-point query: its cells in growing Chebyshev shells around the
//! query point (`closest::shells`), with the proximity cloud doing for the search what it does
//! for rays:
//! - the point's cell's distance `d` says every cell within `d - 1` of it is empty, so the
//!   search starts at ring `d` (for a point in empty space, most of the work a plain shell
//!   search would do);
//! - along a row of a ring, an empty cell's distance `k` says the `k - 1` cells after it are
//!   empty too, so the row jumps over them, as a ray does.

use glam::{UVec3, Vec3};

use super::Grid;
use super::proximity::FAR;
use crate::accel::TriAccel;
use crate::accel::binning::cell_margin;
use crate::accel::closest::shells::{Lattice, search};
use crate::accel::closest::{ClosestPoint, box_dist_sq};

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
        // Ring `start.dist` holds a non-empty cell: its triangles have a point in that cell's
        // (grown) box, no farther than the point's distance outside the grid plus the ring's
        // reach, `dist + 1` cells on every axis.
        let outside = lat.outside(p).length();
        let reach = outside + (start.dist as f32 + 1.0) * self.cell_size.length() + 2.0 * lat.margin.length();
        search(&lat, p, start.dist, reach * reach, &mut best, |c, best| {
            let cell = self.cells[self.cell_index(UVec3::from_array(c.map(|x| x as u32)))];
            if cell.count == 0 {
                return cell.dist.min(jump_cap) as i32;
            }
            let (lo, hi) = lat.cell_box(c);
            if box_dist_sq(p, lo, hi) > best.dist_sq {
                return 1;
            }
            for &tri in &self.refs[cell.start as usize..(cell.start + cell.count) as usize] {
                best.offer(&tris[tri as usize], tri, p);
            }
            1
        });
        best
    }
}
