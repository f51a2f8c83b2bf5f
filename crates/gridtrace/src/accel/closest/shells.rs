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
//! **Rounding.** Cells were filled with boxes grown by a margin (`binning::cell_margin`), so a
//! triangle's point within that margin of a face is referenced on both sides. Every bound and
//! cell box here is widened by the same margin: pruning is conservative, and whatever rounding
//! puts on the wrong side of a face by less than the margin is still visited. Pruning is
//! strict (`>`), so equally near triangles are all seen and the tie rule decides.
//!
//! **Only the ball.** Once a best point is known, only cells within the ball of that radius
//! around the query point can hold a nearer one: the search then walks the ball's rows along
//! x (each clipped to the ball as the best distance is when the row starts), not more rings.

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
/// how many cells the enumeration may advance along the row or column it is walking (1, or
/// more where it knows that many cells around this one are empty: a Chebyshev distance, which
/// holds along every axis). `prefetch(cell)` is told of cells a few rows ahead of their visit
/// (it may ask for their memory; it must not change what `visit` finds).
///
/// Two phases. Rings, until one holds a triangle: then the best distance bounds the search.
/// Then the cells of that ball outside the rings visited (or known empty), row by row along
/// x, nearest rows first, each row clipped to the ball as the best distance is when it starts
/// (rows the ball misses are skipped without reading a cell).
#[inline]
pub(crate) fn search(
    lat: &Lattice,
    p: Vec3,
    first_ring: u32,
    best: &mut ClosestPoint,
    prefetch: impl Fn([i32; 3]),
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
    // Phase one: whole rings until one holds a triangle.
    while r <= last_ring && !best.dist_sq.is_finite() {
        ring(lat, c, r, best, &mut visit);
        r += 1;
    }
    let bound = |best: &ClosestPoint| best.dist_sq;
    if r > last_ring || lower_bound(lat, p, c, r, out2) > bound(best) {
        return;
    }
    // Phase two: the ball, less the block of rings `0..r` already visited (or known empty).
    let done = r - 1;
    let reach = Vec3::splat(bound(best).sqrt()) + lat.margin;
    let (z0, z1) = (lat.cell_of(p - reach)[2], lat.cell_of(p + reach)[2]);
    let (y0, y1) = (lat.cell_of(p - reach)[1], lat.cell_of(p + reach)[1]);
    // Rows nearest first (outward from the point's cell in z, and in y within each slab):
    // the best distance shrinks early, and the clipping then drops the farther rows without
    // reading a cell (each row's first cell is a cache miss of its own).
    for z in outward(c[2], z0, z1) {
        let dz = slab_dist(lat, p, 2, z);
        if dz * dz > bound(best) {
            continue;
        }
        // Where the walks of row (y, z) start: outward from the point's cell, or from the
        // faces of the visited block for a row through it.
        let starts = |y: i32| {
            if (y - c[1]).abs() <= done && (z - c[2]).abs() <= done {
                (c[0] + done + 1, c[0] - done - 1)
            } else {
                (c[0], c[0] - 1)
            }
        };
        let ys = outward(c[1], y0, y1);
        // Each row's first cells are a cache miss of their own (a row is a few cells): they
        // are asked for `AHEAD` rows before their turn, so that several rows' misses overlap.
        for y in ys.clone().take(AHEAD) {
            let (right, left) = starts(y);
            prefetch([right.clamp(0, dims[0] - 1), y, z]);
            prefetch([left.clamp(0, dims[0] - 1), y, z]);
        }
        let mut ahead = ys.clone().skip(AHEAD);
        for y in ys {
            if let Some(y) = ahead.next() {
                let (right, left) = starts(y);
                prefetch([right.clamp(0, dims[0] - 1), y, z]);
                prefetch([left.clamp(0, dims[0] - 1), y, z]);
            }
            let dy = slab_dist(lat, p, 1, y);
            let yz = dz * dz + dy * dy;
            if yz > bound(best) {
                continue;
            }
            // Outward from the point along x, each side stopping where the ball (as it is now)
            // ends.
            let (x0, x1) = (0, dims[0] - 1);
            let (right, left) = starts(y);
            let mut walk = |from: i32, step: i32, best: &mut ClosestPoint| {
                let mut x = from;
                while (x0..=x1).contains(&x) {
                    let dx = slab_dist(lat, p, 0, x);
                    if dx * dx + yz > bound(best) {
                        break;
                    }
                    x += step * visit([x, y, z], best).max(1);
                }
            };
            walk(right, 1, best);
            walk(left, -1, best);
        }
    }
}

/// Rows of the ball whose first cells are asked for ahead of their walk.
const AHEAD: usize = 4;

/// `lo..=hi` from `c` outwards: `c, c + 1, c - 1, c + 2, ...` (those in range; `c` is
/// clamped into it).
fn outward(c: i32, lo: i32, hi: i32) -> impl Iterator<Item = i32> + Clone {
    let c = c.clamp(lo, hi);
    let span = (hi - c).max(c - lo);
    (0..=span)
        .flat_map(move |k| [c + k, c - k].into_iter().take(if k == 0 { 1 } else { 2 }))
        .filter(move |&v| (lo..=hi).contains(&v))
}

/// Visits cells `x0..=x1` of row `(y, z)`, advancing by what `visit` says.
#[inline(always)]
fn walk_x(
    y: i32,
    z: i32,
    x0: i32,
    x1: i32,
    best: &mut ClosestPoint,
    visit: &mut impl FnMut([i32; 3], &mut ClosestPoint) -> i32,
) {
    let mut x = x0;
    while x <= x1 {
        x += visit([x, y, z], best).max(1);
    }
}

/// Distance along axis `a` from `p` to the slab of cells `k` (grown by the margin; 0 inside).
#[inline(always)]
pub(crate) fn slab_dist(lat: &Lattice, p: Vec3, a: usize, k: i32) -> f32 {
    let lo = lat.min[a] + k as f32 * lat.cell[a] - lat.margin[a];
    let hi = lat.min[a] + (k + 1) as f32 * lat.cell[a] + lat.margin[a];
    (lo - p[a]).max(p[a] - hi).max(0.0)
}

/// A lower bound on the squared distance from `p` to any cell of ring `r` or beyond around
/// cell `c` (see the module notes); infinite when there is none.
fn lower_bound(lat: &Lattice, p: Vec3, c: [i32; 3], r: i32, out2: Vec3) -> f32 {
    if r == 0 {
        return out2.x + out2.y + out2.z;
    }
    let mut lower = f32::INFINITY;
    for a in 0..3 {
        let rest = out2[(a + 1) % 3] + out2[(a + 2) % 3];
        if c[a] - r >= 0 {
            // The low face of the visited block (rings below r) on axis a.
            let face = lat.min[a] + (c[a] - r + 1) as f32 * lat.cell[a];
            let d = (p[a] - face - lat.margin[a]).max(0.0);
            lower = lower.min(d * d + rest);
        }
        if c[a] + r < lat.dims[a] {
            let face = lat.min[a] + (c[a] + r) as f32 * lat.cell[a];
            let d = (face - p[a] - lat.margin[a]).max(0.0);
            lower = lower.min(d * d + rest);
        }
    }
    lower
}

/// Visits ring `r` around cell `c` (clipped to the lattice): its two z faces and two y faces
/// row by row along x, its two x faces column by column along y, each walk advancing by what
/// `visit` says.
fn ring(
    lat: &Lattice,
    c: [i32; 3],
    r: i32,
    best: &mut ClosestPoint,
    visit: &mut impl FnMut([i32; 3], &mut ClosestPoint) -> i32,
) {
    let dims = lat.dims;
    let lo = |a: usize, inset: i32| (c[a] - r + inset).max(0);
    let hi = |a: usize, inset: i32| (c[a] + r - inset).min(dims[a] - 1);
    let ok = |a: usize, k: i32| (0..dims[a]).contains(&k);
    // The z faces (whole squares), then the y faces (z inside), along x.
    let z_faces = if r == 0 { vec![c[2]] } else { vec![c[2] - r, c[2] + r] };
    for &z in z_faces.iter().filter(|&&z| ok(2, z)) {
        for y in lo(1, 0)..=hi(1, 0) {
            walk_x(y, z, lo(0, 0), hi(0, 0), best, visit);
        }
    }
    if r == 0 {
        return;
    }
    for z in lo(2, 1)..=hi(2, 1) {
        for y in [c[1] - r, c[1] + r].into_iter().filter(|&y| ok(1, y)) {
            walk_x(y, z, lo(0, 0), hi(0, 0), best, visit);
        }
        // The x faces (y and z inside), along y.
        for x in [c[0] - r, c[0] + r].into_iter().filter(|&x| ok(0, x)) {
            let mut y = lo(1, 1);
            while y <= hi(1, 1) {
                y += visit([x, y, z], best).max(1);
            }
        }
    }
}
