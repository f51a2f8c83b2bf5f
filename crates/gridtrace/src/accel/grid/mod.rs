//! The uniform grid: cells over the scene bounds, each with a (start, count) slice of one packed
//! triangle-reference list, plus the proximity-cloud distance. This is the paper's Figure 3
//! layout (its RGB texel per cell), kept as plain arrays that go to the GPU unchanged.

use crate::util::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{UVec3, Vec3};

mod closest;
pub mod dda;
mod packet;
pub mod proximity;
mod structure;

pub use dda::Stepping;
use proximity::chebyshev_distance_transform;

use crate::accel::binning::{
    cell_margin, count_by_cell, overlap_pairs_by_triangle, pad_bounds, place_by_cell, tri_bounds,
};
use crate::accel::resolution::{MAX_CELLS, Resolution, auto_dims};
use crate::accel::{Aabb, TriAccel};
use crate::{Error, Result};

/// One grid cell: 12 bytes, as the paper's RGB float texel, but integers.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct Cell {
    /// First index into `Grid::refs`.
    pub start: u32,
    /// Number of triangle references in this cell.
    pub count: u32,
    /// Chebyshev distance in cells to the nearest non-empty cell (0 if this one is non-empty;
    /// `proximity::FAR` if the grid has no non-empty cell at all).
    pub dist: u32,
}

/// Statistics of a built grid (the `info` command and the benchmarks print them).
#[derive(Debug, Clone, Default)]
pub struct GridStats {
    pub triangles: usize,
    pub dims: [u32; 3],
    pub cells: usize,
    pub empty_cells: usize,
    pub references: usize,
    pub build_ms: f64,
    pub max_refs_in_cell: u32,
}

impl GridStats {
    pub fn empty_fraction(&self) -> f64 {
        self.empty_cells as f64 / self.cells.max(1) as f64
    }
    pub fn refs_per_triangle(&self) -> f64 {
        self.references as f64 / self.triangles.max(1) as f64
    }
}

#[derive(Debug, Clone)]
pub struct Grid {
    /// Grid bounds in world space (scene bounds, slightly padded).
    pub bounds: Aabb,
    pub dims: UVec3,
    /// World-space size of one cell per axis.
    pub cell_size: Vec3,
    pub inv_cell_size: Vec3,
    /// `cells[x + dims.x * (y + dims.y * z)]`.
    pub cells: Vec<Cell>,
    /// Packed triangle indices, cell after cell, ascending within a cell.
    pub refs: Vec<u32>,
    pub stats: GridStats,
    /// The resolution it was asked for (an automatic one stays automatic, so a rebuild after
    /// the triangles move sizes the cells for the new bounds); `dims` is what it gave.
    pub resolution: Resolution,
    /// How its walks cross empty cells: the traversal it serves, `grid` (every cell) or `pc`
    /// (jumps). The two share every array, so switching is setting this (`Accel::set_traversal`).
    pub stepping: Stepping,
}

/// Where a grid's cells lie: everything about a grid but its contents. The CPU build
/// (`Grid::build`) and the GPU build (`gpu::GpuGridBuilder`) both start from this one value, so
/// both put every cell face at the same float and test the same cell boxes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridLattice {
    /// Grid bounds in world space (scene bounds, slightly padded).
    pub bounds: Aabb,
    pub dims: UVec3,
    /// World-space size of one cell per axis, and its reciprocal.
    pub cell_size: Vec3,
    pub inv_cell_size: Vec3,
    /// How much a cell box is grown before the overlap test (`cell_margin`).
    pub margin: Vec3,
}

impl GridLattice {
    /// The lattice a grid over `tris` at `resolution` has.
    pub fn new(tris: &[TriAccel], resolution: Resolution) -> Result<GridLattice> {
        let scene_bounds = tri_bounds(tris)?;
        let bounds = pad_bounds(scene_bounds);
        let dims = match resolution {
            Resolution::Auto { lambda } => auto_dims(scene_bounds.extent(), tris.len(), lambda),
            Resolution::Fixed(d) => {
                let cells = d.iter().map(|&x| x as u64).product::<u64>();
                if d.contains(&0) || cells > MAX_CELLS {
                    return Err(Error::InvalidInput(format!(
                        "grid {}x{}x{} has {cells} cells; allowed 1..={MAX_CELLS}",
                        d[0], d[1], d[2]
                    )));
                }
                UVec3::from(d)
            }
        };
        let cell_size = bounds.extent() / dims.as_vec3();
        // Cell boxes are tested slightly enlarged, so a triangle that touches a cell face within
        // rounding error is referenced from both cells. Traversal accepts a hit in a cell only
        // up to that cell's exit distance; a hit computed a hair beyond the face it truly lies
        // on is then found again in the next cell instead of being lost.
        let margin = cell_margin(cell_size, bounds);
        Ok(GridLattice {
            bounds,
            dims,
            cell_size,
            inv_cell_size: cell_size.recip(),
            margin,
        })
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        (self.dims.x as usize) * (self.dims.y as usize) * (self.dims.z as usize)
    }
}

impl Grid {
    /// Builds the grid over the given triangles. An empty triangle list gives a 1x1x1 empty grid.
    pub fn build(tris: &[TriAccel], resolution: Resolution) -> Result<Grid> {
        let t0 = Instant::now();
        let lattice = GridLattice::new(tris, resolution)?;
        Ok(Grid {
            resolution,
            ..Self::build_on(tris, lattice, t0)
        })
    }

    /// Builds the grid over `tris` on a given lattice (`GridLattice::new` over the same
    /// triangles); `t0` is when the build started, for `GridStats::build_ms`. Its `resolution`
    /// is the lattice's cell counts.
    pub fn build_on(tris: &[TriAccel], lattice: GridLattice, t0: Instant) -> Grid {
        let GridLattice {
            bounds,
            dims,
            cell_size,
            inv_cell_size,
            margin,
        } = lattice;
        let pairs = overlap_pairs_by_triangle(tris, bounds, dims, margin);
        let n_cells = (dims.x * dims.y * dims.z) as usize;
        let counts = count_by_cell(&pairs, n_cells);
        // The references are placed (one thread, random writes) while the proximity cloud,
        // which needs only the counts, is computed beside it: the Stanford Bunny's 1.3 ms
        // transform hid the 0.9 ms of placing and cells.
        let ((refs, mut cells), (occupied, dist)) = rayon::join(
            || {
                let refs = place_by_cell(&pairs, &counts, |k| k as u32);
                let mut start = 0u32;
                let cells: Vec<Cell> = counts
                    .iter()
                    .map(|&count| {
                        let c = Cell {
                            start,
                            count,
                            ..Cell::zeroed()
                        };
                        start += count;
                        c
                    })
                    .collect();
                (refs, cells)
            },
            || {
                let occupied: Vec<bool> = counts.iter().map(|&n| n > 0).collect();
                let dist = chebyshev_distance_transform(dims.to_array(), &occupied);
                (occupied, dist)
            },
        );
        for (c, d) in cells.iter_mut().zip(dist) {
            c.dist = d;
        }
        let stats = GridStats {
            triangles: tris.len(),
            dims: dims.to_array(),
            cells: n_cells,
            empty_cells: occupied.iter().filter(|o| !**o).count(),
            references: refs.len(),
            build_ms: t0.elapsed().as_secs_f64() * 1e3,
            max_refs_in_cell: cells.iter().map(|c| c.count).max().unwrap_or(0),
        };
        Grid {
            bounds,
            dims,
            cell_size,
            inv_cell_size,
            cells,
            refs,
            stats,
            resolution: Resolution::Fixed(dims.to_array()),
            stepping: Stepping::EveryCell,
        }
    }

    #[inline]
    pub fn cell_index(&self, c: UVec3) -> usize {
        (c.x + self.dims.x * (c.y + self.dims.y * c.z)) as usize
    }

    /// The references of one cell.
    pub fn cell_refs(&self, c: UVec3) -> &[u32] {
        let cell = self.cells[self.cell_index(c)];
        &self.refs[cell.start as usize..(cell.start + cell.count) as usize]
    }

    /// Bytes of the grid's own arrays (cells and references).
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.cells.as_slice()) + std::mem::size_of_val(self.refs.as_slice())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::tri_box::triangle_overlaps_box;

    #[test]
    fn references_cover_brute_force_overlap() {
        // Every (cell, triangle) pair whose exact overlap test passes on the unenlarged cell must
        // be referenced; nothing is referenced twice in a cell.
        let mut rng = crate::util::Rng::new(3);
        let tris: Vec<TriAccel> = (0..300)
            .map(|_| {
                let p = Vec3::new(rng.range(0.0, 10.0), rng.range(0.0, 10.0), rng.range(0.0, 10.0));
                let q = |r: &mut crate::util::Rng| {
                    p + Vec3::new(r.range(-2.0, 2.0), r.range(-2.0, 2.0), r.range(-2.0, 2.0))
                };
                TriAccel::new(p, q(&mut rng), q(&mut rng))
            })
            .collect();
        let g = Grid::build(&tris, Resolution::Fixed([7, 8, 9])).unwrap();
        for z in 0..9 {
            for y in 0..8 {
                for x in 0..7 {
                    let c = UVec3::new(x, y, z);
                    let refs = g.cell_refs(c);
                    assert!(refs.windows(2).all(|w| w[0] < w[1]));
                    let center = g.bounds.min + (c.as_vec3() + 0.5) * g.cell_size;
                    for (i, t) in tris.iter().enumerate() {
                        let [a, b, cc] = t.vertices();
                        if triangle_overlaps_box(center, g.cell_size * 0.5, a, b, cc) {
                            assert!(refs.contains(&(i as u32)), "cell {c} misses tri {i}");
                        }
                    }
                }
            }
        }
        assert!(g.stats.references >= 300);
    }
}
