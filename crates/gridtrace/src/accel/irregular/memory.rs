//! What an irregular-grid build will take, known without running it: upper bounds on its arrays
//! (`MemoryBound`), from one cheap pass over the triangles' candidate cells, so a caller can
//! tell whether a mesh fits before a build spends its time (`gridtrace info` prints the bound
//! beside what its build made), and a test can hold the build to it
//! (`tests/irregular_memory.rs`, a counting allocator).
//!
//! Why these are bounds and not estimates:
//! - Top-level references: the build keeps a (top cell, triangle) pair only among the candidate
//!   cells of the triangle's grown box (`candidate_cells`, the same function), so their number
//!   bounds the pairs, overall and per top cell.
//! - Levels: `level_for` never gives fewer levels to more references, so the levels from the
//!   candidate counts bound the build's, and with them the second-level cells.
//! - Second-level references: per candidate (top cell, triangle), the candidate cells at the
//!   bounding level, of the triangle's box grown by the build's largest margin (the top cells',
//!   or the triangle's own slack) plus the top cells' margin once more. Finer cells and a wider
//!   box cover at least the cells of the build's range at its own level and margin. The extra
//!   margin (a thousandth of a top cell plus a millionth of the coordinates' magnitude) is what
//!   makes it hold in floating point too: the two ranges place their cells through different
//!   roundings (`top_min` and the reciprocal computed another way), errors of a few ulps of
//!   the coordinates, far below it.
//! - Merging only unites reference sets and expansion adds none, so the final references and
//!   cells are at most the second level's.
//! - The build's own arrays are listed phase by phase below with their element sizes and
//!   capacities (`build.rs` and `merge.rs` allocate them exactly so: `with_capacity`,
//!   `vec![..; n]`, exact collects); a `Vec` that grows by doubling is counted at three times its length (its last
//!   reallocation holds the old block and one twice as large). The peak is the largest phase.
//! - The second level runs a task per top cell whose working arrays live only while it runs,
//!   and a thread runs one task at a time (a task calls nothing that runs on the pool): the
//!   largest `rayon::current_num_threads()` tasks' working arrays are counted, so the bound is
//!   for a build in the same pool (as `gridtrace info` and the test build).

use glam::UVec3;

use super::boxes::Box16;
use super::build::{TopGrid, level_for};
use super::merge::Refs;
use super::{IrrCell, IrregularGrid, IrregularParams};
use crate::Result;
use crate::accel::TriAccel;
use crate::accel::binning::{candidate_cells, cell_margin};

/// Upper bounds on an irregular-grid build over given triangles and parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MemoryBound {
    pub top_cells: u64,
    /// (top cell, triangle) candidates: at least the top level's references.
    pub top_pairs: u64,
    /// Second-level cells at most (the cells after merging are fewer).
    pub initial_cells: u64,
    /// References at most, before and after merging.
    pub references: u64,
    /// Bytes of the arrays a ray reads (`IrregularGrid::bytes`) at most.
    pub structure_bytes: u64,
    /// Bytes the build holds at once at most (heap, its own allocations; the triangles are the
    /// caller's).
    pub build_peak_bytes: u64,
}

impl IrregularGrid {
    /// Upper bounds on what `build(tris, params)` will allocate and make (see the module
    /// notes); a pass over the triangles' candidate cells, a small part of a build's time.
    pub fn memory_bound(tris: &[TriAccel], params: IrregularParams) -> Result<MemoryBound> {
        params.check()?;
        let TopGrid {
            bounds,
            top_dims,
            max_shift,
        } = TopGrid::new(tris, params)?;
        let n_top = (top_dims.x as usize) * (top_dims.y as usize) * (top_dims.z as usize);
        let top_size = bounds.extent() / top_dims.as_vec3();
        let inv_top = top_size.recip();
        let top_margin = cell_margin(top_size, bounds);
        let mut candidates = vec![0u32; n_top];
        let mut top_pairs = 0u64;
        let index = |c: UVec3| (c.x + top_dims.x * (c.y + top_dims.y * c.z)) as usize;
        for tri in tris {
            let (c0, c1, _) = candidate_cells(tri, bounds.min, inv_top, top_dims, top_margin);
            for z in c0.z..=c1.z {
                for y in c0.y..=c1.y {
                    for x in c0.x..=c1.x {
                        let n = &mut candidates[index(UVec3::new(x, y, z))];
                        *n = n.saturating_add(1);
                        top_pairs += 1;
                    }
                }
            }
        }
        let levels: Vec<u32> = candidates
            .iter()
            .map(|&n| level_for(n, params.cell_density, max_shift))
            .collect();
        let initial_cells: u64 = levels.iter().map(|&l| 1u64 << (3 * l)).sum();
        let mut references = 0u64;
        // Per top cell, for the tasks' working memory (`account`).
        let mut refs_in = vec![0u64; n_top];
        for tri in tris {
            let (c0, c1, margin) = candidate_cells(tri, bounds.min, inv_top, top_dims, top_margin);
            let margin = margin + top_margin;
            for z in c0.z..=c1.z {
                for y in c0.y..=c1.y {
                    for x in c0.x..=c1.x {
                        let top = UVec3::new(x, y, z);
                        let level = levels[index(top)];
                        let r = if level == 0 {
                            1
                        } else {
                            let side = 1u32 << level;
                            let size = top_size / side as f32;
                            let top_min = bounds.min + top.as_vec3() * top_size;
                            let (s0, s1, _) = candidate_cells(tri, top_min, size.recip(), UVec3::splat(side), margin);
                            ((s1 - s0) + 1).as_u64vec3().element_product()
                        };
                        references += r;
                        refs_in[index(top)] += r;
                    }
                }
            }
        }
        // The second level's tasks hold their working arrays only while they run, one task a
        // thread at a time (a task calls nothing that runs on the pool): at most the largest
        // `threads` of them at once, in the pool the build will run in.
        let mut task_bytes: Vec<u64> = refs_in
            .iter()
            .zip(&levels)
            .map(|(&r, &l)| task_working_bytes(r, 1u64 << (3 * l)))
            .collect();
        let threads = rayon::current_num_threads().max(1);
        if task_bytes.len() > threads {
            task_bytes.select_nth_unstable_by(threads - 1, |a, b| b.cmp(a));
            task_bytes.truncate(threads);
        }
        Ok(account(
            tris.len() as u64,
            n_top as u64,
            top_pairs,
            initial_cells,
            references,
            task_bytes.iter().sum(),
        ))
    }
}

/// What one second-level task holds while it runs (`build.rs`, phase 2), beyond its output,
/// for a top cell with at most `r` references in `n` cells: a growing (cell, triangle) list
/// (doubled when full: three times its length), the counts, a cursor per cell, the
/// references; for the merge the parents, boxes and reference sets, the merged sets (at most
/// the task's references alive, as much again while a union is made); the survivors' new
/// indices.
fn task_working_bytes(r: u64, n: u64) -> u64 {
    let refs_enum = std::mem::size_of::<Refs>() as u64;
    let box16 = std::mem::size_of::<Box16>() as u64;
    24 * r + 4 * n + 4 * n + 4 * r + (4 + box16 + refs_enum) * n + 8 * r + 4 * n
}

/// The build's arrays, phase by phase (`build.rs`), from the bounds on their lengths (`i`
/// second-level cells, `r2` references; survivors and final cells are at most `i`, their
/// references at most `r2`), and `tasks`, the second-level tasks' working arrays.
fn account(n: u64, top: u64, p1: u64, i: u64, r2: u64, tasks: u64) -> MemoryBound {
    const CHUNK: u64 = 2048; // `overlap_pairs_by_triangle`'s triangles per task
    let refs_enum = std::mem::size_of::<Refs>() as u64;
    let cell = std::mem::size_of::<IrrCell>() as u64;
    let vox_box = 24u64; // [UVec3; 2]: the partition and the grown boxes
    let box16 = std::mem::size_of::<Box16>() as u64; // a box through merging
    // Phase 1, `overlap_pairs`: the per-chunk pair lists (capacity 4 per triangle, doubled
    // when full), their outer list, the counts and cursors per top cell, the sorted pairs.
    let chunks = n.div_ceil(CHUNK);
    let phase1 = 8 * (4 * n + 3 * p1) + 24 * chunks + 8 * top + 8 * p1;
    // Kept from phase 1: the pairs (until phase 2's cells are made) and the top cells' starts.
    let kept1 = 8 * p1 + 4 * (top + 1);
    // Phase 2: levels and begins; then per top cell a task that makes its cells' references,
    // merges them and gathers the survivors: `tasks`, the working arrays of the tasks that
    // can run at once (`task_working_bytes`), and every task's output, held to the end of
    // the phase (a survivor per cell, the survivors' boxes, counts and references, with 96
    // bytes of list headers).
    let levels = 4 * top + 8 * top;
    let outputs = 96 * top + 4 * i + box16 * i + 4 * i + 4 * r2;
    let phase2 = kept1 + levels + tasks + outputs;
    // Then every initial cell's survivor (filled through a list of the top cells' parts, 32
    // bytes each), and the survivors' boxes, reference sets and references in one array each
    // (made while the outputs are still held), the top cells' first survivors kept.
    let survivors = 4 * i + (box16 + refs_enum) * i + 4 * r2;
    let gathered = 4 * (top + 1) + levels + 4 * top + 32 * top + outputs + survivors;
    // Phase 3, across top cells: union-find parents, the live list, merged reference sets (as
    // in the tasks); at its end each survivor's root, new indices, the voxel map, the final
    // cells' boxes and a byte each saying whether it is empty, the parents, roots, new
    // indices and the initial cells' survivors dropped as soon as done with.
    let kept2 = 4 * (top + 1) + levels + 4 * top + survivors + 8 * r2;
    let merged = kept2 + 4 * i + 4 * i + 4 * i + 4 * i + 4 * i + vox_box * i + i;
    // Phases 4-5: the grown boxes, then the final cells (and sentinel) and references, the
    // top cells' entries; the build's own arrays are dropped before the entries are made. No
    // union is in progress any more: the merged sets alive are at most the references.
    let kept3 = kept2 - 4 * r2 + 4 * i + 4 * i + vox_box * i + i;
    let late = kept3 + vox_box * i + cell * (i + 1) + 4 * r2 + 4 * top;
    MemoryBound {
        top_cells: top,
        top_pairs: p1,
        initial_cells: i,
        references: r2,
        structure_bytes: 4 * top + 4 * i + cell * (i + 1) + 4 * r2,
        build_peak_bytes: phase1.max(phase2).max(gathered).max(merged).max(late),
    }
}
