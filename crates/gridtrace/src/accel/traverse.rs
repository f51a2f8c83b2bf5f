//! Amanatides-Woo 3D-DDA through the grid, with optional proximity-cloud jumps, and the closest-
//! hit and any-hit queries on top of it.

use std::ops::ControlFlow;

use glam::{IVec3, Vec3};

use std::sync::OnceLock;

use super::bvh::BvhAccel;
use super::{Cell, Grid, TriAccel};

/// A ray `origin + t * dir`. `dir` need not be normalised: `t` is in units of its length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray { origin, dir }
    }
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// Closest hit. A miss is explicit: `t = INFINITY`, `tri = u32::MAX`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub tri: u32,
    pub u: f32,
    pub v: f32,
}

impl Hit {
    pub const MISS: Hit = Hit {
        t: f32::INFINITY,
        tri: u32::MAX,
        u: 0.0,
        v: 0.0,
    };
    pub fn is_hit(&self) -> bool {
        self.tri != u32::MAX
    }
}

/// Which acceleration the traversal uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AccelKind {
    /// Plain uniform grid: one DDA step per cell.
    Grid,
    /// Uniform grid with proximity clouds: empty space is crossed in jumps.
    ProximityCloud,
    /// Bounding volume hierarchy (binned SAH), the comparison the paper left as future work.
    /// CPU only.
    Bvh,
}

impl std::str::FromStr for AccelKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "grid" | "g" => Ok(AccelKind::Grid),
            "pc" | "proximity" => Ok(AccelKind::ProximityCloud),
            "bvh" => Ok(AccelKind::Bvh),
            _ => Err(format!("accel must be 'grid', 'pc' or 'bvh', got '{s}'")),
        }
    }
}

impl AccelKind {
    /// Every kind (the CPU runs them all).
    pub const ALL: [AccelKind; 3] = [AccelKind::Grid, AccelKind::ProximityCloud, AccelKind::Bvh];
    /// The kinds the GPU kernels run.
    pub const GPU: [AccelKind; 2] = [AccelKind::Grid, AccelKind::ProximityCloud];

    pub fn name(self) -> &'static str {
        match self {
            AccelKind::Grid => "grid",
            AccelKind::ProximityCloud => "pc",
            AccelKind::Bvh => "bvh",
        }
    }
}

/// Traversal counters. The no-op implementation compiles to nothing, so the hot loop pays for
/// statistics only when they are asked for.
pub trait Counters {
    fn cell(&mut self) {}
    fn jump(&mut self) {}
    fn tri_test(&mut self) {}
}

/// Counters that cost nothing.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoCounters;
impl Counters for NoCounters {}

/// Counters that count.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct TraversalCounters {
    /// Cells visited (DDA steps plus landing cells of jumps).
    pub cells: u64,
    /// Proximity-cloud jumps taken.
    pub jumps: u64,
    /// Ray/triangle tests.
    pub tri_tests: u64,
}

impl Counters for TraversalCounters {
    #[inline(always)]
    fn cell(&mut self) {
        self.cells += 1;
    }
    #[inline(always)]
    fn jump(&mut self) {
        self.jumps += 1;
    }
    #[inline(always)]
    fn tri_test(&mut self) {
        self.tri_tests += 1;
    }
}

impl std::ops::AddAssign for TraversalCounters {
    fn add_assign(&mut self, o: Self) {
        self.cells += o.cells;
        self.jumps += o.jumps;
        self.tri_tests += o.tri_tests;
    }
}

/// The triangles and the structures over them: everything a ray query needs. The grid is
/// always built; the BVH (`AccelKind::Bvh`) is built the first time it is asked for.
#[derive(Debug, Clone)]
pub struct GridAccel {
    pub grid: Grid,
    pub tris: Vec<TriAccel>,
    bvh: OnceLock<BvhAccel>,
}

impl GridAccel {
    pub fn new(grid: Grid, tris: Vec<TriAccel>) -> GridAccel {
        GridAccel {
            grid,
            tris,
            bvh: OnceLock::new(),
        }
    }

    /// The BVH over `tris`, built on first use.
    pub fn bvh(&self) -> &BvhAccel {
        self.bvh.get_or_init(|| BvhAccel::build(&self.tris))
    }

    /// The BVH if it has been built.
    pub fn bvh_if_built(&self) -> Option<&BvhAccel> {
        self.bvh.get()
    }

    /// Closest hit with `t_min < t < t_max`.
    pub fn intersect<C: Counters>(&self, ray: &Ray, t_min: f32, t_max: f32, kind: AccelKind, counters: &mut C) -> Hit {
        if kind == AccelKind::Bvh {
            return self.bvh().intersect(ray, t_min, t_max, counters);
        }
        let mut best = Hit { t: t_max, ..Hit::MISS };
        self.walk(ray, t_min, t_max, kind, counters, |refs, t_cell_exit, counters| {
            for &tri in refs {
                counters.tri_test();
                if let Some(h) = self.tris[tri as usize].intersect(ray.origin, ray.dir, t_min, best.t) {
                    best = Hit {
                        t: h.t,
                        tri,
                        u: h.u,
                        v: h.v,
                    };
                }
            }
            // A hit beyond this cell's exit may be beaten by a triangle in a later cell; only a
            // hit inside the cell (or before it) is final.
            if best.tri != u32::MAX && best.t <= t_cell_exit {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        });
        if best.tri == u32::MAX { Hit::MISS } else { best }
    }

    /// Closest hits of a batch, `out[i]` for `rays[i]` (on this thread: callers split large
    /// batches across threads). The same answers as `intersect`; the BVH interleaves the rays
    /// to hide memory latency (`BvhAccel::intersect_batch`).
    pub fn intersect_batch(&self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind, out: &mut [Hit]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        if kind == AccelKind::Bvh {
            return self.bvh().intersect_batch(rays, t_min, t_max, out);
        }
        for (r, o) in rays.iter().zip(out) {
            *o = self.intersect(r, t_min, t_max, kind, &mut NoCounters);
        }
    }

    /// `intersect_batch`, also giving each hit's geometric normal (`TriAccel::normal`,
    /// unnormalised; zero for a miss).
    pub fn intersect_batch_normals(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        kind: AccelKind,
        out: &mut [Hit],
        normals: &mut [Vec3],
    ) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        assert_eq!(rays.len(), normals.len(), "one normal per ray");
        self.intersect_batch_each(rays, t_min, t_max, kind, |i, hit, normal| {
            out[i] = hit;
            normals[i] = normal;
        });
    }

    /// Closest hits of a batch handed to `f(i, hit, normal)` for each ray `rays[i]`, in no
    /// particular order, with the hit's geometric normal (`TriAccel::normal`, unnormalised;
    /// zero for a miss). The BVH takes the normal from the triangle's block while it is still
    /// in cache (`BvhAccel::intersect_batch_each`): looked up afterwards, it is a cache miss
    /// per hit.
    #[inline]
    pub fn intersect_batch_each(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        kind: AccelKind,
        mut f: impl FnMut(usize, Hit, Vec3),
    ) {
        if kind == AccelKind::Bvh {
            return self.bvh().intersect_batch_each(rays, t_min, t_max, f);
        }
        for (i, r) in rays.iter().enumerate() {
            let hit = self.intersect(r, t_min, t_max, kind, &mut NoCounters);
            f(i, hit, self.hit_normal(&hit));
        }
    }

    /// The geometric normal (`TriAccel::normal`, unnormalised) of a hit's triangle; zero for a
    /// miss.
    pub fn hit_normal(&self, hit: &Hit) -> Vec3 {
        if hit.is_hit() {
            self.tris[hit.tri as usize].normal()
        } else {
            Vec3::ZERO
        }
    }

    /// Any-hit results of a batch, like `intersect_batch`.
    pub fn occluded_batch(&self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind, out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        if kind == AccelKind::Bvh {
            return self.bvh().occluded_batch(rays, t_min, t_max, out);
        }
        for (r, o) in rays.iter().zip(out) {
            *o = self.occluded(r, t_min, t_max, kind, &mut NoCounters);
        }
    }

    /// Any hit with `t_min < t < t_max` (shadow rays): stops at the first one found.
    pub fn occluded<C: Counters>(&self, ray: &Ray, t_min: f32, t_max: f32, kind: AccelKind, counters: &mut C) -> bool {
        if kind == AccelKind::Bvh {
            return self.bvh().occluded(ray, t_min, t_max, counters);
        }
        let mut hit = false;
        self.walk(ray, t_min, t_max, kind, counters, |refs, _, counters| {
            for &tri in refs {
                counters.tri_test();
                if self.tris[tri as usize]
                    .intersect(ray.origin, ray.dir, t_min, t_max)
                    .is_some()
                {
                    hit = true;
                    return ControlFlow::Break(());
                }
            }
            ControlFlow::Continue(())
        });
        hit
    }

    /// Visits the non-empty cells pierced by the ray within `[t_min, t_max]`, front to back,
    /// calling `visit(refs, t_cell_exit)` until it breaks. Proximity jumps are taken for
    /// `AccelKind::ProximityCloud` only.
    ///
    /// Boundary distances are recomputed from the integer cell coordinate at every step
    /// (`t = (grid_min + k * cell_size - origin) / dir`) instead of accumulating `t_delta`, so
    /// they do not drift, and re-entering the DDA after a proximity jump is the same computation.
    #[inline]
    pub fn walk<C: Counters>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        kind: AccelKind,
        counters: &mut C,
        mut visit: impl FnMut(&[u32], f32, &mut C) -> ControlFlow<()>,
    ) {
        let g = &self.grid;
        let inv_dir = ray.dir.recip();
        let Some((t_enter, t_leave)) = g.bounds.clip(ray.origin, inv_dir, t_min, t_max) else {
            return;
        };
        // Plain arrays, not glam vectors: the loop indexes by a runtime axis, which on a Vec3
        // is a three-way branch per access.
        let dims = g.dims.as_ivec3().to_array();
        let grid_min = g.bounds.min.to_array();
        let cell_size = g.cell_size.to_array();
        let origin = ray.origin.to_array();
        let inv = inv_dir.to_array();
        let step = [sign(ray.dir.x), sign(ray.dir.y), sign(ray.dir.z)];
        // Offset of the boundary ahead of a cell: +1 cell when stepping up, 0 when stepping down.
        let ahead = step.map(|s| s.max(0));
        let world_to_grid = |p: Vec3| ((p - g.bounds.min) * g.inv_cell_size).floor().as_ivec3();
        let mut cell = world_to_grid(ray.at(t_enter))
            .clamp(IVec3::ZERO, IVec3::from(dims) - 1)
            .to_array();
        let boundary_t = |axis: usize, k: i32| {
            if step[axis] == 0 {
                f32::INFINITY
            } else {
                (grid_min[axis] + k as f32 * cell_size[axis] - origin[axis]) * inv[axis]
            }
        };
        let next_boundaries = |cell: &[i32; 3]| std::array::from_fn::<f32, 3, _>(|a| boundary_t(a, cell[a] + ahead[a]));
        let mut t_next = next_boundaries(&cell);
        let use_pc = kind == AccelKind::ProximityCloud;
        let (nx, nxy) = (dims[0] as usize, (dims[0] * dims[1]) as usize);
        // Every iteration moves at least one cell forward along some axis, so this bounds the
        // loop even if floating point misbehaves: never a hang.
        let mut budget = (dims[0] + dims[1] + dims[2]) as u32 * 2 + 8;
        loop {
            counters.cell();
            let t_exit = t_next[0].min(t_next[1]).min(t_next[2]);
            let Cell { start, count, dist } =
                g.cells[cell[0] as usize + nx * cell[1] as usize + nxy * cell[2] as usize];
            if count > 0 {
                let refs = &g.refs[start as usize..(start + count) as usize];
                if visit(refs, t_exit.min(t_leave), counters).is_break() {
                    return;
                }
            } else if use_pc && dist >= 2 {
                // The cube of cells within Chebyshev distance dist-1 is empty: leave it at once.
                let k = (dist - 1).min(1 << 20) as i32;
                let t_cube: [f32; 3] = std::array::from_fn(|a| boundary_t(a, cell[a] + ahead[a] + step[a] * k));
                let t_jump = t_cube[0].min(t_cube[1]).min(t_cube[2]);
                if t_jump >= t_leave {
                    return;
                }
                counters.jump();
                let axis = min_position(t_cube);
                // Land in the cell where the ray leaves the cube: the exit axis moves k+1 cells,
                // the others take the cell of the exit point, kept inside the cube's range
                // (rounding at a cube edge must not move the ray sideways out of it).
                let here = IVec3::from(cell);
                let mut next = world_to_grid(ray.at(t_jump)).clamp(here - k, here + k).to_array();
                next[axis] = cell[axis] + step[axis] * (k + 1);
                cell = next;
                if (0..3).any(|a| cell[a] < 0 || cell[a] >= dims[a]) {
                    return;
                }
                t_next = next_boundaries(&cell);
                budget = budget.saturating_sub(1);
                if budget == 0 {
                    return;
                }
                continue;
            }
            if t_exit >= t_leave {
                return;
            }
            let axis = min_position(t_next);
            cell[axis] += step[axis];
            if cell[axis] < 0 || cell[axis] >= dims[axis] {
                return;
            }
            t_next[axis] = boundary_t(axis, cell[axis] + ahead[axis]);
            budget -= 1;
            if budget == 0 {
                return;
            }
        }
    }
}

/// Index of the smallest element, the first on ties (glam's `min_position`; the WGSL
/// `min_position` in common.wgsl is the same).
#[inline(always)]
fn min_position(v: [f32; 3]) -> usize {
    let mut m = v[0];
    let mut i = 0;
    if v[1] < m {
        m = v[1];
        i = 1;
    }
    if v[2] < m {
        i = 2;
    }
    i
}

#[inline(always)]
fn sign(x: f32) -> i32 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}

/// Reference closest hit: every triangle tested. The ground truth for all traversal tests.
pub fn brute_force_intersect(tris: &[TriAccel], ray: &Ray, t_min: f32, t_max: f32) -> Hit {
    let mut best = Hit { t: t_max, ..Hit::MISS };
    for (i, tri) in tris.iter().enumerate() {
        if let Some(h) = tri.intersect(ray.origin, ray.dir, t_min, best.t) {
            best = Hit {
                t: h.t,
                tri: i as u32,
                u: h.u,
                v: h.v,
            };
        }
    }
    if best.tri == u32::MAX { Hit::MISS } else { best }
}

/// Reference any hit.
pub fn brute_force_occluded(tris: &[TriAccel], ray: &Ray, t_min: f32, t_max: f32) -> bool {
    tris.iter()
        .any(|t| t.intersect(ray.origin, ray.dir, t_min, t_max).is_some())
}
