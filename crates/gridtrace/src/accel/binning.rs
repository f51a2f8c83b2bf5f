//! Binning triangles into the cells of a lattice: the scene bounds every structure shares, the
//! cell candidates of a triangle, the exact overlap test four cells at a time, and the counting
//! sort of `cell << 32 | triangle` pairs. The uniform grid's build and the irregular grid's top
//! level and second-level cells all go through here (no structure borrows another's build).

use glam::{UVec3, Vec3};
use rayon::prelude::*;

use super::tri_box::triangle_overlaps_boxes4;
use super::triangle::slack_pad;
use super::{Aabb, TriAccel};
use crate::{Error, Result};

/// How much a cell box is grown before the overlap test: a thousandth of the cell, plus the
/// rounding of coordinates of the bounds' magnitude (see `Grid::build`).
pub(crate) fn cell_margin(cell_size: Vec3, bounds: Aabb) -> Vec3 {
    cell_size * 1e-3 + Vec3::splat(1e-6 * bounds.min.abs().max(bounds.max.abs()).max_element())
}

/// Every (cell, triangle) pair of a grid of `dims` cells over `bounds` whose cell box, grown by
/// `margin` (and at least the triangle test's slack, `slack_pad`), overlaps the triangle (exact
/// test, `triangle_overlaps_box`), as `cell << 32 | triangle`, sorted: cell after cell, and
/// ascending triangles within a cell. The uniform grid and the irregular grid's top level share
/// it.
pub(crate) fn overlap_pairs(tris: &[TriAccel], bounds: Aabb, dims: UVec3, margin: Vec3) -> Vec<u64> {
    let pairs = overlap_pairs_by_triangle(tris, bounds, dims, margin);
    let n_cells = (dims.x as usize) * (dims.y as usize) * (dims.z as usize);
    place_by_cell(&pairs, &count_by_cell(&pairs, n_cells), |k| k)
}

/// The pairs of `overlap_pairs` in triangle order (each triangle's cells in x, y, z order),
/// chunk by chunk: found on all cores, in the order a sequential loop would find them.
pub(crate) fn overlap_pairs_by_triangle(tris: &[TriAccel], bounds: Aabb, dims: UVec3, margin: Vec3) -> Vec<Vec<u64>> {
    /// Triangles per task: enough to amortise a task, few enough to balance two to many cores.
    const CHUNK: usize = 2048;
    let cell_size = bounds.extent() / dims.as_vec3();
    let inv_cell_size = cell_size.recip();
    tris.par_chunks(CHUNK)
        .enumerate()
        .map(|(chunk, tris)| {
            let mut out = Vec::with_capacity(tris.len() * 4);
            for (j, tri) in tris.iter().enumerate() {
                let i = chunk * CHUNK + j;
                let [a, b, c] = tri.vertices();
                let (c0, c1, margin) = candidate_cells(tri, bounds.min, inv_cell_size, dims, margin);
                let key = |cell: UVec3| {
                    let idx = cell.x as u64 + dims.x as u64 * (cell.y as u64 + dims.y as u64 * cell.z as u64);
                    idx << 32 | i as u64
                };
                if c1.cmpgt(c0).bitmask().count_ones() <= 1 {
                    // A range one cell thick on two axes (or a single cell) needs no test: the
                    // triangle's grown box lies inside the row's grown cross-section, and a
                    // triangle is connected, so it crosses every cell's slab along the row. In
                    // exact arithmetic every cell overlaps it; where rounding would make the
                    // exact test refuse a cell at the row's end by a hair, the extra reference
                    // costs one triangle test and misses nothing. This is 41% of the bunny's
                    // triangles and 27% of its candidate cells. The GPU build's `takes` agrees.
                    for z in c0.z..=c1.z {
                        for y in c0.y..=c1.y {
                            for x in c0.x..=c1.x {
                                out.push(key(UVec3::new(x, y, z)));
                            }
                        }
                    }
                    continue;
                }
                // The candidate cells through the exact test, pushed in x, y, z order.
                let half = cell_size * 0.5 + margin;
                let center = |cell: UVec3| bounds.min + cell.as_vec3() * cell_size + cell_size * 0.5;
                overlapping_cells(c0, c1, half, [a, b, c], center, |cell| out.push(key(cell)));
            }
            out
        })
        .collect()
}

/// The cells (inclusive range) a triangle may overlap in a grid of `dims` cells from `grid_min`
/// (the triangle's box grown by `margin`, at least its own `slack_pad`), and that margin.
#[inline(always)]
pub(crate) fn candidate_cells(
    tri: &TriAccel,
    grid_min: Vec3,
    inv_cell_size: Vec3,
    dims: UVec3,
    margin: Vec3,
) -> (UVec3, UVec3, Vec3) {
    let [a, b, c] = tri.vertices();
    // At least the triangle test's own slack (large triangles), else the cell margin.
    let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
    let margin = margin.max(Vec3::splat(slack_pad(lo, hi)));
    // The float-to-integer cast truncates, which equals `floor` (what the GPU build writes) on
    // the non-negative values left after `max`; `floor` itself is a libm call on baseline
    // x86-64 and was 5% of the build.
    let clamp = |p: Vec3| {
        ((p - grid_min) * inv_cell_size)
            .max(Vec3::ZERO)
            .as_uvec3()
            .min(dims - 1)
    };
    (clamp(lo - margin), clamp(hi + margin), margin)
}

/// Calls `take(cell)` for every cell of the candidate range `c0..=c1` (x fastest, then y, then
/// z) whose box, centred at `center(cell)` with half size `half`, overlaps the triangle: four
/// cells at a time through `triangle_overlaps_boxes4` (the scalar test's answers bit for bit).
/// The uniform grid's cells and the irregular grid's second-level cells both go through it.
#[inline(always)]
pub(crate) fn overlapping_cells(
    c0: UVec3,
    c1: UVec3,
    half: Vec3,
    [a, b, c]: [Vec3; 3],
    center: impl Fn(UVec3) -> Vec3,
    mut take: impl FnMut(UVec3),
) {
    let mut batch = [UVec3::ZERO; 4];
    let mut n = 0;
    let mut flush = |batch: &[UVec3; 4], n: usize| {
        let centers = std::array::from_fn(|k| center(batch[k.min(n - 1)]));
        let takes = triangle_overlaps_boxes4(centers, half, a, b, c).bitmask();
        for (k, &cell) in batch[..n].iter().enumerate() {
            if takes >> k & 1 == 1 {
                take(cell);
            }
        }
    };
    for z in c0.z..=c1.z {
        for y in c0.y..=c1.y {
            for x in c0.x..=c1.x {
                batch[n] = UVec3::new(x, y, z);
                n += 1;
                if n == 4 {
                    flush(&batch, n);
                    n = 0;
                }
            }
        }
    }
    if n > 0 {
        flush(&batch, n);
    }
}

/// A counting sort of `cell << 32 | item` pairs by cell, first half: the number of pairs per
/// cell. It replaces a comparison sort of the 64-bit keys: the key's histogram is the cells'
/// counts, which the grid needs anyway (the GPU build does the same).
pub(crate) fn count_by_cell(pairs: &[Vec<u64>], n_cells: usize) -> Vec<u32> {
    let mut counts = vec![0u32; n_cells];
    for k in pairs.iter().flatten() {
        counts[(k >> 32) as usize] += 1;
    }
    counts
}

/// Second half: `value(pair)` for every pair, cell after cell (`counts` from `count_by_cell`).
/// Stable, so items given in ascending order stay ascending within a cell. (Splitting the cells
/// among threads, each reading every pair, was measured slower on two cores: 8.0 against 7.2 ms
/// for the Bunny's whole build.)
pub(crate) fn place_by_cell<T: Copy + Default>(pairs: &[Vec<u64>], counts: &[u32], value: impl Fn(u64) -> T) -> Vec<T> {
    let mut cursor = Vec::with_capacity(counts.len());
    let mut at = 0u32;
    for &n in counts {
        cursor.push(at);
        at += n;
    }
    let mut out = vec![T::default(); at as usize];
    for &k in pairs.iter().flatten() {
        let c = &mut cursor[(k >> 32) as usize];
        out[*c as usize] = value(k);
        *c += 1;
    }
    out
}

/// Bounds of every triangle's slack-padded box (a unit box for no triangles).
pub(crate) fn tri_bounds(tris: &[TriAccel]) -> Result<Aabb> {
    // The bounds hold every triangle's slack-padded box: a hit the triangle test accepts a
    // hair outside a large triangle can lie outside the vertices' bounds (`SLACK_PAD`).
    // On all cores (min and max are exact, so any grouping gives the same box).
    let scene_bounds = tris
        .par_chunks(8192)
        .map(|chunk| {
            chunk.iter().fold(Aabb::EMPTY, |b, t| {
                let [a, bb, c] = t.vertices();
                let (lo, hi) = (a.min(bb).min(c), a.max(bb).max(c));
                let pad = slack_pad(lo, hi);
                b.grow(lo - pad).grow(hi + pad)
            })
        })
        .reduce(|| Aabb::EMPTY, Aabb::union);
    let scene_bounds = if scene_bounds.is_empty() {
        Aabb {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        }
    } else {
        scene_bounds
    };
    if !scene_bounds.min.is_finite() || !scene_bounds.max.is_finite() {
        return Err(Error::InvalidInput("triangle coordinates are not finite".into()));
    }
    Ok(scene_bounds)
}

/// The box a grid over `tris` covers (`Grid::bounds`), whatever its resolution: ray sets that
/// must be the same for every structure are drawn from it.
pub fn grid_bounds(tris: &[TriAccel]) -> Result<Aabb> {
    tri_bounds(tris).map(pad_bounds)
}

/// Pads the scene bounds a little on every axis: a flat scene gets a non-zero thickness (cell
/// sizes must be positive for the DDA), and hit points on the boundary are strictly inside.
pub(crate) fn pad_bounds(b: Aabb) -> Aabb {
    let e = b.extent();
    let scale = e
        .max_element()
        .max(b.min.abs().max(b.max.abs()).max_element() * 1e-3)
        .max(1e-30);
    let pad = Vec3::splat(scale * 1e-4) + e * 1e-5;
    Aabb {
        min: b.min - pad,
        max: b.max + pad,
    }
}
