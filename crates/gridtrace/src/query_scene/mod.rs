//! A scene of several triangle meshes for programs, with the queries (and the names) of
//! Open3D's `RaycastingScene`: geometries added with an id and a 4x4 transform each, moved or
//! removed; closest hits, occlusion, counts and lists of every hit along rays; closest points,
//! distances, signed distances and occupancy at points. The structure (`AccelChoice`, `auto`
//! by default) and the backend are chosen as for `TraceMesh`.
//!
//! ```
//! use gridtrace::query_scene::{QueryScene, INVALID_ID};
//! use gridtrace::query::{Backend, QueryOptions};
//! use glam::Mat4;
//!
//! let opts = QueryOptions { backend: Backend::Cpu, ..Default::default() };
//! let mut scene = QueryScene::new(opts);
//! // A unit square in z = 0, and the same square lifted to z = 1.
//! let v = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
//! let f = vec![[0, 1, 2], [0, 2, 3]];
//! let low = scene.add_triangles(v.clone(), f.clone(), None)?;
//! let high = scene.add_triangles(v, f, Some(Mat4::from_translation([0.0, 0.0, 1.0].into())))?;
//!
//! // A ray down from z = 3 hits the high square first, at t = 2.
//! let rays = [[0.25, 0.75, 3.0, 0.0, 0.0, -1.0], [5.0, 5.0, 3.0, 0.0, 0.0, -1.0]];
//! let hits = scene.cast_rays(&rays)?;
//! assert_eq!((hits.t_hit[0], hits.geometry_ids[0], hits.primitive_ids[0]), (2.0, high, 1));
//! assert_eq!((hits.t_hit[1], hits.geometry_ids[1]), (f32::INFINITY, INVALID_ID));
//! assert_eq!(scene.count_intersections(&rays)?, vec![2, 0]);
//!
//! // The nearest point to (0.5, 0.5, 0.25) is on the low square.
//! let near = scene.compute_closest_points(&[[0.5, 0.5, 0.25]])?;
//! assert_eq!((near.geometry_ids[0], near.points[0]), (low, [0.5, 0.5, 0.0]));
//! scene.remove(low)?;
//! assert_eq!(scene.compute_distance(&[[0.5, 0.5, 0.25]])?, vec![0.75]);
//! # Ok::<(), gridtrace::Error>(())
//! ```
//!
//! **Conventions** (Open3D's): a ray is `[ox, oy, oz, dx, dy, dz]`, `t` in units of the
//! direction's length; a miss has `t_hit = inf` and ids `INVALID_ID` (`u32::MAX`); uvs are the
//! barycentric weights of a face's second and third vertex; normals are the unit geometric
//! normal `(v1 - v0) x (v2 - v0)` of the face in world space (not flipped towards the ray).
//! Rays with a non-finite component or a zero direction miss (they are no error here, unlike
//! `TraceMesh`); points with a non-finite coordinate get NaN distances and `INVALID_ID`.
//!
//! **Two levels.** Each geometry is an instance: a mesh (its triangles in its own space, shared
//! by every instance of it: `add_instance`), a 4x4 affine transform, a 32-bit mask. On the CPU
//! the ray queries walk two levels (`two_level.rs`): each mesh's own structure, built once in
//! its own space, under a BVH over the instances' world boxes (`top_level.rs`); a ray is carried
//! into an instance's space with its direction not normalised, so `t` is the same `t` in both.
//! Moving instances (`set_transform`, `set_transforms`) or changing masks rebuilds the top
//! level only. Every ray query takes each ray's interval and mask (`RayOptions`: the `_with`
//! forms).
//!
//! **On the GPU** (`gpu_rays.rs`): where the backend traces on a GPU, whatever the meshes' structure,
//! closest hits and occlusion walk the two levels there too
//! (`gpu::walks::two_level`): each mesh's structure uploaded once, a move uploads the top level
//! alone (`gpu_uploads` reports the bytes). With `hwrt` the two levels are the driver's (a BLAS
//! a mesh, built once; a TLAS instance a scene instance, rebuilt alone by a move:
//! `gpu::walks::hwrt::instances`).
//!
//! **The merged path.** Where the backend traces on a GPU and the structure has no two-level
//! walk (none today), the ray queries whose rays all share one interval and see every
//! geometry still run on one world-space mesh of every geometry's triangles (`merged.rs`), as
//! do the point queries (closest points, distances, signed distances, occupancy, winding
//! numbers), except on the CPU in a moving scene whose every instance is placed by a
//! similarity, where they all run on the two levels (`two_level_points.rs`): a change marks
//! the merged mesh stale and the next query that uses it rebuilds it,
//! except `update_vertices` on a built scene, which moves the vertices of the built mesh (the
//! BVH refits) when that gives what a rebuild would. `ray_path` is where that is decided.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use glam::Mat4;

use crate::placement::QueryPlacement;
use crate::query::QueryOptions;
use crate::{Error, Result};

mod all_hits;
mod batch;
mod cpu_rays;
mod enclosure;
mod geometry;
mod gpu_all_hits;
mod gpu_rays;
mod gpu_scan;
mod instanced_rays;
mod instances;
mod last_query;
mod merged;
mod points;
mod rays;
mod streamed_rays;
mod top_level;
mod two_level;
mod two_level_points;
mod winding_only;

pub use all_hits::Intersections;
pub use batch::{PerRay, RayHits, RayOptions};
pub use geometry::{Geometry, SceneMesh};
pub use gpu_rays::GpuUploads;
pub use instances::InstanceOf;
pub use last_query::LastQuery;
pub use points::ClosestPoints;

use merged::Merged;
use two_level::TwoLevel;

/// The id of no geometry and no primitive (a miss): Open3D's `INVALID_ID`.
pub const INVALID_ID: u32 = u32::MAX;

/// Several triangle meshes, each with an id and a transform, and the queries over them.
/// Queries take `&self` and may run from several threads at once; changes take `&mut self`.
pub struct QueryScene {
    opts: QueryOptions,
    geometries: BTreeMap<u32, Geometry>,
    next_id: u32,
    /// The merged mesh; `None` when a change made it stale (the next query rebuilds it).
    merged: Mutex<Option<Arc<Merged>>>,
    /// The two levels' records and top level; `None` when a change made them stale.
    two_level: Mutex<Option<Arc<TwoLevel>>>,
    /// Structures built over triangles so far: bottom levels and merged meshes (for tests:
    /// a move must build none).
    builds: AtomicUsize,
    /// The two levels on the GPU, once a GPU ray query ran on them (`gpu_rays.rs`); kept
    /// across moves, which upload its top level alone.
    gpu: Mutex<Option<gpu_rays::GpuTwoLevel>>,
    /// Whether the scene moves: set by `add_instance`, `set_transform(s)` and `set_mask` (and
    /// by `from_parts` when meshes are shared). `ray_path` sends a static scene's CPU rays to
    /// the merged mesh, one structure over every triangle, and a moving one's to the two
    /// levels, whose moves build nothing.
    moving: bool,
    /// What the last query did (`last_query.rs`).
    records: Mutex<last_query::Records>,
    /// The winding numbers' faces and tree while the merged mesh is not built
    /// (`winding_only.rs`); `None` when a change made them stale.
    winding_only: Mutex<Option<Arc<winding_only::WindingOnly>>>,
    /// Where its GPU work goes, the device opened on first need (or given: `adopt_device`),
    /// shared by the two levels and the merged meshes.
    placement: Arc<QueryPlacement>,
}

/// Where a ray query runs (`QueryScene::ray_path`).
pub(crate) enum RayPath {
    /// The merged mesh (a backend that traces on a GPU, a structure the GPU does not carry
    /// under a top level, rays that share one interval and see every geometry).
    Merged,
    /// The CPU's two levels.
    Cpu(Arc<TwoLevel>),
    /// The GPU's two levels (`gpu_rays.rs`).
    Gpu(Arc<TwoLevel>),
}

impl QueryScene {
    /// An empty scene whose queries use `opts` (structure, grid and irregular parameters,
    /// backend).
    pub fn new(opts: QueryOptions) -> QueryScene {
        QueryScene {
            geometries: BTreeMap::new(),
            next_id: 0,
            merged: Mutex::new(None),
            two_level: Mutex::new(None),
            builds: AtomicUsize::new(0),
            gpu: Mutex::new(None),
            moving: false,
            records: Mutex::default(),
            winding_only: Mutex::new(None),
            placement: Arc::new(QueryPlacement::new(opts.backend, opts.gpu_variants)),
            opts,
        }
    }

    /// The options the scene was made with.
    pub fn options(&self) -> &QueryOptions {
        &self.opts
    }

    /// Adds a mesh (vertices in its own space, faces indexing them) placed by `transform`
    /// (identity when `None`); returns its id, 0 for the first and counting up (ids of removed
    /// geometries are not reused). Non-finite coordinates or transforms and faces out of range
    /// are errors naming the argument. Zero-area faces are kept in the numbering but never hit.
    pub fn add_triangles(
        &mut self,
        vertices: Vec<[f32; 3]>,
        faces: Vec<[u32; 3]>,
        transform: Option<Mat4>,
    ) -> Result<u32> {
        let g = Geometry::new(vertices, faces, transform)?;
        self.push(g)
    }

    /// Adds `g` under the next id.
    fn push(&mut self, g: Geometry) -> Result<u32> {
        let id = self.next_id;
        self.next_id = id
            .checked_add(1)
            .filter(|&n| n != INVALID_ID)
            .ok_or_else(|| Error::InvalidInput("no geometry ids left".into()))?;
        self.insert(id, g);
        Ok(id)
    }

    /// Adds a mesh file (OBJ, PLY, glTF/GLB, STL, OFF), as `add_triangles`.
    pub fn add_file(&mut self, path: &Path, transform: Option<Mat4>) -> Result<u32> {
        let mesh = crate::io::load_mesh(path)?;
        let vertices = mesh.positions.iter().map(|p| p.to_array()).collect();
        self.add_triangles(vertices, mesh.triangles, transform)
    }

    /// Rebuilds a scene from its parts, ids kept (for deserialising): `next_id` is the id the
    /// next `add_triangles` returns; `meshes` are (vertices, faces), each once; `instances` are
    /// (id, index into `meshes`, transform, mask), so that instances of one mesh share it again.
    /// An id twice or not below `next_id`, or a mesh index out of range, is an error.
    #[allow(clippy::type_complexity)]
    pub fn from_parts(
        opts: QueryOptions,
        next_id: u32,
        meshes: Vec<(Vec<[f32; 3]>, Vec<[u32; 3]>)>,
        instances: Vec<(u32, usize, Mat4, u32)>,
    ) -> Result<QueryScene> {
        let mut scene = QueryScene::new(opts);
        scene.next_id = next_id;
        let meshes = meshes
            .into_iter()
            .map(|(v, f)| SceneMesh::new(v, f).map(Arc::new))
            .collect::<Result<Vec<_>>>()?;
        for (id, mesh, transform, mask) in instances {
            if id >= next_id || scene.geometries.contains_key(&id) {
                return Err(Error::InvalidInput(format!(
                    "geometry id {id} is repeated or not below the next id {next_id}"
                )));
            }
            let m = meshes.get(mesh).ok_or_else(|| {
                Error::InvalidInput(format!("geometry {id} names mesh {mesh}; there are {}", meshes.len()))
            })?;
            let g = Geometry::place(m.clone(), transform, mask, &format!("transform of geometry {id}"))?;
            // A mesh placed twice: the scene was made with instances.
            scene.moving |= Arc::strong_count(m) > 2;
            scene.insert(id, g);
        }
        Ok(scene)
    }

    /// The scene's parts (`from_parts` takes them back): each mesh once, and each geometry as
    /// (id, index into the meshes, transform, mask).
    #[allow(clippy::type_complexity)]
    pub fn parts(&self) -> (Vec<&SceneMesh>, Vec<(u32, usize, Mat4, u32)>) {
        let mut meshes: Vec<&SceneMesh> = Vec::new();
        let mut index = std::collections::HashMap::new();
        let instances = self
            .geometries
            .iter()
            .map(|(&id, g)| {
                let k = *index.entry(Arc::as_ptr(g.mesh())).or_insert_with(|| {
                    meshes.push(g.mesh().as_ref());
                    meshes.len() - 1
                });
                (id, k, g.transform(), g.mask())
            })
            .collect();
        (meshes, instances)
    }

    fn insert(&mut self, id: u32, g: Geometry) {
        self.geometries.insert(id, g);
        self.stale();
    }

    /// Marks what a change to the geometries makes stale: the merged mesh and the two levels'
    /// top (the bottom levels belong to the meshes and stay).
    fn stale(&mut self) {
        *self.merged.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
        *self.winding_only.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
        // The GPU's renderer stays: the next query uploads what changed (`gpu_rays.rs`).
        *self.two_level.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
    }

    /// The id the next `add_triangles` returns.
    pub fn next_id(&self) -> u32 {
        self.next_id
    }

    /// The geometries' ids, ascending.
    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.geometries.keys().copied()
    }

    /// Geometry `id` as it was given (own-space vertices, faces, transform).
    pub fn geometry(&self, id: u32) -> Option<&Geometry> {
        self.geometries.get(&id)
    }

    /// Whether geometry `id` is in the scene.
    pub fn contains(&self, id: u32) -> bool {
        self.geometries.contains_key(&id)
    }

    /// Removes geometry `id`; an unknown id is an error naming it.
    pub fn remove(&mut self, id: u32) -> Result<()> {
        self.geometries.remove(&id).ok_or_else(|| unknown(id))?;
        self.stale();
        Ok(())
    }

    /// Moves geometry `id`'s vertices (own space, as many as it has, same order; faces and
    /// transform stay). On a built scene the structure is updated in place where that gives
    /// the same answers as a rebuild (the BVH refits); else the next query rebuilds. An
    /// unknown id, a wrong count or a non-finite coordinate is an error that changes nothing.
    pub fn update_vertices(&mut self, id: u32, vertices: Vec<[f32; 3]>) -> Result<()> {
        let g = self.geometries.get_mut(&id).ok_or_else(|| unknown(id))?;
        g.set_vertices(vertices)?;
        let world = g.world_vertices();
        // The geometry has a mesh of its own now: its bottom level is built on the next query.
        *self.two_level.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
        *self.winding_only.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
        let slot = self.merged.get_mut().unwrap_or_else(|p| p.into_inner());
        // In place only when no query holds the merged mesh (`Arc` unique).
        let updated = match slot.as_mut().and_then(Arc::get_mut) {
            Some(m) => m.update(id, &world).unwrap_or(false),
            None => false,
        };
        if !updated {
            *slot = None;
        }
        Ok(())
    }

    /// Triangles in the scene (all faces, zero-area ones included).
    pub fn triangle_count(&self) -> usize {
        self.geometries.values().map(|g| g.faces().len()).sum()
    }

    /// The merged mesh, built now if a change made it stale. Concurrent queries share it; the
    /// first after a change builds it while the others wait.
    fn merged(&self) -> Result<Arc<Merged>> {
        let mut slot = self.merged.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(m) = slot.as_ref() {
            return Ok(m.clone());
        }
        // Where the scene places its work, unless a fault sent the scene to the CPU: then a
        // placement of the mesh's own, which its queries never use (`on_mesh`).
        let own = || Arc::new(QueryPlacement::new(self.opts.backend, self.opts.gpu_variants));
        let placement = if self.failed_over() {
            own()
        } else {
            self.placement.clone()
        };
        let m = match Merged::build(&self.geometries, &self.opts, placement) {
            // Opening the renderer on a device that failed is a fault like any other: under
            // `auto` the scene's queries then run on the CPU, the mesh with them.
            Err(Error::Gpu(e)) if self.opts.backend == crate::query::Backend::Auto => {
                self.gpu_fault(&e);
                Merged::build(&self.geometries, &self.opts, own())?
            }
            r => r?,
        };
        let m = Arc::new(m);
        self.builds.fetch_add(1, Ordering::Relaxed);
        *slot = Some(m.clone());
        Ok(m)
    }

    /// The two levels, their top rebuilt now if a change made it stale (and any mesh's bottom
    /// level built that has none yet).
    fn two_level(&self) -> Result<Arc<TwoLevel>> {
        let mut slot = self.two_level.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(t) = slot.as_ref() {
            return Ok(t.clone());
        }
        let t = Arc::new(TwoLevel::build(&self.geometries, &self.opts, &self.builds)?);
        *slot = Some(t.clone());
        Ok(t)
    }

    /// Where a ray query with `o` runs, decided here alone: with a backend that traces on a GPU,
    /// on the GPU's two levels where it carries the meshes' structure (`gpu_carries`: the BVH,
    /// the grid and brute force), else on the merged mesh where the rays share one interval and see
    /// every geometry, else on the CPU's two levels. With the CPU: a static scene's rays that
    /// share one interval and see every geometry on the merged mesh (one structure over every
    /// triangle: a room and five Bunnies' camera rays took 2.4x as long through two levels),
    /// the others on the CPU's two levels (`moving`).
    fn ray_path(&self, o: &RayOptions) -> Result<RayPath> {
        let merged_answers = || self.merged_answers(o);
        if !self.traces_on_gpu() {
            if !self.moving && merged_answers() {
                return Ok(RayPath::Merged);
            }
            return self.two_level().map(RayPath::Cpu);
        }
        let two = self.two_level()?;
        if self.gpu_carries(&two) {
            return Ok(RayPath::Gpu(two));
        }
        Ok(if merged_answers() {
            RayPath::Merged
        } else {
            RayPath::Cpu(two)
        })
    }

    /// Whether the merged mesh answers rays with `o`: one interval, not empty, and a mask that
    /// sees every geometry.
    pub(super) fn merged_answers(&self, o: &RayOptions) -> bool {
        o.uniform().is_some_and(|(t_near, t_far, mask)| {
            t_near <= t_far && self.geometries.values().all(|g| g.mask() & mask != 0)
        })
    }

    /// Structures built over triangles so far by this scene: each mesh's bottom level (once,
    /// however many instances share it) and each merged mesh. For tests: a move builds none.
    pub fn structure_builds(&self) -> usize {
        self.builds.load(Ordering::Relaxed)
    }

    /// Where the ray queries run: "cpu (N threads)" or the GPU adapter (builds the scene);
    /// after a GPU fault under `auto`, the CPU and why.
    pub fn device(&self) -> Result<String> {
        if let Some(why) = self.gpu_failure().filter(|_| self.failed_over()) {
            return Ok(format!("{} (the GPU failed: {why})", crate::backend::describe_cpu()));
        }
        let m = self.merged()?;
        Ok(m.mesh
            .as_ref()
            .map_or_else(crate::backend::describe_cpu, |mesh| mesh.device()))
    }

    /// The structure the queries walk (`auto` resolved), in a word; "none" for a scene with
    /// no triangle to hit (builds the scene).
    pub fn accel_name(&self) -> Result<&'static str> {
        let m = self.merged()?;
        Ok(m.mesh.as_ref().map_or("none", |mesh| mesh.accel().name()))
    }
}

pub(crate) fn unknown(id: u32) -> Error {
    Error::InvalidInput(format!("unknown geometry id {id}"))
}
