//! The acceleration structures, one folder each, behind one front door (`Accel`): the paper's
//! uniform grid with proximity clouds (`grid/`), a wide BVH to compare it with (`bvh/`), and
//! the irregular grid that followed the paper (`irregular/`).
//!
//! A structure is built over `TriAccel`s (`triangle.rs`, the one edge-safe triangle test every
//! structure shares) and answers closest-hit and any-hit queries for single rays and batches.
//! Adding a structure means a new folder and one arm of `Structure`; everything above this
//! module (renderers, queries, benchmarks) goes through `Accel`.

pub mod aabb;
pub mod brute_force;
pub mod bvh;
pub mod closest;
pub mod grid;
pub mod huge;
pub mod irregular;
pub mod lanes;
pub mod ray;
pub mod triangle;
pub mod winding;

use glam::Vec3;

pub use aabb::Aabb;
pub use brute_force::{brute_force_intersect, brute_force_occluded};
pub use bvh::{Bvh, BvhAccel, BvhNode};
pub use grid::{Cell, Grid, GridLattice, GridStats, Resolution, Stepping};
pub use irregular::{IrrCell, IrregularGrid, IrregularParams, MemoryBound, PACKET};
pub use ray::{AccelKind, Counters, Hit, NoCounters, Ray, TraversalCounters};
pub use triangle::{LaneHits, TriAccel, TriAccel4, TriHit, TriHit4, intersect_lanes};

use crate::{Error, Result};

/// The structure built over the triangles: only the one that was asked for.
#[derive(Debug, Clone)]
pub enum Structure {
    /// The uniform grid with its proximity cloud; serves `AccelKind::Grid` (cell by cell) and
    /// `AccelKind::ProximityCloud` (jumps), which share it.
    Grid(Grid),
    /// The eight-wide BVH (`AccelKind::Bvh`); it keeps its own copy of the triangles in leaf
    /// order.
    Bvh(BvhAccel),
    /// The irregular grid (`AccelKind::Irregular`), built with `IrregularParams::default()`
    /// unless `Accel::build_irregular` says otherwise.
    Irregular(IrregularGrid),
}

/// The triangles and the structure over them: everything a ray query needs.
#[derive(Debug, Clone)]
pub struct Accel {
    /// The triangles, in the order hits name them (`Hit::tri`).
    pub tris: Vec<TriAccel>,
    pub structure: Structure,
    /// How the structure was built, so that `update` builds it the same way after the
    /// triangles move.
    pub resolution: Resolution,
    pub irregular: IrregularParams,
    /// Set when the triangles moved and the structure was left to a GPU to rebuild
    /// (`update_triangles_only`): CPU traversal of it would be wrong, and `check_current`
    /// says so.
    pub structure_stale: bool,
}

impl Accel {
    /// Builds the structure that serves `kind` over `tris` (`resolution` sizes a grid; the BVH
    /// ignores it; the irregular grid gets `IrregularParams::default()`).
    pub fn build(tris: Vec<TriAccel>, kind: AccelKind, resolution: Resolution) -> Result<Accel> {
        Self::build_with(tris, kind, resolution, IrregularParams::default())
    }

    /// `build`, with the irregular grid's parameters (the other structures ignore them).
    pub fn build_with(
        tris: Vec<TriAccel>,
        kind: AccelKind,
        resolution: Resolution,
        irregular: IrregularParams,
    ) -> Result<Accel> {
        let structure = match kind {
            AccelKind::Grid | AccelKind::ProximityCloud => Structure::Grid(Grid::build(&tris, resolution)?),
            AccelKind::Bvh => Structure::Bvh(BvhAccel::build(&tris)),
            AccelKind::Irregular => Structure::Irregular(IrregularGrid::build(&tris, irregular)?),
        };
        Ok(Accel {
            tris,
            structure,
            resolution,
            irregular,
            structure_stale: false,
        })
    }

    /// A grid built elsewhere (over these triangles).
    pub fn from_grid(grid: Grid, tris: Vec<TriAccel>) -> Accel {
        Accel {
            tris,
            resolution: Resolution::Fixed(grid.dims.to_array()),
            structure: Structure::Grid(grid),
            irregular: IrregularParams::default(),
            structure_stale: false,
        }
    }

    /// New positions of the same triangles (same count and order): the grids are rebuilt as
    /// they were built (a grid costs about what a refit would, and a refit grid would keep the
    /// old bounds), the BVH is refitted (its tree kept, its boxes recomputed: much cheaper than a
    /// rebuild, at a quality that degrades as the vertices move away from the build pose).
    /// On an error nothing has changed. Returns what was done.
    pub fn update(&mut self, tris: Vec<TriAccel>) -> Result<&'static str> {
        self.check_same_count(&tris)?;
        // A build that fails returns before anything is assigned; a refit cannot fail (the
        // count is checked), so the BVH is refitted in place, not copied first.
        let how = match &mut self.structure {
            Structure::Grid(g) => {
                *g = Grid::build(&tris, self.resolution)?;
                "rebuilt"
            }
            Structure::Bvh(b) => {
                b.refit(&tris);
                "refitted"
            }
            Structure::Irregular(g) => {
                *g = IrregularGrid::build(&tris, self.irregular)?;
                "rebuilt"
            }
        };
        self.tris = tris;
        self.structure_stale = false;
        Ok(how)
    }

    /// New positions of the triangles, the structure left for a GPU to rebuild (which only the
    /// uniform grid's has): until `update` runs, CPU traversal is refused (`check_current`).
    pub fn update_triangles_only(&mut self, tris: Vec<TriAccel>) -> Result<()> {
        self.check_same_count(&tris)?;
        self.tris = tris;
        self.structure_stale = true;
        Ok(())
    }

    fn check_same_count(&self, tris: &[TriAccel]) -> Result<()> {
        if tris.len() != self.tris.len() {
            return Err(Error::InvalidInput(format!(
                "an update gives {} triangles; the structure holds {}",
                tris.len(),
                self.tris.len()
            )));
        }
        Ok(())
    }

    /// An error when the structure does not match the triangles (`structure_stale`).
    pub fn check_current(&self) -> Result<()> {
        if self.structure_stale {
            return Err(Error::InvalidInput(
                "the mesh moved and its structure was rebuilt on the GPU only: trace it there, or \
                 update it on the CPU (PreparedScene::update_vertices with RebuildOn::Cpu)"
                    .into(),
            ));
        }
        Ok(())
    }

    /// The grid, if that is the structure.
    pub fn grid(&self) -> Option<&Grid> {
        match &self.structure {
            Structure::Grid(g) => Some(g),
            _ => None,
        }
    }

    /// The BVH, if that is the structure.
    pub fn bvh(&self) -> Option<&BvhAccel> {
        match &self.structure {
            Structure::Bvh(b) => Some(b),
            _ => None,
        }
    }

    /// The irregular grid, if that is the structure.
    pub fn irregular(&self) -> Option<&IrregularGrid> {
        match &self.structure {
            Structure::Irregular(g) => Some(g),
            _ => None,
        }
    }

    /// The box every ray set over these triangles is drawn from: the grid's bounds, which any
    /// structure over the same triangles shares (`grid::grid_bounds`).
    pub fn bounds(&self) -> Aabb {
        match &self.structure {
            Structure::Grid(g) => g.bounds,
            Structure::Irregular(g) => g.bounds,
            // The triangles were checked finite when the structure was built.
            _ => grid::grid_bounds(&self.tris).unwrap_or(Aabb::EMPTY),
        }
    }

    /// The structure's name, as `--accel` spells the kinds it serves.
    pub fn structure_name(&self) -> &'static str {
        match self.structure {
            Structure::Grid(_) => "grid",
            Structure::Bvh(_) => "bvh",
            Structure::Irregular(_) => "irregular",
        }
    }

    /// Whether this structure can run traversal `kind`.
    pub fn serves(&self, kind: AccelKind) -> bool {
        matches!(
            (&self.structure, kind),
            (Structure::Grid(_), AccelKind::Grid | AccelKind::ProximityCloud)
                | (Structure::Bvh(_), AccelKind::Bvh)
                | (Structure::Irregular(_), AccelKind::Irregular)
        )
    }

    /// `serves`, as an error that says what to do.
    pub fn check_serves(&self, kind: AccelKind) -> Result<()> {
        if self.serves(kind) {
            Ok(())
        } else {
            Err(Error::InvalidInput(format!(
                "accel '{}' asked of a scene prepared with a {}: prepare it for '{}'",
                kind.name(),
                self.structure_name(),
                kind.name()
            )))
        }
    }

    /// Closest hit with `t_min < t < t_max`. `kind` must be one this structure serves
    /// (`serves`); the grid's `Grid` and `ProximityCloud` differ only in how they cross empty
    /// space.
    #[inline]
    pub fn intersect<C: Counters>(&self, ray: &Ray, t_min: f32, t_max: f32, kind: AccelKind, counters: &mut C) -> Hit {
        debug_assert!(self.serves(kind), "{kind:?} on a {}", self.structure_name());
        match &self.structure {
            Structure::Grid(g) => g.intersect(&self.tris, ray, t_min, t_max, stepping(kind), counters),
            Structure::Bvh(b) => b.intersect(ray, t_min, t_max, counters),
            Structure::Irregular(g) => g.intersect(&self.tris, ray, t_min, t_max, counters),
        }
    }

    /// Closest hits of a packet of up to `PACKET` coherent rays (a 4x2 block of pixels' rays:
    /// the CPU renderer's, `cpu/blocks.rs`), each counted into its own `counters[i]`: the same
    /// hits and counts as `intersect` ray by ray. The irregular grid walks the packet's rays
    /// together, a ray per SIMD lane (`IrregularGrid::intersect_packet`); the BVH and the
    /// uniform grids interleave the rays' own walks, a step each in turn, so that one ray's
    /// chain of dependent steps overlaps the others' (`BvhAccel::intersect_packet`,
    /// `Grid::intersect_packet`). Hits past `rays.len()` are misses.
    #[inline]
    pub fn intersect_packet<C: Counters>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        kind: AccelKind,
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        debug_assert!(self.serves(kind), "{kind:?} on a {}", self.structure_name());
        // Each structure checks the packet's length and counters itself.
        match &self.structure {
            Structure::Irregular(g) => g.intersect_packet(&self.tris, rays, t_min, t_max, counters),
            Structure::Bvh(b) => b.intersect_packet(rays, t_min, t_max, counters),
            Structure::Grid(g) => g.intersect_packet(&self.tris, rays, t_min, t_max, stepping(kind), counters),
        }
    }

    /// Whether each of up to `PACKET` rays hits anything with `t_min < t < t_max[i]` (the
    /// shadow rays of a 4x2 block towards one light), each counted into its own `counters[i]`:
    /// the same answers and counts as `occluded` ray by ray. False past `rays.len()`.
    #[inline]
    pub fn occluded_packet<C: Counters>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        kind: AccelKind,
        counters: &mut [C],
    ) -> [bool; PACKET] {
        debug_assert!(self.serves(kind), "{kind:?} on a {}", self.structure_name());
        // Each structure checks the packet's length and counters itself.
        match &self.structure {
            Structure::Irregular(g) => g.occluded_packet(&self.tris, rays, t_min, t_max, counters),
            Structure::Bvh(b) => b.occluded_packet(rays, t_min, t_max, counters),
            Structure::Grid(g) => g.occluded_packet(&self.tris, rays, t_min, t_max, stepping(kind), counters),
        }
    }

    /// Any hit with `t_min < t < t_max` (shadow rays): stops at the first one found.
    #[inline]
    pub fn occluded<C: Counters>(&self, ray: &Ray, t_min: f32, t_max: f32, kind: AccelKind, counters: &mut C) -> bool {
        debug_assert!(self.serves(kind), "{kind:?} on a {}", self.structure_name());
        match &self.structure {
            Structure::Grid(g) => g.occluded(&self.tris, ray, t_min, t_max, stepping(kind), counters),
            Structure::Bvh(b) => b.occluded(ray, t_min, t_max, counters),
            Structure::Irregular(g) => g.occluded(&self.tris, ray, t_min, t_max, counters),
        }
    }

    /// The batch query: closest hits of `rays` handed to `f(i, hit, normal)` for each ray
    /// `rays[i]`, in no particular order, with the hit's geometric normal (`TriAccel::normal`,
    /// unnormalised; zero for a miss). On this thread: callers split large batches across
    /// threads. The BVH interleaves the rays to hide memory latency and takes the normal from
    /// the hit's block while it is still in cache (`BvhAccel::intersect_batch_each`); looked up
    /// afterwards, it is a cache miss per hit.
    #[inline]
    pub fn intersect_batch_each(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        kind: AccelKind,
        mut f: impl FnMut(usize, Hit, Vec3),
    ) {
        match &self.structure {
            Structure::Bvh(b) => b.intersect_batch_each(rays, t_min, t_max, f),
            Structure::Irregular(g) => g.batch::<false>(&self.tris, rays, t_min, t_max, |i, hit| {
                f(i, hit, self.hit_normal(&hit))
            }),
            Structure::Grid(_) => {
                for (i, r) in rays.iter().enumerate() {
                    let hit = self.intersect(r, t_min, t_max, kind, &mut NoCounters);
                    f(i, hit, self.hit_normal(&hit));
                }
            }
        }
    }

    /// Closest hits of a batch into `out` (`out[i]` for `rays[i]`), like `intersect_batch_each`.
    pub fn intersect_batch(&self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind, out: &mut [Hit]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        self.intersect_batch_each(rays, t_min, t_max, kind, |i, hit, _| out[i] = hit);
    }

    /// Any-hit results of a batch into `out` (`out[i]` for `rays[i]`).
    pub fn occluded_batch(&self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind, out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        match &self.structure {
            Structure::Bvh(b) => b.occluded_batch(rays, t_min, t_max, out),
            Structure::Irregular(g) => g.batch::<true>(&self.tris, rays, t_min, t_max, |i, hit| out[i] = hit.is_hit()),
            Structure::Grid(_) => {
                for (r, o) in rays.iter().zip(out) {
                    *o = self.occluded(r, t_min, t_max, kind, &mut NoCounters);
                }
            }
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

    /// Bytes of each array the structure traverses (the triangles included).
    pub fn memory(&self) -> Vec<(&'static str, usize)> {
        let mut v = match &self.structure {
            Structure::Grid(g) => vec![
                ("cells", std::mem::size_of_val(g.cells.as_slice())),
                ("refs", std::mem::size_of_val(g.refs.as_slice())),
            ],
            Structure::Bvh(b) => vec![("bvh", b.memory())],
            Structure::Irregular(g) => g.memory(),
        };
        v.push(("triangles", std::mem::size_of_val(self.tris.as_slice())));
        v
    }
}

/// How the grid crosses empty space for a traversal kind.
fn stepping(kind: AccelKind) -> Stepping {
    if kind == AccelKind::ProximityCloud {
        Stepping::ProximityJumps
    } else {
        Stepping::EveryCell
    }
}
