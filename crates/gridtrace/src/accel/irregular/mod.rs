//! The irregular grid (Pérard-Gayot, Kalojanov, Slusallek 2017, "GPU Ray Tracing using
//! Irregular Grids"), implemented from the paper's description: the grid that follows a mesh's
//! density where a uniform grid cannot ("teapot in a stadium").
//!
//! It starts as a two-level grid (Kalojanov et al. 2011): a coarse uniform top grid, each top
//! cell split into `2^level` cells per axis by the number of triangles it holds. All cell
//! boundaries then lie on one fine *virtual* grid of `top_dims << shift` voxels. Then
//! - **merging** joins neighbouring cells with the same extent on the other two axes when the
//!   surface-area cost says the merged cell is no worse (cells with the same triangles always
//!   merge; empty space ends up in a few large boxes), and
//! - **expansion** grows each cell's box over the empty cells around it. The cells' own boxes
//!   still partition space; the grown boxes overlap only empty cells, so testing a cell's
//!   triangles is still exact inside its grown box.
//!
//! Traversal is no DDA: the ray looks up the cell under its current point (top cell, then the
//! voxel map of that top cell), tests the cell's triangles, and leaves through the grown box's
//! exit in one step (`walk.rs`). Large boxes mean few steps; a step is two dependent loads and a
//! 16-byte cell.

use glam::{UVec3, Vec3};

use bytemuck::{Pod, Zeroable};

use super::triangle::{any_in, closest_in};
use super::{Aabb, AccelParams, Counters, Hit, Ray, TriAccel};
use crate::{Error, Result};

mod boxes;
mod build;
mod closest;
mod memory;
mod merge;
mod packet;
mod structure;
#[cfg(test)]
mod tests;
mod walk;

pub use memory::MemoryBound;

/// Bits of one packed voxel coordinate of `IrrCell::bounds` (the GPU walk unpacks them with the
/// prelude's `IRR_COORD_BITS` and `IRR_COORD_MASK`).
pub const COORD_BITS: u32 = 16;
pub const COORD_MASK: u32 = (1 << COORD_BITS) - 1;

/// One cell as stored: its grown box in virtual voxels (`min` inclusive, `max` exclusive) as
/// six 16-bit coordinates, and the first of its references in `IrregularGrid::refs`; they end
/// where the next cell's begin (the cells' arrays end with a sentinel cell whose `start` is the
/// number of references). 16 bytes, one load on the GPU: half the 32 of a cell with 32-bit
/// coordinates and a count, which brought the structure from 71 to 54 bytes per triangle on the
/// Stanford Bunny (docs/benchmarks.md). Virtual grids are under 2^16 voxels per axis: the build
/// caps the top grid at 4,096 cells per axis and the levels below it to fit (`TopGrid::new`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct IrrCell {
    /// `min.x | min.y << 16`, `min.z | max.x << 16`, `max.y | max.z << 16`.
    pub bounds: [u32; 3],
    pub start: u32,
}

impl IrrCell {
    /// Packs a box (coordinates below 2^16, which the build checks) and a start.
    pub fn new(min: [u32; 3], max: [u32; 3], start: u32) -> IrrCell {
        debug_assert!(min.iter().chain(&max).all(|&c| c <= COORD_MASK));
        let s = COORD_BITS;
        IrrCell {
            bounds: [min[0] | min[1] << s, min[2] | max[0] << s, max[1] | max[2] << s],
            start,
        }
    }

    #[inline(always)]
    pub fn min(&self) -> [u32; 3] {
        let b = self.bounds;
        [b[0] & COORD_MASK, b[0] >> COORD_BITS, b[1] & COORD_MASK]
    }

    #[inline(always)]
    pub fn max(&self) -> [u32; 3] {
        let b = self.bounds;
        [b[1] >> COORD_BITS, b[2] & COORD_MASK, b[2] >> COORD_BITS]
    }
}

/// A cell unpacked for the walk: its grown box and its slice of the references.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellView {
    pub min: [u32; 3],
    pub max: [u32; 3],
    pub start: u32,
    pub count: u32,
}

/// Top cells are split into at most `2^MAX_LEVEL` cells per axis. Four levels (16^3 cells for a
/// top cell) is more than the default densities ask for on any of our meshes (the densest top
/// cell of the Stanford Bunny asks for 3). The build may use fewer where the top grid is large
/// (`TopGrid::new` keeps the virtual grid under 2^16 voxels per axis, for `IrrCell`).
pub const MAX_LEVEL: u32 = 4;
/// Bits of a top-cell entry that hold its level (`entry = begin << LEVEL_BITS | level`).
pub const LEVEL_BITS: u32 = 3;

/// The build's parameters (the paper's, with our defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IrregularParams {
    /// Top cells per triangle (the paper's lambda_1).
    pub top_density: f32,
    /// Second-level cells per triangle reference of a top cell (lambda_2).
    pub cell_density: f32,
    /// Two cells merge when the merged cell's cost is at most `merge_alpha` times the two's
    /// (cost: surface area times `COST_STEP` + references).
    pub merge_alpha: f32,
    /// Rounds of merging (each round tries x, y and z); it stops early when nothing merges.
    pub merge_passes: u32,
    /// Rounds of expansion (each tries the six faces of every cell).
    pub expand_passes: u32,
}

impl Default for IrregularParams {
    /// Measured on the Stanford Bunny, the bunny in a room and the knight (docs/benchmarks.md,
    /// "The irregular grid").
    fn default() -> Self {
        IrregularParams {
            top_density: 0.12,
            cell_density: 2.0,
            merge_alpha: 1.0,
            merge_passes: 8,
            expand_passes: 3,
        }
    }
}

impl IrregularParams {
    /// Checks the parameters: densities positive and finite, and not so large that the grid
    /// could not be addressed.
    pub fn check(&self) -> Result<()> {
        let ok = |x: f32, hi: f32| x.is_finite() && x > 0.0 && x <= hi;
        if !ok(self.top_density, 64.0) {
            return Err(Error::InvalidInput(format!(
                "irregular grid: top density must be in (0, 64] cells per triangle, got {}",
                self.top_density
            )));
        }
        if !ok(self.cell_density, 512.0) {
            return Err(Error::InvalidInput(format!(
                "irregular grid: cell density must be in (0, 512] cells per reference, got {}",
                self.cell_density
            )));
        }
        if !(self.merge_alpha.is_finite() && self.merge_alpha >= 0.0) {
            return Err(Error::InvalidInput(format!(
                "irregular grid: merge alpha must be a finite number >= 0, got {}",
                self.merge_alpha
            )));
        }
        if self.merge_passes > 64 || self.expand_passes > 64 {
            return Err(Error::InvalidInput(format!(
                "irregular grid: at most 64 merge and expansion passes, got {} and {}",
                self.merge_passes, self.expand_passes
            )));
        }
        Ok(())
    }
}

impl IrregularParams {
    /// The keys `--accel irregular:KEY=VALUE,...` takes, in the order `to_params` writes them.
    pub const KEYS: [&'static str; 5] = ["top", "cell", "alpha", "merge", "expand"];

    /// Reads the irregular grid's keys of `params` (any subset, in any order; the others keep
    /// their defaults) and checks the result.
    pub fn from_params(params: &AccelParams) -> Result<IrregularParams> {
        let mut p = IrregularParams::default();
        params.read("irregular", &Self::KEYS, |k, v| {
            let f = || v.parse::<f32>().map_err(|_| format!("bad number '{v}'"));
            let n = || v.parse::<u32>().map_err(|_| format!("bad count '{v}'"));
            match k {
                "top" => p.top_density = f()?,
                "cell" => p.cell_density = f()?,
                "alpha" => p.merge_alpha = f()?,
                "merge" => p.merge_passes = n()?,
                _ => p.expand_passes = n()?,
            }
            Ok(())
        })?;
        p.check()?;
        Ok(p)
    }

    /// The parameters that differ from the defaults, as `from_params` reads them.
    pub fn to_params(&self) -> AccelParams {
        let d = IrregularParams::default();
        let mut out = AccelParams::NONE;
        let floats = [
            ("top", self.top_density, d.top_density),
            ("cell", self.cell_density, d.cell_density),
            ("alpha", self.merge_alpha, d.merge_alpha),
        ];
        for (k, v, dv) in floats {
            if v != dv {
                out = out.with(k, v);
            }
        }
        for (k, v, dv) in [
            ("merge", self.merge_passes, d.merge_passes),
            ("expand", self.expand_passes, d.expand_passes),
        ] {
            if v != dv {
                out = out.with(k, v);
            }
        }
        out
    }
}

impl std::str::FromStr for IrregularParams {
    type Err = String;
    /// `top=0.12,cell=2,alpha=1,merge=8,expand=3`, any subset, in any order.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        IrregularParams::from_params(&s.parse()?).map_err(|e| e.to_string())
    }
}

/// What a build made and how long each phase took (`gridtrace info` prints it).
#[derive(Debug, Clone, Default)]
pub struct IrregularStats {
    pub triangles: usize,
    pub top_dims: [u32; 3],
    /// Cells of the two-level grid before merging.
    pub initial_cells: usize,
    /// Cells after merging (what the traversal steps through).
    pub cells: usize,
    pub empty_cells: usize,
    pub references: usize,
    pub max_level: u32,
    /// Milliseconds per phase: top level, second level (with the merge inside each top cell,
    /// which runs in the same task per top cell), merge (across top cells, and the voxel
    /// map), expansion, final arrays.
    pub phase_ms: [f64; 5],
}

impl IrregularStats {
    pub const PHASES: [&'static str; 5] = ["top level", "second level", "merge", "expand", "arrays"];
    pub fn build_ms(&self) -> f64 {
        self.phase_ms.iter().sum()
    }
    pub fn refs_per_triangle(&self) -> f64 {
        self.references as f64 / self.triangles.max(1) as f64
    }
}

/// The irregular grid over a set of triangles (which it does not own: queries take them).
#[derive(Debug, Clone)]
pub struct IrregularGrid {
    /// World-space box of the virtual grid (the uniform grid's bounds over the same triangles).
    pub bounds: Aabb,
    pub top_dims: UVec3,
    /// Levels of the finest top cell: the virtual grid has `top_dims << shift` voxels.
    pub shift: u32,
    /// World-space size of one virtual voxel per axis, and its reciprocal (the walk multiplies
    /// by it; the GPU gets the same value).
    pub voxel_size: Vec3,
    pub inv_voxel_size: Vec3,
    /// One per top cell, x fastest: `begin << LEVEL_BITS | level`; the top cell's
    /// `8^level` voxel-map entries start at `begin`.
    pub entries: Vec<u32>,
    /// Cell index of each second-level cell of the two-level grid (merged cells appear many
    /// times).
    pub voxel_map: Vec<u32>,
    /// The cells, then a sentinel (`start` = number of references; no voxel maps to it).
    pub cells: Vec<IrrCell>,
    /// Packed triangle indices, cell after cell, ascending within a cell.
    pub refs: Vec<u32>,
    /// Each cell's own box (`min`, `max` in voxels) before expansion: these partition the
    /// virtual grid. Kept for checks and statistics; the traversal reads the grown boxes only.
    pub partition: Vec<[UVec3; 2]>,
    pub stats: IrregularStats,
    /// What it was built with (a rebuild after the triangles move uses them again).
    pub params: IrregularParams,
}

impl IrregularGrid {
    /// Builds the grid over `tris` (in parallel). No triangles give one empty cell.
    pub fn build(tris: &[TriAccel], params: IrregularParams) -> Result<IrregularGrid> {
        params.check()?;
        build::build(tris, params)
    }

    /// Virtual voxels per axis.
    pub fn voxel_dims(&self) -> UVec3 {
        self.top_dims << self.shift
    }

    /// The index of the cell that holds voxel `v` (which must be inside the grid).
    pub fn cell_at(&self, v: [u32; 3]) -> u32 {
        self.voxel_map[self.slot(v.map(|x| x as i32))]
    }

    /// Cells (not counting the sentinel at the end of `cells`).
    pub fn cell_count(&self) -> usize {
        self.cells.len() - 1
    }

    /// Cell `c` unpacked (`c < cell_count()`).
    #[inline(always)]
    pub fn cell(&self, c: u32) -> CellView {
        let cell = self.cells[c as usize];
        let end = self.cells[c as usize + 1].start;
        CellView {
            min: cell.min(),
            max: cell.max(),
            start: cell.start,
            count: end - cell.start,
        }
    }

    /// The references of cell `c`.
    pub fn cell_refs(&self, c: u32) -> &[u32] {
        let cell = self.cell(c);
        &self.refs[cell.start as usize..(cell.start + cell.count) as usize]
    }

    /// Bytes of the arrays a ray reads: entries, voxel map, cells, references.
    pub fn bytes(&self) -> usize {
        self.memory().iter().map(|(_, b)| b).sum()
    }

    /// Bytes of each array a ray reads.
    pub fn memory(&self) -> Vec<(&'static str, usize)> {
        vec![
            ("entries", std::mem::size_of_val(self.entries.as_slice())),
            ("voxel map", std::mem::size_of_val(self.voxel_map.as_slice())),
            ("cells", std::mem::size_of_val(self.cells.as_slice())),
            ("refs", std::mem::size_of_val(self.refs.as_slice())),
        ]
    }

    /// Closest hit in the ray's interval.
    pub fn intersect<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> Hit {
        let mut best = Hit {
            t: ray.t_max,
            ..Hit::MISS
        };
        self.walk(ray, counters, |refs, t_cell_exit, counters| {
            closest_in(tris, refs, ray, &mut best, counters);
            // As in the uniform grid: a hit is final only inside the (grown) cell.
            best.tri != u32::MAX && best.t <= t_cell_exit
        });
        if best.tri == u32::MAX { Hit::MISS } else { best }
    }

    /// Any hit in the ray's interval.
    pub fn occluded<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> bool {
        let mut hit = false;
        self.walk(ray, counters, |refs, _, counters| {
            hit = any_in(tris, refs, ray, counters);
            hit
        });
        hit
    }
}
