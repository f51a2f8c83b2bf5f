//! The uniform grid: cells over the scene bounds, each with a (start, count) slice of one packed
//! triangle-reference list, plus the proximity-cloud distance. This is the paper's Figure 3
//! layout (its RGB texel per cell), kept as plain arrays that go to the GPU unchanged.

use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{UVec3, Vec3};
use rayon::prelude::*;

mod closest;
pub mod dda;
mod packet;
pub mod proximity;
pub mod tri_box;

pub use dda::Stepping;
use proximity::chebyshev_distance_transform;
use tri_box::triangle_overlaps_boxes4;

use crate::accel::triangle::slack_pad;
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

/// Default cells per triangle for the automatic resolution. Measured on the paper's scenes and
/// the Stanford bunny with `gridtrace bench --sweep-grid` (see docs/benchmarks.md): times are
/// flat within a few percent between 2 and 8; 4 is near the best for dense and sparse scenes.
pub const DEFAULT_LAMBDA: f32 = 4.0;

/// Upper bound on the number of cells; 2^26 cells are 768 MiB of cell data alone.
pub const MAX_CELLS: u64 = 1 << 26;

/// How the grid resolution is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Resolution {
    /// `dims = extent * cbrt(lambda * N / volume)`, with flat axes handled (see `auto_dims`).
    Auto { lambda: f32 },
    /// Given cell counts per axis, as the paper tuned per scene.
    Fixed([u32; 3]),
}

impl Default for Resolution {
    fn default() -> Self {
        Resolution::Auto { lambda: DEFAULT_LAMBDA }
    }
}

impl std::str::FromStr for Resolution {
    type Err = String;
    /// `auto`, `auto:LAMBDA`, `N` (NxNxN) or `AxBxC`.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let s = s.trim();
        if s == "auto" {
            return Ok(Resolution::default());
        }
        if let Some(l) = s.strip_prefix("auto:") {
            let lambda: f32 = l.parse().map_err(|_| format!("bad lambda '{l}'"))?;
            if !(lambda.is_finite() && lambda > 0.0) {
                return Err(format!("lambda must be positive, got {lambda}"));
            }
            return Ok(Resolution::Auto { lambda });
        }
        let parts: Vec<&str> = s.split(['x', 'X']).collect();
        let nums: std::result::Result<Vec<u32>, _> = parts.iter().map(|p| p.trim().parse::<u32>()).collect();
        match nums.as_deref() {
            Ok([n]) if *n > 0 => Ok(Resolution::Fixed([*n; 3])),
            Ok([a, b, c]) if *a > 0 && *b > 0 && *c > 0 => Ok(Resolution::Fixed([*a, *b, *c])),
            _ => Err(format!(
                "grid resolution must be 'auto', 'auto:LAMBDA', 'N' or 'AxBxC' with positive integers, got '{s}'"
            )),
        }
    }
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
        Ok(Self::build_on(tris, lattice, t0))
    }

    /// Builds the grid over `tris` on a given lattice (`GridLattice::new` over the same
    /// triangles); `t0` is when the build started, for `GridStats::build_ms`.
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
fn overlap_pairs_by_triangle(tris: &[TriAccel], bounds: Aabb, dims: UVec3, margin: Vec3) -> Vec<Vec<u64>> {
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

/// Grid dimensions as everyone prints them: `AxBxC`.
pub fn dims_str(d: [u32; 3]) -> String {
    format!("{}x{}x{}", d[0], d[1], d[2])
}

/// Bounds of every triangle's slack-padded box (a unit box for no triangles).
fn tri_bounds(tris: &[TriAccel]) -> Result<Aabb> {
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
fn pad_bounds(b: Aabb) -> Aabb {
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

/// Cube-root rule `dims = extent * cbrt(lambda * N / volume)`, generalised to flat scenes: an axis
/// whose share would be below one cell gets one cell, and the budget of `lambda * N` cells is
/// re-solved over the remaining axes (square root for a planar scene, linear for a line).
pub fn auto_dims(extent: Vec3, n_tris: usize, lambda: f32) -> UVec3 {
    let budget = (lambda as f64 * n_tris.max(1) as f64).min(MAX_CELLS as f64);
    let ext = extent.as_dvec3().to_array();
    let mut fixed = [false; 3];
    let mut dims = [1.0f64; 3];
    loop {
        let free: Vec<usize> = (0..3).filter(|&a| !fixed[a]).collect();
        if free.is_empty() {
            break;
        }
        let fixed_cells: f64 = (0..3).filter(|&a| fixed[a]).map(|a| dims[a]).product();
        let free_volume: f64 = free.iter().map(|&a| ext[a]).product();
        if free_volume <= 0.0 {
            // Some free axis has zero extent: it gets one cell.
            for &a in &free {
                if ext[a] <= 0.0 {
                    fixed[a] = true;
                    dims[a] = 1.0;
                }
            }
            continue;
        }
        let k = (budget / fixed_cells / free_volume).powf(1.0 / free.len() as f64);
        let mut changed = false;
        for &a in &free {
            dims[a] = ext[a] * k;
            if dims[a] < 1.0 {
                fixed[a] = true;
                dims[a] = 1.0;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    UVec3::new(dims[0].round() as u32, dims[1].round() as u32, dims[2].round() as u32)
        .clamp(UVec3::ONE, UVec3::splat(1024))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tri_box::triangle_overlaps_box;

    #[test]
    fn auto_dims_cube_and_flat() {
        let d = auto_dims(Vec3::ONE, 1000, 8.0);
        assert_eq!(d, UVec3::splat(20));
        // A planar scene gets a 2-D grid with about lambda*N cells.
        let d = auto_dims(Vec3::new(2.0, 0.0, 1.0), 1000, 2.0);
        assert_eq!(d.y, 1);
        assert!((d.x * d.z) as f32 > 1500.0 && ((d.x * d.z) as f32) < 2500.0, "{d}");
        // A nearly flat scene does too, rather than a budget wasted on the thin axis.
        let d = auto_dims(Vec3::new(1.0, 1e-4, 1.0), 1000, 4.0);
        assert_eq!(d.y, 1);
        assert!(d.x >= 60 && d.x <= 66, "{d}");
        // A line.
        let d = auto_dims(Vec3::new(0.0, 0.0, 5.0), 100, 4.0);
        assert_eq!(d, UVec3::new(1, 1, 400));
    }

    #[test]
    fn parse_resolution() {
        assert_eq!(
            "20x16x14".parse::<Resolution>().unwrap(),
            Resolution::Fixed([20, 16, 14])
        );
        assert_eq!("16".parse::<Resolution>().unwrap(), Resolution::Fixed([16; 3]));
        assert_eq!("auto".parse::<Resolution>().unwrap(), Resolution::default());
        assert!("0x1x1".parse::<Resolution>().is_err());
        assert!("1x2".parse::<Resolution>().is_err());
        assert!("auto:-1".parse::<Resolution>().is_err());
    }

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
