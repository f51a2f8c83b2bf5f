//! The nearest-point search of a uniform lattice of cells: cells in growing Chebyshev shells
//! ("rings") around the query point's cell, until no unvisited cell can hold anything nearer
//! than the best point found. The uniform grid searches its cells this way, the irregular grid
//! its top cells.
//!
//! **When to stop.** After rings `0..r` every unvisited cell lies in ring `r` or beyond: on
//! some axis `a` and side it is past the face of the visited block, at least
//! `(r - 1) * cell + (the point's distance to its own cell's face)` away along `a`. For a point
//! outside the lattice (the search starts from the cell nearest to it) the other two axes add
//! at least the point's distance outside the lattice on them. The smallest of these bounds over
//! the (up to six) sides that still have cells is a lower bound on the distance of anything
//! unvisited; once it exceeds the best distance the search is over. A side past the lattice's
//! edge has no cells and no bound; when no side has cells, everything has been visited.
//!
//! **Rounding.** Cells were filled with boxes grown by a margin (`grid::cell_margin`), so a
//! triangle's point within that margin of a face is referenced on both sides. Every bound and
//! cell box here is widened by the same margin: pruning is conservative, and whatever rounding
//! puts on the wrong side of a face by less than the margin is still visited. Pruning is
//! strict (`>`), so equally near triangles are all seen and the tie rule decides.
//!
//! **Only the sphere.** Once a best point is known, only cells within the box of its sphere
//! around the query point can hold a nearer one, so each ring is enumerated within that box
//! (which shrinks as the best improves), not whole.

use glam::Vec3;

use super::ClosestPoint;

/// A uniform lattice of cells: `dims` cells of size `cell` from `min`, filled with boxes grown
/// by `margin`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Lattice {
    pub min: Vec3,
    pub cell: Vec3,
    pub dims: [i32; 3],
    pub margin: Vec3,
}

impl Lattice {
    /// The lattice cell nearest to `p` (the one holding `p`, clamped into the lattice).
    #[inline]
    pub fn cell_of(&self, p: Vec3) -> [i32; 3] {
        // `as i32` saturates (and maps NaN to 0, though callers reject NaN points first).
        std::array::from_fn(|a| (((p[a] - self.min[a]) / self.cell[a]).floor() as i32).clamp(0, self.dims[a] - 1))
    }

    /// Cell `c`'s box, grown by the margin.
    #[inline(always)]
    pub fn cell_box(&self, c: [i32; 3]) -> (Vec3, Vec3) {
        let lo = self.min + Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) * self.cell;
        (lo - self.margin, lo + self.cell + self.margin)
    }
}

/// Searches `lat` for the point nearest to `p` (finite), into `best`: rings from `first_ring`
/// (rings below it must hold no triangles: the proximity cloud's distance says how many are
/// empty), `visit(cell, best)` for every cell that may hold something nearer. `visit` returns
/// how many cells along x the enumeration may advance (1, or more where it knows the cells
/// after this one are empty).
#[inline]
pub(crate) fn search(
    lat: &Lattice,
    p: Vec3,
    first_ring: u32,
    best: &mut ClosestPoint,
    mut visit: impl FnMut([i32; 3], &mut ClosestPoint) -> i32,
) {
    let dims = lat.dims;
    let max = lat.min + Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32) * lat.cell;
    let c = lat.cell_of(p);
    // How far outside the lattice the point is, per axis (0 inside), squared.
    let out = (lat.min - p).max(p - max).max(Vec3::ZERO);
    let out2 = out * out;
    // No ring is farther than the farthest lattice edge.
    let last_ring = (0..3).map(|a| c[a].max(dims[a] - 1 - c[a])).max().unwrap_or(0);
    let mut r = first_ring.min(i32::MAX as u32) as i32;
    while r <= last_ring {
        let lower = if r == 0 {
            out2.x + out2.y + out2.z
        } else {
            let mut lower = f32::INFINITY;
            for a in 0..3 {
                let rest = out2[(a + 1) % 3] + out2[(a + 2) % 3];
                if c[a] - r >= 0 {
                    // The low face of the visited block (rings below r) on axis a.
                    let face = lat.min[a] + (c[a] - r + 1) as f32 * lat.cell[a];
                    let d = (p[a] - face - lat.margin[a]).max(0.0);
                    lower = lower.min(d * d + rest);
                }
                if c[a] + r < dims[a] {
                    let face = lat.min[a] + (c[a] + r) as f32 * lat.cell[a];
                    let d = (face - p[a] - lat.margin[a]).max(0.0);
                    lower = lower.min(d * d + rest);
                }
            }
            lower
        };
        if lower > best.dist_sq {
            return;
        }
        // Ring r, within the box of the best point's sphere (all of it while there is none).
        let mut lo = [c[0] - r, c[1] - r, c[2] - r];
        let mut hi = [c[0] + r, c[1] + r, c[2] + r];
        if best.dist_sq.is_finite() {
            let reach = Vec3::splat(best.dist_sq.sqrt()) + lat.margin;
            let (a, b) = (lat.cell_of(p - reach), lat.cell_of(p + reach));
            for k in 0..3 {
                lo[k] = lo[k].max(a[k]);
                hi[k] = hi[k].min(b[k]);
            }
        }
        for k in 0..3 {
            lo[k] = lo[k].max(0);
            hi[k] = hi[k].min(dims[k] - 1);
        }
        for z in lo[2]..=hi[2] {
            let z_face = (z - c[2]).abs() == r;
            for y in lo[1]..=hi[1] {
                if z_face || (y - c[1]).abs() == r {
                    // A whole row of the ring's face.
                    let mut x = lo[0];
                    while x <= hi[0] {
                        x += visit([x, y, z], best).max(1);
                    }
                } else {
                    // Inside the ring's faces in y and z: only its two ends in x.
                    if c[0] - r >= lo[0] {
                        visit([c[0] - r, y, z], best);
                    }
                    if r > 0 && c[0] + r <= hi[0] {
                        visit([c[0] + r, y, z], best);
                    }
                }
            }
        }
        r += 1;
    }
}
