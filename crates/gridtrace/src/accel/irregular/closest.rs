//! The irregular grid's nearest-point query, by its cells: its top grid is a uniform lattice,
//! searched in Chebyshev shells as the uniform grid's cells are (`closest::shells`); a top
//! cell is searched through its voxel-map entries (`2^level` per axis, each naming the merged
//! cell that covers it), row by row, each row clipped to the ball of the best distance so far.
//! A cell is opened only if its box is within that distance, and an entry naming the cell the
//! previous entry named is skipped (merged cells repeat along x).
//!
//! A merged cell that spans several top cells is met once per top cell: its box test repeats,
//! and its triangles are tested again where the box is near enough. That costs time, never
//! correctness. The top grid has no proximity cloud, so empty top cells are walked one by one
//! (there are few: about a tenth of a cell per triangle).
//!
//! The box tested is the cell's grown box (`IrrCell`), which contains its own box: a smaller
//! distance than the cell's own, so still a lower bound. The cells were filled with boxes grown
//! by `cell_margin` of a *voxel*; the top cells' lattice uses the larger margin of a top cell,
//! which is as conservative.

use glam::Vec3;

use super::{IrregularGrid, LEVEL_BITS};
use crate::accel::TriAccel;
use crate::accel::binning::cell_margin;
use crate::accel::closest::shells::{Lattice, search, slab_dist};
use crate::accel::closest::{ClosestPoint, box_dist_sq};

impl IrregularGrid {
    /// The point of `tris` (the triangles the grid was built over) nearest to `p`: the answer
    /// of `closest_point_brute`, tie rule included (see `accel::closest`).
    pub fn closest_point(&self, tris: &[TriAccel], p: Vec3) -> ClosestPoint {
        if !p.is_finite() {
            return ClosestPoint::INVALID;
        }
        let mut best = ClosestPoint::NONE;
        if self.refs.is_empty() {
            return best;
        }
        let top_cell = self.voxel_size * (1u32 << self.shift) as f32;
        let margin = cell_margin(top_cell, self.bounds);
        let lat = Lattice {
            min: self.bounds.min,
            cell: top_cell,
            dims: self.top_dims.as_ivec3().to_array(),
            margin,
        };
        let t = self.top_dims;
        search(
            &lat,
            p,
            0,
            &mut best,
            |_| {},
            |c, best| {
                let (lo, hi) = lat.cell_box(c);
                if box_dist_sq(p, lo, hi) > best.dist_sq {
                    return 1;
                }
                let entry = self.entries[(c[0] as u32 + t.x * (c[1] as u32 + t.y * c[2] as u32)) as usize];
                let level = entry & ((1 << LEVEL_BITS) - 1);
                let begin = (entry >> LEVEL_BITS) as usize;
                // The top cell's own lattice of 2^level cells per axis, walked row by row, each row
                // clipped to the best point's ball as it is when the row starts.
                let n = 1i32 << level;
                let sub = Lattice {
                    min: lo + margin,
                    cell: top_cell / n as f32,
                    dims: [n; 3],
                    margin,
                };
                for z in 0..n {
                    let dz = slab_dist(&sub, p, 2, z);
                    for y in 0..n {
                        let dy = slab_dist(&sub, p, 1, y);
                        let rest = best.dist_sq - dz * dz - dy * dy;
                        if rest.is_nan() || rest < 0.0 {
                            continue;
                        }
                        let half = rest.sqrt() + margin.x;
                        let x0 = sub.cell_of(Vec3::new(p.x - half, p.y, p.z))[0];
                        let x1 = sub.cell_of(Vec3::new(p.x + half, p.y, p.z))[0];
                        let row = begin + ((y << level) + (z << (2 * level))) as usize;
                        let mut previous = u32::MAX;
                        for &cell in &self.voxel_map[row + x0 as usize..=row + x1 as usize] {
                            // Merged cells repeat along the row.
                            if cell != previous {
                                previous = cell;
                                self.closest_offer_cell(tris, cell, p, margin, best);
                            }
                        }
                    }
                }
                1
            },
        );
        best
    }

    /// Offers the triangles of cell `c` to `best` if its grown box (widened by `margin`) is
    /// near enough to hold a better one.
    #[inline(always)]
    fn closest_offer_cell(&self, tris: &[TriAccel], c: u32, p: Vec3, margin: Vec3, best: &mut ClosestPoint) {
        let view = self.cell(c);
        if view.count == 0 {
            return;
        }
        let to_world = |v: [u32; 3]| self.bounds.min + Vec3::from_array(v.map(|x| x as f32)) * self.voxel_size;
        let (lo, hi) = (to_world(view.min) - margin, to_world(view.max) + margin);
        if box_dist_sq(p, lo, hi) > best.dist_sq {
            return;
        }
        for &tri in &self.refs[view.start as usize..(view.start + view.count) as usize] {
            best.offer(&tris[tri as usize], tri, p);
        }
    }
}
