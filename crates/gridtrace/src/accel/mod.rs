//! The acceleration structures, one folder each, behind one front door (`Accel`): the paper's
//! uniform grid with proximity clouds (`grid/`), a wide BVH to compare it with (`bvh/`), the
//! irregular grid that followed the paper (`irregular/`) and no structure at all (`brute/`).
//!
//! Every structure keeps one contract (`contract::AccelStructure`: build, update, bounds,
//! memory, reports, closest and any hits for rays, packets and batches) over `TriAccel`s
//! (`triangle/`, the one edge-safe triangle test all share; its lane forms in
//! `triangle/packed.rs`), and has one row in the registry (`registry.rs`: names, aliases,
//! parameters). What they share lives beside them, not in one of
//! them: `binning` (bounds, candidate cells, counting sort), `resolution`, `tri_box`, `lattice`
//! (DDA basics), `simd` (AVX2, prefetch, packet width), `lanes`. No structure imports another.
//! Adding one: see "Adding a structure" in docs/design.md.

pub mod aabb;
pub mod binning;
pub mod brute;
pub mod brute_force;
pub mod bvh;
pub mod closest;
pub mod contract;
pub mod grid;
pub mod huge;
pub mod hwrt;
pub mod irregular;
pub mod lanes;
pub mod lattice;
pub mod params;
pub(crate) mod point_order;
pub mod ray;
pub mod registry;
pub mod resolution;
pub mod simd;
pub mod tri_box;
pub mod triangle;
pub mod winding;

use glam::Vec3;

pub use aabb::Aabb;
pub use binning::grid_bounds;
pub use brute::Brute;
pub use brute_force::{brute_force_intersect, brute_force_occluded};
pub use bvh::{Bvh, BvhAccel, BvhNode};
pub use contract::{AccelStructure, Walks};
pub use grid::{Cell, Grid, GridLattice, GridStats, Stepping};
pub use irregular::{IrrCell, IrregularGrid, IrregularParams, MemoryBound};
pub use params::AccelParams;
pub use ray::{Counters, Hit, NoCounters, Ray, TraversalCounters};
pub use registry::{AccelChoice, AccelEntry, AccelKind, AccelSpec, StructureId, TracedOn, Work};
pub use resolution::{DEFAULT_LAMBDA, MAX_CELLS, Resolution, dims_str};
pub use simd::PACKET;
pub use triangle::{LaneHits, LaneRay, ShearedRay, TriAccel, TriAccel4, TriHit, TriHit4, intersect_lanes};

use crate::{Error, Result};

/// The structure built over the triangles: only the one that was asked for. One arm per
/// structure (the registry's `structure` column); `dispatch!` below is the only match on it.
#[derive(Debug, Clone)]
pub enum Structure {
    /// The uniform grid with its proximity cloud; serves `grid` (cell by cell) and `pc`
    /// (jumps), which share it.
    Grid(Grid),
    /// The eight-wide BVH; it keeps its own copy of the triangles in leaf order.
    Bvh(BvhAccel),
    /// The irregular grid.
    Irregular(IrregularGrid),
    /// No structure: every triangle per ray.
    Brute(Brute),
    /// The GPU's ray queries; a BVH kept for closest points and the CPU's answers.
    Hwrt(hwrt::Hwrt),
}

/// Runs `$body` with `$s` bound to the structure inside `$structure`, whatever it is: the one
/// place that lists the arms.
macro_rules! dispatch {
    ($structure:expr, $s:ident => $body:expr) => {
        match $structure {
            Structure::Grid($s) => $body,
            Structure::Bvh($s) => $body,
            Structure::Irregular($s) => $body,
            Structure::Brute($s) => $body,
            Structure::Hwrt($s) => $body,
        }
    };
}

/// Runs `$body` with `$s` bound to what walks rays for the structure inside `$structure`:
/// itself, or for `hwrt` the BVH it keeps (its CPU-side walks: counts, lists, nearest points,
/// the tests' references; `Accel::check_cpu_traces` keeps its closest hits off the CPU).
macro_rules! walk {
    ($structure:expr, $s:ident => $body:expr) => {
        match $structure {
            Structure::Grid($s) => $body,
            Structure::Bvh($s) | Structure::Hwrt(hwrt::Hwrt { bvh: $s, .. }) => $body,
            Structure::Irregular($s) => $body,
            Structure::Brute($s) => $body,
        }
    };
}

impl Structure {
    /// Builds the structure `kind` walks, which reads its own keys of `params`, set to serve
    /// `kind` (`kind()` says so).
    pub fn build(kind: AccelKind, tris: &[TriAccel], params: &AccelParams) -> Result<Structure> {
        let mut s = Structure::build_structure(kind, tris, params)?;
        s.set_traversal(kind)?;
        Ok(s)
    }

    /// Reads `params` as the structure `kind` walks reads them when it builds (the same
    /// functions), without building: front ends refuse a bad key or value with their other
    /// argument errors, before a mesh is loaded (`gridtrace render --accel grid:res=0`).
    pub fn check_params(kind: AccelKind, params: &AccelParams) -> Result<()> {
        match kind.structure() {
            StructureId::Grid => Grid::resolution_from(params).map(drop),
            StructureId::Irregular => IrregularParams::from_params(params).map(drop),
            id @ (StructureId::Bvh | StructureId::Brute | StructureId::Hwrt) => {
                params.read(id.name(), &[], |_, _| Ok(()))
            }
        }
    }

    fn build_structure(kind: AccelKind, tris: &[TriAccel], params: &AccelParams) -> Result<Structure> {
        Ok(match kind.structure() {
            StructureId::Grid => Structure::Grid(AccelStructure::build(tris, params)?),
            StructureId::Bvh => Structure::Bvh(AccelStructure::build(tris, params)?),
            StructureId::Irregular => Structure::Irregular(AccelStructure::build(tris, params)?),
            StructureId::Brute => Structure::Brute(AccelStructure::build(tris, params)?),
            StructureId::Hwrt => Structure::Hwrt(AccelStructure::build(tris, params)?),
        })
    }

    /// The traversal it serves: its own, or for the uniform grid the one its `stepping` says.
    pub fn kind(&self) -> AccelKind {
        match self {
            Structure::Grid(g) if g.stepping == Stepping::ProximityJumps => AccelKind::ProximityCloud,
            Structure::Grid(_) => AccelKind::Grid,
            Structure::Bvh(_) => AccelKind::Bvh,
            Structure::Irregular(_) => AccelKind::Irregular,
            Structure::Brute(_) => AccelKind::Brute,
            Structure::Hwrt(_) => AccelKind::Hwrt,
        }
    }

    /// Which structure it is (the registry's `structure` column).
    pub fn id(&self) -> StructureId {
        self.kind().structure()
    }

    /// The structure's name, for messages.
    pub fn name(&self) -> &'static str {
        self.id().name()
    }

    /// Serves `kind` from now on: another traversal of the same structure (the grid's `grid`
    /// and `pc`, which share every array), so nothing is built. An error for a kind of another
    /// structure, which needs a build (`PreparedScene::with_accel`).
    pub fn set_traversal(&mut self, kind: AccelKind) -> Result<()> {
        kind.check_walks(self.id(), "scene prepared")?;
        if let Structure::Grid(g) = self {
            g.stepping = match kind {
                AccelKind::ProximityCloud => Stepping::ProximityJumps,
                _ => Stepping::EveryCell,
            };
        }
        Ok(())
    }
}

/// The triangles and the structure over them: everything a ray query needs.
#[derive(Debug, Clone)]
pub struct Accel {
    /// The triangles, in the order hits name them (`Hit::tri`).
    pub tris: Vec<TriAccel>,
    /// The structure, which keeps the parameters it was built with (`params`), so that
    /// `update` builds it the same way after the triangles move.
    pub structure: Structure,
    /// Set when the triangles moved and the structure was left to a GPU to rebuild
    /// (`update_triangles_only`): CPU traversal of it would be wrong, and `check_current`
    /// says so.
    pub structure_stale: bool,
}

impl Accel {
    /// Builds the structure that serves `kind` over `tris`; the structure reads its own keys of
    /// `params` (`AccelParams::NONE`: its defaults) and refuses the others.
    pub fn build(tris: Vec<TriAccel>, kind: AccelKind, params: &AccelParams) -> Result<Accel> {
        let structure = Structure::build(kind, &tris, params)?;
        Ok(Accel {
            tris,
            structure,
            structure_stale: false,
        })
    }

    /// A grid built elsewhere (over these triangles), serving the traversal its `stepping` says.
    pub fn from_grid(grid: Grid, tris: Vec<TriAccel>) -> Accel {
        Accel {
            tris,
            structure: Structure::Grid(grid),
            structure_stale: false,
        }
    }

    /// The parameters the structure was built with (`update` builds it the same way).
    pub fn params(&self) -> AccelParams {
        dispatch!(&self.structure, s => AccelStructure::params(s))
    }

    /// New positions of the same triangles (same count and order): each structure updates as
    /// its contract says (`AccelStructure::update`: the grids are rebuilt as they were built,
    /// since a grid costs about what a refit would and a refit grid would keep the old bounds;
    /// the BVH is refitted). On an error nothing has changed. Returns what was done.
    pub fn update(&mut self, tris: Vec<TriAccel>) -> Result<&'static str> {
        self.check_same_count(&tris)?;
        // A build that fails returns before anything is assigned (`update` builds into a new
        // value and assigns it last); a refit cannot fail.
        let how = dispatch!(&mut self.structure, s => AccelStructure::update(s, &tris))?;
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

    /// An error when the CPU may not trace this structure's rays: `check_current`'s, or the
    /// registry's `cpu` column false (`hwrt`: rays on the GPU's ray-tracing hardware only; its
    /// closest points and hit lists, which are not ray queries, still run on the CPU).
    pub fn check_cpu_traces(&self) -> Result<()> {
        self.check_current()?;
        self.check_cpu_kind()
    }

    /// The registry's half of `check_cpu_traces`: whether the CPU may ever trace this kind of
    /// structure's rays (a stale grid it may, once rebuilt: what a tracer does when its GPU
    /// fails).
    pub fn check_cpu_kind(&self) -> Result<()> {
        match registry::ENTRIES.iter().find(|e| e.structure == self.structure_id()) {
            Some(e) if !e.cpu => Err(Error::InvalidInput(format!(
                "accel '{}' traces rays only on a GPU with ray queries (its ray-tracing hardware), not on the \
                 CPU: use --backend gpu on such a GPU, or another structure (--accel bvh) on the CPU",
                e.name
            ))),
            _ => Ok(()),
        }
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
    /// structure over the same triangles shares (`binning::grid_bounds`).
    pub fn bounds(&self) -> Aabb {
        dispatch!(&self.structure, s => AccelStructure::bounds(s, &self.tris))
    }

    /// Which structure it is (the registry's `structure` column).
    pub fn structure_id(&self) -> StructureId {
        self.structure.id()
    }

    /// The structure's name, for messages.
    pub fn structure_name(&self) -> &'static str {
        self.structure.name()
    }

    /// The traversal its walks run (`Structure::kind`).
    pub fn kind(&self) -> AccelKind {
        self.structure.kind()
    }

    /// `Structure::set_traversal`: `grid` and `pc` switch in place; any other change is an
    /// error that says to prepare the scene for it.
    pub fn set_traversal(&mut self, kind: AccelKind) -> Result<()> {
        self.structure.set_traversal(kind)
    }

    /// This structure switched to `kind` (`set_traversal`), as a new value.
    pub fn with_traversal(mut self, kind: AccelKind) -> Result<Accel> {
        self.set_traversal(kind)?;
        Ok(self)
    }

    /// The structure in a few words (`AccelStructure::summary`).
    pub fn summary(&self) -> String {
        dispatch!(&self.structure, s => AccelStructure::summary(s))
    }

    /// The structure's statistics for `gridtrace info`, a `(label, value)` each.
    pub fn info_lines(&self) -> Result<Vec<(String, String)>> {
        dispatch!(&self.structure, s => AccelStructure::info_lines(s, &self.tris))
    }

    /// Closest hit in the ray's interval, by the traversal the structure serves (`kind`: the
    /// grid's `grid` and `pc` differ only in how they cross empty space).
    #[inline]
    pub fn intersect<C: Counters>(&self, ray: &Ray, counters: &mut C) -> Hit {
        walk!(&self.structure, s => Walks::intersect(s, &self.tris, ray, counters))
    }

    /// Any hit in the ray's interval (shadow rays): stops at the first one found.
    #[inline]
    pub fn occluded<C: Counters>(&self, ray: &Ray, counters: &mut C) -> bool {
        walk!(&self.structure, s => Walks::occluded(s, &self.tris, ray, counters))
    }

    /// Closest hits of a packet of up to `PACKET` coherent rays (a 4x2 block of pixels' rays:
    /// the CPU renderer's, `cpu/blocks.rs`), each in its own interval and counted into its own
    /// `counters[i]`: the same hits and counts as `intersect` ray by ray. The irregular grid
    /// walks the packet's rays together, a ray per SIMD lane; the BVH and the uniform grids
    /// interleave the rays' own walks, a step each in turn, so that one ray's chain of
    /// dependent steps overlaps the others'. Hits past `rays.len()` are misses.
    #[inline]
    pub fn intersect_packet<C: Counters>(&self, rays: &[Ray], counters: &mut [C]) -> [Hit; PACKET] {
        walk!(&self.structure, s => Walks::intersect_packet(s, &self.tris, rays, counters))
    }

    /// Whether each of up to `PACKET` rays hits anything in its interval (the shadow rays of a
    /// 4x2 block towards one light), each counted into its own `counters[i]`: the same answers
    /// and counts as `occluded` ray by ray. False past `rays.len()`.
    #[inline]
    pub fn occluded_packet<C: Counters>(&self, rays: &[Ray], counters: &mut [C]) -> [bool; PACKET] {
        walk!(&self.structure, s => Walks::occluded_packet(s, &self.tris, rays, counters))
    }

    /// The batch query: closest hits of `rays`, each in its own interval, handed to
    /// `f(i, hit, normal)` for each ray `rays[i]`, in no particular order, with the hit's
    /// geometric normal (`TriAccel::normal`, unnormalised; zero for a miss). On this thread:
    /// callers split large batches across threads. The BVH interleaves the rays to hide memory
    /// latency and takes the normal from the hit's block while it is still in cache; the
    /// irregular grid takes runs of coherent rays as packets.
    #[inline]
    pub fn intersect_batch_each(&self, rays: &[Ray], f: impl FnMut(usize, Hit, Vec3)) {
        walk!(&self.structure, s => Walks::intersect_batch_each(s, &self.tris, rays, f))
    }

    /// `intersect_batch_each` for the two levels' streams (`Walks::intersect_stream_each`).
    #[inline]
    pub fn intersect_stream_each(&self, rays: &[Ray], f: impl FnMut(usize, Hit, Vec3)) {
        walk!(&self.structure, s => Walks::intersect_stream_each(s, &self.tris, rays, f))
    }

    /// Closest hits of a batch into `out` (`out[i]` for `rays[i]`), like `intersect_batch_each`.
    pub fn intersect_batch(&self, rays: &[Ray], out: &mut [Hit]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        self.intersect_batch_each(rays, |i, hit, _| out[i] = hit);
    }

    /// Any-hit results of a batch into `out` (`out[i]` for `rays[i]`).
    pub fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        walk!(&self.structure, s => Walks::occluded_batch(s, &self.tris, rays, out))
    }

    /// Every hit in the ray's interval, each triangle once, appended to `out` in no particular
    /// order (`Walks::all_hits`).
    #[inline]
    pub fn all_hits(&self, ray: &Ray, out: &mut Vec<Hit>) {
        walk!(&self.structure, s => Walks::all_hits(s, &self.tris, ray, out))
    }

    /// How many triangles each ray of a batch hits in its interval (`out[i]` for `rays[i]`;
    /// `Walks::count_hits_batch`): the number of hits `all_hits` lists.
    pub fn count_hits_batch(&self, rays: &[Ray], out: &mut [u32]) {
        assert_eq!(rays.len(), out.len(), "one count per ray");
        walk!(&self.structure, s => Walks::count_hits_batch(s, &self.tris, rays, out))
    }

    /// The point of the mesh nearest to `p`, through the structure's own search
    /// (`Walks::closest_point`; brute force where it has none).
    pub fn closest_point(&self, p: Vec3) -> closest::ClosestPoint {
        walk!(&self.structure, s => Walks::closest_point(s, &self.tris, p))
    }

    /// The nearest points of a batch, `out[i]` for `points[i]`, on this thread
    /// (`Walks::closest_points_batch`): `closest_point`'s answers.
    pub fn closest_points_batch(&self, points: &[[f32; 3]], out: &mut [closest::ClosestPoint]) {
        assert_eq!(points.len(), out.len(), "one answer per point");
        walk!(&self.structure, s => Walks::closest_points_batch(s, &self.tris, points, out))
    }

    /// The geometric normal (`TriAccel::normal`, unnormalised) of a hit's triangle; zero for a
    /// miss.
    pub fn hit_normal(&self, hit: &Hit) -> Vec3 {
        contract::hit_normal(&self.tris, hit)
    }

    /// Bytes of each array the structure traverses (the triangles included).
    pub fn memory(&self) -> Vec<(&'static str, usize)> {
        let mut v = dispatch!(&self.structure, s => AccelStructure::memory(s));
        v.push(("triangles", std::mem::size_of_val(self.tris.as_slice())));
        v
    }
}
