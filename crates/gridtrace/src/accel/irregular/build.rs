//! The build, in five phases (`IrregularStats::PHASES`): the top grid's references (the
//! uniform grid's own pair generation), each top cell split by its reference count and its
//! cells merged inside it (one task per top cell), merging across top cells, expansion, and
//! the final arrays.

use crate::util::Instant;

use glam::{UVec3, Vec3};
use rayon::prelude::*;

use super::boxes::{Box16, VoxBox};
use super::merge::{Cells, MergeRule, Refs, TopCells, find};
use super::{IrrCell, IrregularGrid, IrregularParams, IrregularStats, LEVEL_BITS, MAX_LEVEL};
use crate::accel::binning::{
    candidate_cells, cell_margin, count_by_cell, grid_bounds, overlap_pairs, overlapping_cells, place_by_cell,
};
use crate::accel::resolution::auto_dims;
use crate::accel::{Aabb, TriAccel};
use crate::{Error, Result};

/// Top cells per axis at most (see `build`).
const MAX_TOP_PER_AXIS: u32 = 4096;
/// Probes of neighbouring cells one face of one cell may make in one expansion attempt: a
/// large face next to many small cells gives up rather than spend the build's time there (the
/// traversal is exact whatever the expansion).
const MAX_PROBES: u32 = 256;

pub(super) fn build(tris: &[TriAccel], params: IrregularParams) -> Result<IrregularGrid> {
    let mut phase_ms = [0.0; 5];
    let mut clock = Instant::now();
    let mut lap = |i: usize| {
        phase_ms[i] = clock.elapsed().as_secs_f64() * 1e3;
        clock = Instant::now();
    };

    let (top, pairs, top_start) = top_pairs(tris, params)?;
    lap(0);
    let lattice = Lattice::new(top, &top_start, params)?;
    let rule = MergeRule {
        voxel_dims: lattice.voxel_dims,
        voxel_size: lattice.voxel_size,
        alpha: params.merge_alpha as f64,
    };
    let survivors = split_top_cells(tris, &lattice, pairs, &top_start, params, &rule)?;
    lap(1);
    let merged = merge_across(&lattice, survivors, params, &rule);
    lap(2);
    let grown = expand(&lattice, &merged, params);
    lap(3);
    let Merged {
        voxel_map,
        partition,
        live,
        live_empty,
        boxes,
        refs_of,
        flat,
    } = merged;
    let (cells, refs) = final_arrays(&live, &refs_of, &flat, &grown)?;
    // The build's own arrays go before the entries are made (`memory.rs` counts on it).
    drop((refs_of, flat, grown, boxes, live_empty));
    let Lattice {
        bounds,
        top_dims,
        levels,
        begin,
        shift,
        voxel_size,
        n_init,
        ..
    } = lattice;
    let entries: Vec<u32> = (0..levels.len())
        .map(|t| (begin[t] as u32) << LEVEL_BITS | levels[t])
        .collect();
    lap(4);

    let stats = IrregularStats {
        triangles: tris.len(),
        top_dims: top_dims.to_array(),
        initial_cells: n_init,
        cells: cells.len() - 1,
        empty_cells: cells.windows(2).filter(|c| c[0].start == c[1].start).count(),
        references: refs.len(),
        max_level: shift,
        phase_ms,
    };
    Ok(IrregularGrid {
        bounds,
        top_dims,
        shift,
        voxel_size,
        inv_voxel_size: voxel_size.recip(),
        entries,
        voxel_map,
        cells,
        refs,
        partition,
        stats,
        params,
    })
}

/// Phase 1: the top grid, its (top cell, triangle) pairs as `cell << 32 | triangle` in cell
/// order, and each top cell's first pair (`n_top + 1` starts).
fn top_pairs(tris: &[TriAccel], params: IrregularParams) -> Result<(TopGrid, Vec<u64>, Vec<u32>)> {
    let top = TopGrid::new(tris, params)?;
    let top_size = top.bounds.extent() / top.top_dims.as_vec3();
    let pairs = overlap_pairs(tris, top.bounds, top.top_dims, cell_margin(top_size, top.bounds));
    let n_top = (top.top_dims.x * top.top_dims.y * top.top_dims.z) as usize;
    let mut top_start = vec![0u32; n_top + 1];
    for p in &pairs {
        top_start[(p >> 32) as usize + 1] += 1;
    }
    for i in 0..n_top {
        top_start[i + 1] += top_start[i];
    }
    Ok((top, pairs, top_start))
}

/// The two-level lattice: the top grid, each top cell's level (it is split into `2^level`
/// cells per axis, about `cell_density` cells per reference) and the virtual voxels all
/// levels are counted in.
struct Lattice {
    bounds: Aabb,
    top_dims: UVec3,
    levels: Vec<u32>,
    /// Each top cell's first second-level cell (cells counted over all top cells).
    begin: Vec<u64>,
    /// The deepest level: a top cell is `2^shift` voxels per axis.
    shift: u32,
    voxel_dims: UVec3,
    voxel_size: Vec3,
    /// Second-level cells in all.
    n_init: usize,
}

impl Lattice {
    fn new(top: TopGrid, top_start: &[u32], params: IrregularParams) -> Result<Lattice> {
        let n_top = top_start.len() - 1;
        let levels: Vec<u32> = (0..n_top)
            .map(|t| level_for(top_start[t + 1] - top_start[t], params.cell_density, top.max_shift))
            .collect();
        let shift = levels.iter().copied().max().unwrap_or(0);
        let voxel_dims = top.top_dims << shift;
        let voxel_size = top.bounds.extent() / voxel_dims.as_vec3();
        let mut begin = Vec::with_capacity(n_top);
        let mut n_init: u64 = 0;
        for &l in &levels {
            begin.push(n_init);
            n_init += 1u64 << (3 * l);
        }
        if n_init >= 1 << (32 - LEVEL_BITS) {
            return Err(Error::InvalidInput(format!(
                "irregular grid: {n_init} second-level cells; at most 2^{} can be addressed (lower the densities)",
                32 - LEVEL_BITS
            )));
        }
        Ok(Lattice {
            bounds: top.bounds,
            top_dims: top.top_dims,
            levels,
            begin,
            shift,
            voxel_dims,
            voxel_size,
            n_init: n_init as usize,
        })
    }

    fn top_coord(&self, t: usize) -> UVec3 {
        let (t, d) = (t as u32, self.top_dims);
        UVec3::new(t % d.x, (t / d.x) % d.y, t / (d.x * d.y))
    }

    /// The box of second-level cell `i` of top cell `t` (`i` counted within the top cell).
    fn cell_box(&self, t: usize, i: u32) -> VoxBox {
        let level = self.levels[t];
        let side = 1u32 << level;
        let cell_voxels = 1u32 << (self.shift - level);
        let local = UVec3::new(i & (side - 1), (i >> level) & (side - 1), i >> (2 * level));
        let min = (self.top_coord(t) << self.shift) + local * cell_voxels;
        [min, min + cell_voxels]
    }

    /// The second-level cell (its index before merging) that holds voxel `v`.
    #[inline]
    fn initial_at(&self, v: UVec3) -> u32 {
        let (shift, d) = (self.shift, self.top_dims);
        let top = v >> shift;
        let t = (top.x + d.x * (top.y + d.y * top.z)) as usize;
        let level = self.levels[t];
        self.begin[t] as u32 + in_top((v & UVec3::splat((1 << shift) - 1)) >> (shift - level), level)
    }
}

/// What phase 2 leaves: the cells that survived the merges inside their top cells, in one set
/// of arrays, and each second-level cell's survivor.
struct Survivors {
    boxes: Vec<Box16>,
    refs_of: Vec<Refs>,
    flat: Vec<u32>,
    survivor_of: Vec<u32>,
}

/// Phase 2: per top cell, on all cores, its cells' triangles, then the first part of phase
/// 3, the merge inside the top cell, on the task's own arrays while they are in the core's
/// cache. A top cell's cells form one dense array there, so a neighbour is a few bits of
/// arithmetic away, and most merges happen there (empty space, a triangle's run of cells):
/// the Stanford Bunny's 311,797 cells leave 86,254 survivors. Only the survivors leave the
/// task, so the build never holds a box or a reference set for every second-level cell.
fn split_top_cells(
    tris: &[TriAccel],
    lattice: &Lattice,
    pairs: Vec<u64>,
    top_start: &[u32],
    params: IrregularParams,
    rule: &MergeRule,
) -> Result<Survivors> {
    let n_top = lattice.levels.len();
    let top_cells: Vec<TopCells> = (0..n_top)
        .into_par_iter()
        .map(|t| {
            let tri_ids = pairs[top_start[t] as usize..top_start[t + 1] as usize]
                .iter()
                .map(|p| *p as u32);
            split_top_cell(tris, lattice, t, tri_ids, params, rule)
        })
        .collect();
    // Freed here, not at the end of the build (`memory.rs` counts on it).
    drop(pairs);
    gather(lattice, top_cells)
}

/// One top cell of phase 2: its second-level cells' triangles (the exact overlap test), and
/// the merges inside it.
fn split_top_cell(
    tris: &[TriAccel],
    lattice: &Lattice,
    t: usize,
    tri_ids: impl Iterator<Item = u32>,
    params: IrregularParams,
    rule: &MergeRule,
) -> TopCells {
    let (bounds, voxel_size, shift) = (lattice.bounds, lattice.voxel_size, lattice.shift);
    let level = lattice.levels[t];
    let side = 1u32 << level;
    let cell_voxels = 1u32 << (shift - level);
    let origin = lattice.top_coord(t) << shift;
    let n_cells = 1usize << (3 * level);
    let (counts, refs) = if level == 0 {
        let refs: Vec<u32> = tri_ids.collect();
        (vec![refs.len() as u32], refs)
    } else {
        let size = voxel_size * cell_voxels as f32;
        let inv_size = size.recip();
        let margin = cell_margin(size, bounds);
        let top_min = bounds.min + (origin.as_vec3()) * voxel_size;
        let center = |l: UVec3| bounds.min + (origin + l * cell_voxels).as_vec3() * voxel_size + size * 0.5;
        // The (cell, triangle) pairs in triangle order, as `cell << 32 | triangle`.
        let mut pairs_here: Vec<u64> = Vec::new();
        for tri in tri_ids {
            let verts = tris[tri as usize].vertices();
            let (c0, c1, margin) = candidate_cells(&tris[tri as usize], top_min, inv_size, UVec3::splat(side), margin);
            overlapping_cells(c0, c1, size * 0.5 + margin, verts, center, |l| {
                pairs_here.push((in_top(l, level) as u64) << 32 | tri as u64)
            });
        }
        // Sorted by cell (stable: triangles stay ascending within a cell).
        let pairs_here = std::slice::from_ref(&pairs_here);
        let counts = count_by_cell(pairs_here, n_cells);
        let refs = place_by_cell(pairs_here, &counts, |k| k as u32);
        (counts, refs)
    };
    let mut parent: Vec<u32> = (0..n_cells as u32).collect();
    let mut boxes: Vec<Box16> = (0..n_cells as u32)
        .map(|i| Box16::pack(lattice.cell_box(t, i)))
        .collect();
    let mut refs_of: Vec<Refs> = Refs::spans(&counts, 0).collect();
    drop(counts);
    if level > 0 {
        let top = lattice.top_coord(t);
        let local_at = |v: UVec3| in_top((v - origin) >> (shift - level), level);
        let mut cells = Cells {
            parent: &mut parent,
            boxes: &mut boxes,
            refs_of: &mut refs_of,
            flat: &refs,
        };
        for _ in 0..params.merge_passes {
            let mut merged = 0;
            for axis in 0..3 {
                merged += rule.merge_along(&mut cells, 0..n_cells as u32, axis, |_, v| {
                    (v[axis] >> shift == top[axis]).then(|| local_at(v))
                });
            }
            if merged == 0 {
                break;
            }
        }
    }
    TopCells::gather(parent, &boxes, &refs_of, &refs)
}

/// The survivors of all top cells in one set of arrays, and each initial cell's survivor.
fn gather(lattice: &Lattice, top_cells: Vec<TopCells>) -> Result<Survivors> {
    let mut first = Vec::with_capacity(top_cells.len());
    let (mut n_surv, mut n_refs) = (0usize, 0usize);
    for tc in &top_cells {
        first.push(n_surv as u32);
        n_surv += tc.boxes.len();
        n_refs += tc.refs.len();
    }
    // References are addressed with 32 bits (spans here, cell starts at the end): say so
    // before an offset could wrap.
    if n_refs > u32::MAX as usize {
        return Err(Error::InvalidInput(format!(
            "irregular grid: {n_refs} references do not fit 32-bit indices (lower the densities)"
        )));
    }
    let mut survivor_of = vec![0u32; lattice.n_init];
    {
        let mut parts = Vec::with_capacity(top_cells.len());
        let mut rest = survivor_of.as_mut_slice();
        for (t, tc) in top_cells.iter().enumerate() {
            let (mine, tail) = std::mem::take(&mut rest).split_at_mut(tc.rep.len());
            rest = tail;
            parts.push((first[t], &tc.rep, mine));
        }
        parts.into_par_iter().for_each(|(first, rep, out)| {
            for (o, &r) in out.iter_mut().zip(rep) {
                *o = first + r;
            }
        });
    }
    let mut boxes: Vec<Box16> = Vec::with_capacity(n_surv);
    let mut refs_of: Vec<Refs> = Vec::with_capacity(n_surv);
    let mut flat: Vec<u32> = Vec::with_capacity(n_refs);
    for tc in top_cells {
        boxes.extend_from_slice(&tc.boxes);
        refs_of.extend(Refs::spans(&tc.counts, flat.len() as u32));
        flat.extend_from_slice(&tc.refs);
    }
    Ok(Survivors {
        boxes,
        refs_of,
        flat,
        survivor_of,
    })
}

/// What phase 3 leaves: the final cells (`live`, indices of survivors), the voxel map to
/// them, their boxes before expansion and whether each is empty; the survivors' arrays still
/// held for phase 5.
struct Merged {
    voxel_map: Vec<u32>,
    partition: Vec<VoxBox>,
    live: Vec<u32>,
    /// Whether each final cell is empty, a byte each: the expansion asks it of cells all over
    /// the grid, and the reference sets are 24 bytes a cell to miss in.
    live_empty: Vec<bool>,
    boxes: Vec<Box16>,
    refs_of: Vec<Refs>,
    flat: Vec<u32>,
}

/// Phase 3: merging (its first part, inside each top cell, ran with phase 2). A cell absorbs
/// its neighbour across its upper face on one axis when the neighbour has the same extent on
/// the other two axes and the surface-area cost (`COST_STEP` + references, times area) of the
/// merged cell is at most `merge_alpha` times that of the two (`MergeRule`). Absorbed cells
/// point to their absorber (union-find): a cell is alive while it is its own root. Here,
/// across top cells, sequentially, over the survivors: the same rule, so a merge that crosses
/// a top cell's face is still made. The Stanford Bunny's 86,254 survivors become 77,267 cells
/// (one sweep over all 311,797 cells made 76,652, with 3% more steps per ray, in twice the
/// time: docs/benchmarks-history.md).
fn merge_across(lattice: &Lattice, survivors: Survivors, params: IrregularParams, rule: &MergeRule) -> Merged {
    let Survivors {
        mut boxes,
        mut refs_of,
        flat,
        survivor_of,
    } = survivors;
    let shift = lattice.shift;
    let n_surv = boxes.len();
    let top_mask = (1u32 << shift) - 1;
    let mut parent: Vec<u32> = (0..n_surv as u32).collect();
    // The cells still alive (roots), refreshed after each pass.
    let mut live: Vec<u32> = (0..n_surv as u32).collect();
    for _ in 0..params.merge_passes {
        let mut merged = 0usize;
        let mut cells = Cells {
            parent: &mut parent,
            boxes: &mut boxes,
            refs_of: &mut refs_of,
            flat: &flat,
        };
        for axis in 0..3 {
            merged += rule.merge_along(&mut cells, live.iter().copied(), axis, |mine, v| {
                // Only across a top cell's face, or from a cell that a merge here made larger
                // than a top cell: inside a top cell the first part tried every face (unless
                // it ran out of `merge_passes` while still merging) and what it found there
                // changes after it only through rare cascades (a neighbour that grew across
                // a face). Either way the filter can only miss a merge, never make a wrong
                // cell. Skips four in five probes on the Stanford Bunny.
                let on_face = v[axis] & top_mask == 0;
                let one_top = (mine[0] >> shift) == ((mine[1] - 1) >> shift);
                (on_face || !one_top).then(|| survivor_of[lattice.initial_at(v) as usize])
            });
        }
        live.retain(|&i| parent[i as usize] == i);
        if merged == 0 {
            break;
        }
    }
    // Every survivor's final cell, the final cells' indices, the voxel map, and the final
    // cells' own boxes. Each array is dropped as soon as the build is done with it
    // (`memory.rs` counts the arrays in this order).
    let root: Vec<u32> = (0..n_surv as u32).map(|i| find(&mut parent, i)).collect();
    drop(parent);
    let mut new_index = vec![u32::MAX; n_surv];
    for (k, &i) in live.iter().enumerate() {
        new_index[i as usize] = k as u32;
    }
    let voxel_map: Vec<u32> = survivor_of
        .par_iter()
        .map(|&s| new_index[root[s as usize] as usize])
        .collect();
    drop((new_index, root, survivor_of));
    let partition: Vec<VoxBox> = live.iter().map(|&i| boxes[i as usize].unpack()).collect();
    let live_empty: Vec<bool> = live
        .iter()
        .map(|&i| refs_of[i as usize].get(&flat).is_empty())
        .collect();
    Merged {
        voxel_map,
        partition,
        live,
        live_empty,
        boxes,
        refs_of,
        flat,
    }
}

/// Phase 4: expansion. Each cell's box grows across a face when every cell just beyond that
/// face (over the face's whole extent) is empty, by as far as the nearest of those cells
/// reaches. The cells it grows over are the unexpanded partition, so a grown box covers its
/// own cell and empty cells only.
fn expand(lattice: &Lattice, merged: &Merged, params: IrregularParams) -> Vec<VoxBox> {
    merged
        .partition
        .par_iter()
        .map(|&g| {
            let mut g = g;
            // Faces that can never grow, a bit each (axis * 2 + down).
            let mut stuck = 0u8;
            for _ in 0..params.expand_passes {
                for axis in 0..3 {
                    for (k, up) in [(2 * axis, true), (2 * axis + 1, false)] {
                        if stuck >> k & 1 == 0 && grow(lattice, merged, &mut g, axis, up) {
                            stuck |= 1 << k;
                        }
                    }
                }
                if stuck == 0x3f {
                    break;
                }
            }
            g
        })
        .collect()
}

/// Grows `g` across one face; true when that face can never grow: it lies on the grid's
/// boundary, or a non-empty cell lies just beyond it. The region beyond a face only widens as
/// the box grows on the other axes, so that cell stays in it and later passes need not probe
/// the face again (on the Stanford Bunny 69% of the probes were in faces that failed). A face
/// that gave up on `MAX_PROBES` is tried again.
fn grow(lattice: &Lattice, merged: &Merged, g: &mut VoxBox, axis: usize, up: bool) -> bool {
    let voxel_dims = lattice.voxel_dims;
    let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
    let plane = if up {
        if g[1][axis] >= voxel_dims[axis] {
            return true;
        }
        g[1][axis]
    } else {
        if g[0][axis] == 0 {
            return true;
        }
        g[0][axis] - 1
    };
    let mut depth = u32::MAX;
    let mut probes = 0;
    let mut z = g[0][c];
    while z < g[1][c] {
        let mut z_step = u32::MAX;
        let mut y = g[0][b];
        while y < g[1][b] {
            let mut v = UVec3::ZERO;
            v[axis] = plane;
            v[b] = y;
            v[c] = z;
            let n = merged.voxel_map[lattice.initial_at(v) as usize] as usize;
            if !merged.live_empty[n] {
                return true;
            }
            probes += 1;
            if probes > MAX_PROBES {
                return false;
            }
            let nb = merged.partition[n];
            depth = depth.min(if up {
                nb[1][axis] - plane
            } else {
                plane + 1 - nb[0][axis]
            });
            z_step = z_step.min(nb[1][c] - z);
            y = nb[1][b];
        }
        z += z_step;
    }
    if up {
        g[1][axis] += depth;
    } else {
        g[0][axis] -= depth;
    }
    false
}

/// Phase 5: the arrays the traversal reads: the cells (grown boxes, reference starts, and a
/// sentinel where the last cell's references end) and their references.
fn final_arrays(live: &[u32], refs_of: &[Refs], flat: &[u32], grown: &[VoxBox]) -> Result<(Vec<IrrCell>, Vec<u32>)> {
    let mut cells = Vec::with_capacity(live.len() + 1);
    let mut refs = Vec::with_capacity(live.iter().map(|&i| refs_of[i as usize].get(flat).len()).sum());
    for (k, &i) in live.iter().enumerate() {
        let r = refs_of[i as usize].get(flat);
        let g = grown[k];
        cells.push(IrrCell::new(g[0].to_array(), g[1].to_array(), refs.len() as u32));
        refs.extend_from_slice(r);
    }
    cells.push(IrrCell::new([0; 3], [0; 3], refs.len() as u32));
    if refs.len() > u32::MAX as usize {
        return Err(Error::InvalidInput(format!(
            "irregular grid: {} references do not fit 32-bit indices",
            refs.len()
        )));
    }
    Ok((cells, refs))
}

/// The top grid of a build: where it lies, its cells, and how many levels its cells may have.
pub(super) struct TopGrid {
    pub bounds: Aabb,
    pub top_dims: UVec3,
    pub max_shift: u32,
}

impl TopGrid {
    pub fn new(tris: &[TriAccel], params: IrregularParams) -> Result<TopGrid> {
        let bounds = grid_bounds(tris)?;
        // Cells store their boxes in 16-bit voxel coordinates (`IrrCell`): at most 4,096 top
        // cells per axis (a scene flat in two axes would otherwise put its whole budget on
        // one), and as many levels below them as keep the virtual grid under 2^16 voxels per
        // axis.
        let top_dims = auto_dims(bounds.extent(), tris.len(), params.top_density).min(UVec3::splat(MAX_TOP_PER_AXIS));
        let max_shift = (0..=MAX_LEVEL)
            .rev()
            .find(|&s| (top_dims.max_element() as u64) << s <= 0xffff)
            .unwrap_or(0);
        Ok(TopGrid {
            bounds,
            top_dims,
            max_shift,
        })
    }
}

/// Levels of a top cell with `n` references: about `cell_density` cells per reference (never
/// fewer levels for more references, which `memory.rs` relies on).
pub(super) fn level_for(n: u32, cell_density: f32, max_shift: u32) -> u32 {
    if n == 0 {
        return 0;
    }
    let per_axis = (cell_density as f64 * n as f64).cbrt();
    (per_axis.log2().round().max(0.0) as u32).min(max_shift)
}

/// The index within its top cell of the cell at `l` (cells counted within the top cell, x
/// fastest) in a top cell of `level` levels: the layout of the voxel map's entries, which
/// `cell_box` inverts and `IrregularGrid::slot` reads.
#[inline(always)]
fn in_top(l: UVec3, level: u32) -> u32 {
    l.x + (l.y << level) + (l.z << (2 * level))
}
