//! Ray queries for programs: build an accelerated mesh from plain arrays (or a file) and cast
//! batches of rays at it, on the CPU or the GPU, with the same answers either way.
//!
//! ```
//! use gridtrace::query::{Backend, QueryOptions, TraceMesh};
//!
//! // A unit square in the z = 0 plane, two triangles.
//! let vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
//! let faces = [[0, 1, 2], [0, 2, 3]];
//! let opts = QueryOptions { backend: Backend::Cpu, ..Default::default() };
//! let mesh = TraceMesh::from_arrays(&vertices, &faces, &opts)?;
//!
//! // One ray straight down through (0.25, 0.75), one that misses. Directions need not be unit
//! // length: t is in units of the direction's length.
//! let origins = [[0.25, 0.75, 2.0], [5.0, 5.0, 2.0]];
//! let dirs = [[0.0, 0.0, -2.0], [0.0, 0.0, -1.0]];
//! let hits = mesh.intersect(&origins, &dirs, 0.0, f32::INFINITY)?;
//! assert_eq!(hits.t[0], 1.0);
//! assert_eq!(hits.tri[0], 1);
//! assert_eq!(hits.t[1], f32::INFINITY);
//! assert_eq!(hits.tri[1], u32::MAX);
//! assert_eq!(hits.normal[0], [0.0, 0.0, 1.0]);
//!
//! // Occlusion within [t_min, t_max]: the first ray's hit lies at t = 1.
//! assert_eq!(mesh.occluded(&origins, &dirs, 0.0, 0.5)?, vec![false, false]);
//! assert_eq!(mesh.occluded(&origins, &dirs, 0.0, 1.5)?, vec![true, false]);
//! # Ok::<(), gridtrace::Error>(())
//! ```

use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use glam::{Mat4, Vec3};

use crate::accel::{AccelKind, AccelSpec, Work};
use crate::gpu::{GpuRenderer, GpuVariants};
use crate::placement::QueryPlacement;
use crate::scene::{Mesh, PreparedScene, RebuildOn, Scene};
use crate::{Error, Result};

mod batch;
mod fallback;
mod hits;
mod points;
mod rays;
mod wire;

/// What a mesh's last query did (`TraceMesh::last_query`): the scene's record.
pub use crate::query_scene::LastQuery;
pub use batch::CHUNK;
pub(crate) use fallback::{Answered, limit_note};
pub use hits::Hits;

/// Where ray queries run (the same choice as rendering's).
pub use crate::backend::Backend;

#[derive(Debug, Clone, PartialEq)]
pub struct QueryOptions {
    /// The structure and its build parameters, or `auto` (the one measured fastest for ray
    /// batches; `TraceMesh::notes` says which it picked).
    pub accel: AccelSpec,
    pub backend: Backend,
    /// The GPU kernels and layouts, where the queries run on a GPU (`gpu::variants`).
    pub gpu_variants: GpuVariants,
}

impl Default for QueryOptions {
    fn default() -> Self {
        QueryOptions {
            accel: AccelSpec::default(),
            backend: Backend::Auto,
            gpu_variants: GpuVariants::default(),
        }
    }
}

/// An accelerated triangle mesh for ray queries.
pub struct TraceMesh {
    scene: PreparedScene,
    /// Input face index of each kept (non-degenerate) triangle; `None` when every face was
    /// kept, the usual case, which spares every hit a lookup (a cache miss; a few per cent of a
    /// query).
    original: Option<Vec<u32>>,
    /// What was chosen for the caller (`auto`'s pick), in words.
    notes: Vec<String>,
    /// The backend its queries run on unless told otherwise (`placement`'s).
    backend: Backend,
    /// Where its work goes, the device opened on first need (a scene's, shared by its meshes).
    placement: Arc<QueryPlacement>,
    /// The GPU renderer, opened on first use (or the reason it could not be).
    gpu: OnceLock<std::result::Result<(Mutex<GpuRenderer>, String), String>>,
    /// Why `auto` queries left the GPU for good, once a GPU fault sent them to the CPU
    /// (`fallback.rs`).
    gpu_failed: Mutex<Option<String>>,
    /// What the last answered query did (`fallback.rs`, `last_query`).
    last: Mutex<LastQuery>,
}

impl TraceMesh {
    /// Builds from vertex positions and triangles (indices into `vertices`). Degenerate
    /// triangles are skipped (they can never be hit); indices out of range and non-finite
    /// coordinates are errors.
    pub fn from_arrays(vertices: &[[f32; 3]], faces: &[[u32; 3]], opts: &QueryOptions) -> Result<TraceMesh> {
        Self::from_arrays_on(vertices, faces, opts, None)
    }

    /// `from_arrays` with its GPU work placed by `placement` where one is given (a scene's,
    /// shared by its meshes), instead of a placement of its own.
    pub(crate) fn from_arrays_on(
        vertices: &[[f32; 3]],
        faces: &[[u32; 3]],
        opts: &QueryOptions,
        placement: Option<Arc<QueryPlacement>>,
    ) -> Result<TraceMesh> {
        let n = vertices.len() as u32;
        if let Some(i) = vertices.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
            return Err(Error::InvalidInput(format!(
                "vertex {i} has a non-finite coordinate {:?}",
                vertices[i]
            )));
        }
        if let Some(i) = faces.iter().position(|f| f.iter().any(|&x| x >= n)) {
            return Err(Error::InvalidInput(format!(
                "face {i} {:?} indexes a vertex out of range ({n} vertices)",
                faces[i]
            )));
        }
        let mesh = Mesh {
            positions: vertices.iter().map(|&v| Vec3::from(v)).collect(),
            triangles: faces.to_vec(),
            ..Default::default()
        };
        Self::from_mesh_on(mesh, opts, placement)
    }

    /// Loads a mesh file (OBJ, PLY, glTF/GLB, STL, OFF).
    pub fn load(path: &Path, opts: &QueryOptions) -> Result<TraceMesh> {
        Self::from_mesh(crate::io::load_mesh(path)?, opts)
    }

    pub fn from_mesh(mesh: Mesh, opts: &QueryOptions) -> Result<TraceMesh> {
        Self::from_mesh_on(mesh, opts, None)
    }

    fn from_mesh_on(mesh: Mesh, opts: &QueryOptions, placement: Option<Arc<QueryPlacement>>) -> Result<TraceMesh> {
        // Keep the input face order: drop degenerate faces here and remember where each kept
        // one came from, so hits report input indices.
        let mesh_faces = mesh.triangles.len();
        let mut original = Vec::with_capacity(mesh_faces);
        let mut kept = Vec::with_capacity(mesh_faces);
        for (i, t) in mesh.triangles.iter().enumerate() {
            let [a, b, c] = t.map(|k| mesh.positions[k as usize]);
            if (b - a).cross(c - a).length_squared() > 0.0 {
                original.push(i as u32);
                kept.push(*t);
            }
        }
        if kept.is_empty() {
            return Err(Error::InvalidInput(format!(
                "mesh has no triangles with non-zero area ({} faces given)",
                mesh.triangles.len()
            )));
        }
        let mut scene = Scene::default();
        scene.add_mesh(
            Mesh {
                positions: mesh.positions,
                normals: Vec::new(),
                triangles: kept,
                ..Default::default()
            },
            Mat4::IDENTITY,
            None,
        );
        // Ray queries do not use the camera, but preparing validates one: aim it at the mesh.
        let b = scene.bounds();
        scene.camera.target = b.center();
        scene.camera.eye = b.center() + Vec3::new(0.0, 0.0, b.diagonal().max(1.0));
        let placement = placement.unwrap_or_else(|| Arc::new(QueryPlacement::new(opts.backend, opts.gpu_variants)));
        let (accel, note) = opts.accel.resolve(placement.traced_on(), Work::Rays);
        let prepared = scene.prepare_for(accel, &opts.accel.params)?;
        debug_assert_eq!(prepared.accel.tris.len(), original.len());
        let all_kept = original.len() == mesh_faces;
        let mesh = TraceMesh {
            scene: prepared,
            original: (!all_kept).then_some(original),
            notes: note.into_iter().collect(),
            backend: placement.backend(),
            placement,
            gpu: OnceLock::new(),
            gpu_failed: Mutex::new(None),
            last: Mutex::default(),
        };
        if mesh.placement.is_given() {
            // On a device given, opened now: a device that fails there is the caller's fault
            // to handle (`QueryScene::merged`), as it is when the device is given to the mesh.
            mesh.upload_given()?;
        }
        // Open the GPU now when it was asked for, so a missing adapter is reported at once.
        if opts.backend == Backend::Gpu {
            mesh.renderer(Backend::Gpu)?;
        }
        Ok(mesh)
    }

    /// The traversal the queries run (`auto` resolved): the structure's own (`Accel::kind`).
    pub fn accel(&self) -> AccelKind {
        self.scene.accel.kind()
    }

    /// What was chosen for the caller, in words (`auto`'s pick and why).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Triangles kept (non-degenerate).
    pub fn triangle_count(&self) -> usize {
        self.scene.accel.tris.len()
    }

    /// The GPU renderer for `backend`: `None` means the CPU. `Gpu` without an adapter is an
    /// error; `Auto` falls back to the CPU.
    fn renderer(&self, backend: Backend) -> Result<Option<&Mutex<GpuRenderer>>> {
        let r = self.open_renderer(backend)?;
        if r.is_none() {
            // A grid the GPU rebuilt after `update_vertices` is not the CPU's to trace.
            self.scene.accel.check_current()?;
        }
        Ok(r)
    }

    fn open_renderer(&self, backend: Backend) -> Result<Option<&Mutex<GpuRenderer>>> {
        // `auto` passes a software adapter over for the CPU tracer before compiling or
        // uploading anything to it (`QueryPlacement::traces_on_gpu`); and leaves a GPU that
        // failed.
        if !self.placement.traces_on_gpu(backend) || (backend == Backend::Auto && self.failed_over()) {
            return Ok(None);
        }
        let opened = self.gpu.get_or_init(|| self.upload(backend));
        match (opened, backend) {
            (Ok((r, _)), _) => Ok(Some(r)),
            (Err(e), Backend::Gpu) => Err(Error::Gpu(e.clone())),
            (Err(_), _) => Ok(None),
        }
    }

    /// The mesh on the device its placement gives for `backend` (`QueryPlacement::placement`,
    /// then `Placement::upload`: the rules frames follow), with where in words; or why not.
    fn upload(&self, backend: Backend) -> std::result::Result<(Mutex<GpuRenderer>, String), String> {
        let mut notes = Vec::new();
        let placement = self
            .placement
            .placement(backend, &mut notes)
            .map_err(|e| e.to_string())?;
        match placement.upload(&self.scene, &mut notes) {
            Ok(Some(r)) => {
                let d = format!("gpu: {}", r.context().describe());
                Ok((Mutex::new(r), d))
            }
            Ok(None) => Err(notes.join("; ")),
            Err(e) => Err(e.to_string()),
        }
    }

    /// The backend this mesh's queries run on unless told otherwise.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// Where queries with this mesh's default backend run: "cpu (N threads)" or the adapter.
    pub fn device(&self) -> String {
        self.device_for(self.backend)
    }

    /// Where queries with `backend` run (opens the GPU if needed).
    pub fn device_for(&self, backend: Backend) -> String {
        let cpu = crate::backend::describe_cpu;
        match self.renderer(backend) {
            Ok(Some(_)) => self
                .gpu
                .get()
                .and_then(|r| r.as_ref().ok())
                .map(|(_, d)| d.clone())
                .unwrap_or_else(cpu),
            Ok(None) => match (self.gpu.get(), self.gpu_failure()) {
                (_, Some(why)) if backend == Backend::Auto => format!("{} ({why})", cpu()),
                (Some(Err(e)), _) => format!("{} (no GPU: {e})", cpu()),
                _ => cpu(),
            },
            Err(e) => format!("unavailable: {e}"),
        }
    }

    /// Moves the mesh's vertices (as many as it was made with, in the same order; the faces
    /// stay) and updates the structure on the device the mesh traces on: with its GPU open,
    /// the grid is rebuilt there (every other structure on the CPU, and uploaded), else on the
    /// CPU (grids rebuilt, the BVH refitted). A wrong length or a non-finite coordinate is an
    /// error that leaves the previous mesh in place. Faces dropped as degenerate when the mesh
    /// was made stay dropped.
    pub fn update_vertices(&mut self, vertices: &[[f32; 3]]) -> Result<()> {
        let positions: Vec<Vec3> = vertices.iter().map(|&v| Vec3::from(v)).collect();
        let gpu = match self.gpu.get_mut() {
            Some(Ok((r, _))) => Some(r.get_mut().unwrap_or_else(|p| p.into_inner())),
            _ => None,
        };
        // On the device only where this mesh's own queries trace there: a renderer opened for
        // one `gpu` query of a CPU mesh (or a software adapter under `auto`) must leave the
        // CPU's structure current. The renderer, if any, is brought up to date either way.
        let on = if gpu.is_some() && self.backend.traces_on_gpu() {
            RebuildOn::Device
        } else {
            RebuildOn::Cpu
        };
        self.scene.update_vertices(&positions, on)?;
        if let Some(g) = gpu {
            g.update_vertices(&self.scene)?;
        }
        Ok(())
    }

    pub fn prepared(&self) -> &PreparedScene {
        &self.scene
    }

    /// What the last batch on the GPU took (wall and GPU time, round trips, bytes), with the
    /// frame's meanings; `None` while no batch has run on the GPU.
    pub fn last_gpu_batch(&self) -> Option<crate::gpu::GpuQueryStats> {
        match self.gpu.get() {
            Some(Ok((g, _))) => Some(locked(g).last_query_stats().clone()).filter(|s| s.round_trips > 0),
            _ => None,
        }
    }

    /// Input face index of a kept triangle index.
    #[inline]
    pub fn original_index(&self, kept: u32) -> u32 {
        self.original.as_ref().map_or(kept, |o| o[kept as usize])
    }
}

/// The GPU renderer, for one query at a time. A query that panicked while holding it left
/// nothing half-written that the next one reads (each uploads its own rays), so a poisoned lock
/// is taken as it is.
fn locked(gpu: &Mutex<GpuRenderer>) -> MutexGuard<'_, GpuRenderer> {
    gpu.lock().unwrap_or_else(|p| p.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::{Hit, NoCounters, Ray, brute_force_intersect};
    use crate::testing::triangle_soup;

    /// Empty, single and broadcast batches, on every backend and structure: every pair of
    /// lengths 0..=3 (origins, directions). Lengths that match, or where one side is 1, give
    /// `batch_len` results equal to the one-ray queries; others are errors. Never a panic (an
    /// empty batch against one broadcast ray used to index past the end on the GPU path).
    #[test]
    fn empty_single_and_broadcast_batches() {
        let vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let faces = [[0u32, 1, 2]];
        let origins: Vec<[f32; 3]> = (0..3).map(|i| [0.1 + 0.1 * i as f32, 0.2, 1.0]).collect();
        let dirs: Vec<[f32; 3]> = (0..3).map(|i| [0.0, 0.05 * i as f32, -1.0]).collect();
        // `hwrt` traces only on a GPU, and there only with ray queries.
        let ray_queries = crate::gpu::GpuContext::new().is_ok_and(|c| c.ray_query);
        for accel in AccelKind::ALL {
            let backends = [Backend::Cpu, Backend::Gpu].into_iter().filter(|&b| match b {
                Backend::Cpu => accel.entry().cpu,
                _ => ray_queries || !crate::gpu::walks::needs_ray_queries(accel.structure()),
            });
            for backend in backends {
                let opts = QueryOptions {
                    accel: accel.into(),
                    backend,
                    ..Default::default()
                };
                let mesh = TraceMesh::from_arrays(&vertices, &faces, &opts).unwrap();
                for no in 0..=3 {
                    for nd in 0..=3 {
                        let (o, d) = (&origins[..no], &dirs[..nd]);
                        let want_len = match (no, nd) {
                            (a, b) if a == b => Some(a),
                            (1, b) => Some(b),
                            (a, 1) => Some(a),
                            _ => None,
                        };
                        let what = format!("{} {backend:?}: {no} origins, {nd} directions", accel.name());
                        let hits = mesh.intersect(o, d, 0.0, f32::INFINITY);
                        let occ = mesh.occluded(o, d, 0.0, f32::INFINITY);
                        let Some(n) = want_len else {
                            assert!(hits.is_err() && occ.is_err(), "{what}: must be an error");
                            continue;
                        };
                        let (hits, occ) = (hits.expect(&what), occ.expect(&what));
                        assert_eq!((hits.len(), occ.len()), (n, n), "{what}");
                        for i in 0..n {
                            let one = mesh
                                .intersect(
                                    &[o[if no == 1 { 0 } else { i }]],
                                    &[d[if nd == 1 { 0 } else { i }]],
                                    0.0,
                                    f32::INFINITY,
                                )
                                .unwrap();
                            assert_eq!((hits.t[i], hits.tri[i]), (one.t[0], one.tri[0]), "{what}: ray {i}");
                            assert_eq!(hits.tri[i], 0, "{what}: ray {i} hits the triangle");
                            assert!(occ[i], "{what}: ray {i} occluded");
                        }
                    }
                }
            }
        }
    }

    /// Vertices, faces, ray origins, ray directions.
    type Soup = (Vec<[f32; 3]>, Vec<[u32; 3]>, Vec<[f32; 3]>, Vec<[f32; 3]>);

    /// A soup of triangles as arrays, with (if `degenerate`) a degenerate face after every 7th
    /// (dropped, so kept and input indices differ), and 5,000 rays at it: several CPU work items.
    fn soup(degenerate: bool) -> Soup {
        let tris = triangle_soup(600, 11);
        let mut vertices = Vec::new();
        let mut faces = Vec::new();
        for (i, t) in tris.iter().enumerate() {
            let base = vertices.len() as u32;
            vertices.extend(t.vertices().map(|v| v.to_array()));
            faces.push([base, base + 1, base + 2]);
            if degenerate && i % 7 == 0 {
                faces.push([base, base, base + 1]);
            }
        }
        let mut rng = crate::util::Rng::new(5);
        let origins = (0..5000)
            .map(|_| [rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0)])
            .collect::<Vec<_>>();
        let dirs = (0..5000)
            .map(|_| [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)])
            .collect();
        (vertices, faces, origins, dirs)
    }

    /// The batched CPU query (rays built, traced and written per work item) gives, for every ray,
    /// the brute-force closest hit, reported with the input face index and that face's unit
    /// normal; and occlusion agrees with it.
    #[test]
    fn cpu_queries_equal_brute_force_in_input_terms() {
        let on_cpu = AccelKind::ALL.into_iter().filter(|k| k.entry().cpu);
        for (degenerate, accel) in [false, true]
            .into_iter()
            .flat_map(|d| on_cpu.clone().map(move |a| (d, a)))
        {
            let (vertices, faces, origins, dirs) = soup(degenerate);
            let opts = QueryOptions {
                accel: accel.into(),
                backend: Backend::Cpu,
                ..Default::default()
            };
            let mesh = TraceMesh::from_arrays(&vertices, &faces, &opts).unwrap();
            let hits = mesh.intersect(&origins, &dirs, 0.0, f32::INFINITY).unwrap();
            let occluded = mesh.occluded(&origins, &dirs, 0.0, f32::INFINITY).unwrap();
            let tris = &mesh.prepared().accel.tris;
            let mut hit_count = 0;
            for i in 0..origins.len() {
                let ray = Ray::new(origins[i].into(), dirs[i].into());
                let want = brute_force_intersect(tris, &ray);
                let got = mesh.prepared().accel.intersect(&ray, &mut NoCounters);
                assert_eq!(hits.t[i], got.t, "{} ray {i}", accel.name());
                assert!(
                    (got.t - want.t).abs() <= 1e-6 * want.t.abs() || got.t == want.t,
                    "ray {i}"
                );
                assert_eq!(occluded[i], got.is_hit(), "{} ray {i}", accel.name());
                if got.is_hit() {
                    hit_count += 1;
                    let face = faces[hits.tri[i] as usize].map(|k| Vec3::from(vertices[k as usize]));
                    let normal = (face[1] - face[0]).cross(face[2] - face[0]).normalize();
                    assert_eq!(hits.tri[i], mesh.original_index(got.tri), "ray {i}");
                    assert!(Vec3::from(hits.normal[i]).abs_diff_eq(normal, 1e-5), "ray {i}: normal");
                    assert_eq!((hits.u[i], hits.v[i]), (got.u, got.v), "ray {i}");
                } else {
                    assert_eq!(hits.tri[i], u32::MAX, "ray {i}");
                }
            }
            assert!(hit_count > 500, "{} hits only", hit_count);
        }
    }

    /// `intersect_rays_into` and `occluded_rays_into` reuse a buffer holding a former batch's
    /// answers (longer, then shorter, then longer again than the batch): each time the answers
    /// equal a fresh call's, on the CPU and on the GPU.
    #[test]
    fn reused_answer_buffers_equal_fresh_answers() {
        let (vertices, faces, origins, dirs) = soup(true);
        let rays: Vec<Ray> = origins
            .iter()
            .zip(&dirs)
            .map(|(o, d)| Ray::new(Vec3::from(*o), Vec3::from(*d)))
            .collect();
        let on_gpu = crate::gpu::GpuContext::new().is_ok();
        let backends = [Backend::Cpu, Backend::Gpu]
            .into_iter()
            .filter(|&b| b == Backend::Cpu || on_gpu);
        for backend in backends {
            let opts = QueryOptions {
                accel: AccelKind::Bvh.into(),
                backend,
                ..Default::default()
            };
            let mesh = TraceMesh::from_arrays(&vertices, &faces, &opts).unwrap();
            let (mut hits, mut occ) = (vec![Hit::MISS; 7000], vec![true; 7000]);
            for len in [5000, 1200, 3000] {
                let batch = &rays[..len];
                mesh.intersect_rays_into(backend, &crate::testing::within(batch, 0.0, 1.5), true, &mut hits)
                    .unwrap();
                mesh.occluded_rays_into(backend, &crate::testing::within(batch, 0.0, 1.5), &mut occ)
                    .unwrap();
                let fresh = mesh
                    .intersect_rays_with(backend, &crate::testing::within(batch, 0.0, 1.5))
                    .unwrap();
                let fresh_occ = mesh
                    .occluded_rays_with(backend, &crate::testing::within(batch, 0.0, 1.5))
                    .unwrap();
                assert_eq!(hits.len(), len, "{backend:?}");
                assert!(
                    hits.iter()
                        .zip(&fresh)
                        .all(|(a, b)| (a.t, a.tri, a.u, a.v) == (b.t, b.tri, b.u, b.v)),
                    "{backend:?}: {len} rays into a reused buffer"
                );
                assert_eq!(occ, fresh_occ, "{backend:?}: {len} rays");
                assert!(fresh.iter().filter(|h| h.is_hit()).count() > len / 10, "{backend:?}");
            }
        }
    }

    /// A bad ray in a later work item is reported by its index, the first bad one whichever thread
    /// saw which.
    #[test]
    fn the_first_bad_ray_is_named() {
        let (vertices, faces, mut origins, mut dirs) = soup(true);
        origins[4321][1] = f32::NAN;
        dirs[3210] = [0.0; 3];
        let opts = QueryOptions {
            accel: AccelKind::Bvh.into(),
            backend: Backend::Cpu,
            ..Default::default()
        };
        let mesh = TraceMesh::from_arrays(&vertices, &faces, &opts).unwrap();
        let err = mesh
            .intersect(&origins, &dirs, 0.0, f32::INFINITY)
            .unwrap_err()
            .to_string();
        assert!(err.contains("ray 3210 has a zero direction"), "{err}");
        let err = mesh.occluded(&origins, &dirs, 0.0, 1.0).unwrap_err().to_string();
        assert!(err.contains("ray 3210 has a zero direction"), "{err}");
        dirs[3210] = [0.0, 0.0, 1.0];
        let err = mesh
            .intersect(&origins, &dirs, 0.0, f32::INFINITY)
            .unwrap_err()
            .to_string();
        assert!(err.contains("ray 4321 has a non-finite origin"), "{err}");
    }
}
