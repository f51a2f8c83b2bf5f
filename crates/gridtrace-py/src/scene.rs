//! `NativeScene`: the native part of `gridtrace.Scene` (Open3D's `RaycastingScene` names over
//! `gridtrace::QueryScene`). Arrays arrive flat and checked by the Python side (`(N, 6)` rays,
//! `(N, 3)` points, float32, C order); results go back as dicts of flat numpy arrays, which
//! Python reshapes to the caller's leading shape. Every query releases the GIL and holds only
//! a shared lock, so several Python threads query one scene at once; changes take the lock
//! alone.

use std::path::PathBuf;
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

use glam::Mat4;
use numpy::{
    IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use gridtrace::query_scene::{InstanceOf, PerRay, QueryScene, RayOptions};

use crate::{on_threads, options, to_py};

/// An (N, K) C-contiguous, aligned float32 or uint32 array as a slice of rows, without
/// copying. The Python side makes arrays so (`np.require(..., requirements="CA")`): arrays
/// that come back from a serialiser can be views into a byte buffer at any offset.
fn rows<'a, T: numpy::Element + bytemuck::Pod, const K: usize>(
    a: &'a PyReadonlyArray2<'_, T>,
    what: &str,
) -> PyResult<&'a [[T; K]]> {
    let shape = a.shape();
    if shape[1] != K {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (N, {K}), got {shape:?}"
        )));
    }
    let flat = a
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{what} must be C-contiguous and aligned")))?;
    // The length is a multiple of K (checked above), so the cast cannot fail.
    Ok(bytemuck::cast_slice(flat))
}

/// A 4x4 row-major matrix (numpy's, as Open3D and trimesh write transforms) as glam's.
fn transform(t: Option<PyReadonlyArray2<'_, f32>>) -> PyResult<Option<Mat4>> {
    let Some(t) = t else { return Ok(None) };
    let rows: &[[f32; 4]] = rows(&t, "transform")?;
    if rows.len() != 4 {
        return Err(PyValueError::new_err(format!(
            "transform must have shape (4, 4), got {:?}",
            t.shape()
        )));
    }
    Ok(Some(mat4_of_rows([rows[0], rows[1], rows[2], rows[3]])))
}

/// A row-major 4x4 (numpy's) as glam's.
fn mat4_of_rows(r: [[f32; 4]; 4]) -> Mat4 {
    Mat4::from_cols_array_2d(&r).transpose()
}

/// A per-ray value as Python passes it: a number, or a 1-D array (checked for length and dtype
/// by the Python side, which names the argument).
enum PerRayArg<'py, T: numpy::Element> {
    All(T),
    Each(PyReadonlyArray1<'py, T>),
}

impl<'py, T: numpy::Element + Copy> PerRayArg<'py, T> {
    fn extract(
        ob: &Bound<'py, PyAny>,
        what: &str,
        scalar: impl FnOnce(&Bound<'py, PyAny>) -> Option<T>,
    ) -> PyResult<Self> {
        if let Ok(a) = ob.extract::<PyReadonlyArray1<'py, T>>() {
            return Ok(PerRayArg::Each(a));
        }
        scalar(ob)
            .map(PerRayArg::All)
            .ok_or_else(|| PyValueError::new_err(format!("{what} must be a number or a 1-D array of the right dtype")))
    }

    fn get(&self, what: &str) -> PyResult<PerRay<'_, T>> {
        Ok(match self {
            PerRayArg::All(v) => PerRay::All(*v),
            PerRayArg::Each(a) => PerRay::Each(
                a.as_slice()
                    .map_err(|_| PyValueError::new_err(format!("{what} must be C-contiguous")))?,
            ),
        })
    }
}

/// The interval and mask arguments of a ray query.
struct RayArgs<'py> {
    tnear: PerRayArg<'py, f32>,
    tfar: PerRayArg<'py, f32>,
    mask: PerRayArg<'py, u32>,
}

impl<'py> RayArgs<'py> {
    /// The arguments as given; `None`: the default (`0`, `inf`, every bit).
    fn extract(
        tnear: Option<&Bound<'py, PyAny>>,
        tfar: Option<&Bound<'py, PyAny>>,
        mask: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        Ok(RayArgs {
            tnear: tnear.map_or(Ok(PerRayArg::All(0.0)), |t| {
                PerRayArg::extract(t, "tnear", |o| o.extract::<f32>().ok())
            })?,
            tfar: tfar.map_or(Ok(PerRayArg::All(f32::INFINITY)), |t| {
                PerRayArg::extract(t, "tfar", |o| o.extract::<f32>().ok())
            })?,
            mask: mask.map_or(Ok(PerRayArg::All(u32::MAX)), |m| {
                PerRayArg::extract(m, "mask", |o| o.extract::<u32>().ok())
            })?,
        })
    }

    fn options(&self) -> PyResult<RayOptions<'_>> {
        Ok(RayOptions {
            t_near: self.tnear.get("tnear")?,
            t_far: self.tfar.get("tfar")?,
            mask: self.mask.get("mask")?,
        })
    }
}

fn key_error(id: u32) -> PyErr {
    // The same words as the library's error for an unknown id.
    PyKeyError::new_err(format!("unknown geometry id {id}"))
}

/// A flat numpy array of `n` rows of `K` from a vector of rows (no copy).
fn rows_out<'py, const K: usize>(py: Python<'py>, v: Vec<[f32; K]>) -> PyResult<Bound<'py, PyAny>> {
    let n = v.len();
    let flat: Vec<f32> = bytemuck::allocation::cast_vec(v);
    Ok(flat.into_pyarray(py).reshape([n, K])?.into_any())
}

/// Several meshes with ids and transforms, and the queries over them.
#[pyclass(module = "gridtrace._gridtrace", frozen)]
pub struct NativeScene {
    inner: RwLock<QueryScene>,
}

impl NativeScene {
    fn read(&self) -> RwLockReadGuard<'_, QueryScene> {
        self.inner.read().unwrap_or_else(|p| p.into_inner())
    }
    fn write(&self) -> RwLockWriteGuard<'_, QueryScene> {
        self.inner.write().unwrap_or_else(|p| p.into_inner())
    }
}

#[pymethods]
impl NativeScene {
    #[new]
    #[pyo3(signature = (accel, accel_params, backend, gpu_variant = ""))]
    fn new(accel: &str, accel_params: &str, backend: &str, gpu_variant: &str) -> PyResult<Self> {
        Ok(NativeScene {
            inner: RwLock::new(QueryScene::new(options(accel, accel_params, backend, gpu_variant)?)),
        })
    }

    /// Rebuilds a scene from `parts()` (unpickling): each mesh once, each geometry as (id,
    /// mesh index, 4x4 transform, mask).
    #[staticmethod]
    #[pyo3(signature = (accel, accel_params, backend, next_id, meshes, instances, gpu_variant = ""))]
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    fn from_parts(
        py: Python<'_>,
        accel: &str,
        accel_params: &str,
        backend: &str,
        next_id: u32,
        meshes: Vec<(PyReadonlyArray2<'_, f32>, PyReadonlyArray2<'_, u32>)>,
        instances: Vec<(u32, usize, PyReadonlyArray2<'_, f32>, u32)>,
        gpu_variant: &str,
    ) -> PyResult<Self> {
        let opts = options(accel, accel_params, backend, gpu_variant)?;
        let mut m = Vec::with_capacity(meshes.len());
        for (v, f) in &meshes {
            m.push((
                rows::<f32, 3>(v, "vertices")?.to_vec(),
                rows::<u32, 3>(f, "faces")?.to_vec(),
            ));
        }
        let mut inst = Vec::with_capacity(instances.len());
        for (id, k, t, mask) in &instances {
            inst.push((*id, *k, transform(Some(t.clone()))?.unwrap_or(Mat4::IDENTITY), *mask));
        }
        let scene = py
            .detach(move || QueryScene::from_parts(opts, next_id, m, inst))
            .map_err(to_py)?;
        Ok(NativeScene {
            inner: RwLock::new(scene),
        })
    }

    #[pyo3(signature = (vertices, faces, transform=None))]
    fn add_triangles(
        &self,
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f32>,
        faces: PyReadonlyArray2<'_, u32>,
        transform: Option<PyReadonlyArray2<'_, f32>>,
    ) -> PyResult<u32> {
        let v = rows::<f32, 3>(&vertices, "vertices")?.to_vec();
        let f = rows::<u32, 3>(&faces, "faces")?.to_vec();
        let t = self::transform(transform)?;
        py.detach(|| self.write().add_triangles(v, f, t)).map_err(to_py)
    }

    #[pyo3(signature = (path, transform=None))]
    fn add_file(&self, py: Python<'_>, path: PathBuf, transform: Option<PyReadonlyArray2<'_, f32>>) -> PyResult<u32> {
        let t = self::transform(transform)?;
        py.detach(|| self.write().add_file(&path, t)).map_err(to_py)
    }

    fn remove(&self, py: Python<'_>, id: u32) -> PyResult<()> {
        py.detach(|| {
            let mut s = self.write();
            if !s.contains(id) {
                return Err(key_error(id));
            }
            s.remove(id).map_err(to_py)
        })
    }

    fn update_vertices(&self, py: Python<'_>, id: u32, vertices: PyReadonlyArray2<'_, f32>) -> PyResult<()> {
        let v = rows::<f32, 3>(&vertices, "vertices")?.to_vec();
        py.detach(|| {
            let mut s = self.write();
            if !s.contains(id) {
                return Err(key_error(id));
            }
            s.update_vertices(id, v).map_err(to_py)
        })
    }

    /// (next_id, [(vertices, faces)], [(id, mesh index, transform, mask)]): what pickling
    /// keeps, each mesh once however many geometries place it.
    #[allow(clippy::type_complexity)]
    fn parts<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        u32,
        Vec<(Bound<'py, PyAny>, Bound<'py, PyAny>)>,
        Vec<(u32, usize, Bound<'py, PyAny>, u32)>,
    )> {
        let s = self.read();
        let (meshes, instances) = s.parts();
        let mut m = Vec::with_capacity(meshes.len());
        for mesh in meshes {
            let faces: Vec<u32> = mesh.faces.iter().flatten().copied().collect();
            m.push((
                rows_out(py, mesh.vertices.clone())?,
                faces.into_pyarray(py).reshape([mesh.faces.len(), 3])?.into_any(),
            ));
        }
        let mut inst = Vec::with_capacity(instances.len());
        for (id, k, t, mask) in instances {
            let t: Vec<[f32; 4]> = t.transpose().to_cols_array_2d().to_vec();
            inst.push((id, k, rows_out(py, t)?, mask));
        }
        Ok((s.next_id(), m, inst))
    }

    /// A new geometry placing the mesh of geometry `of` (shared, with its structure).
    fn add_instance(&self, py: Python<'_>, of: u32, transform: PyReadonlyArray2<'_, f32>, mask: u32) -> PyResult<u32> {
        let t = self::transform(Some(transform))?;
        py.detach(|| {
            let mut s = self.write();
            if !s.contains(of) {
                return Err(key_error(of));
            }
            s.add_instance(InstanceOf::Geometry(of), t, mask).map_err(to_py)
        })
    }

    /// Moves geometries `ids[k]` to `transforms[k]` ((K, 4, 4) row-major), all or none.
    fn set_transforms(
        &self,
        py: Python<'_>,
        ids: PyReadonlyArray1<'_, u32>,
        transforms: PyReadonlyArray3<'_, f32>,
    ) -> PyResult<()> {
        let ids = ids
            .as_slice()
            .map_err(|_| PyValueError::new_err("ids must be C-contiguous"))?;
        let shape = transforms.shape();
        if shape[1..] != [4, 4] || shape[0] != ids.len() {
            return Err(PyValueError::new_err(format!(
                "transforms must have shape ({}, 4, 4), got {shape:?}",
                ids.len()
            )));
        }
        let flat = transforms
            .as_slice()
            .map_err(|_| PyValueError::new_err("transforms must be C-contiguous"))?;
        let m: Vec<Mat4> = bytemuck::cast_slice::<f32, [[f32; 4]; 4]>(flat)
            .iter()
            .map(|r| mat4_of_rows(*r))
            .collect();
        py.detach(|| {
            let mut s = self.write();
            if let Some(&id) = ids.iter().find(|&&id| !s.contains(id)) {
                return Err(key_error(id));
            }
            s.set_transforms(ids, &m).map_err(to_py)
        })
    }

    fn set_mask(&self, py: Python<'_>, id: u32, mask: u32) -> PyResult<()> {
        py.detach(|| {
            let mut s = self.write();
            if !s.contains(id) {
                return Err(key_error(id));
            }
            s.set_mask(id, mask).map_err(to_py)
        })
    }

    fn memory_bytes(&self) -> usize {
        self.read().memory_bytes()
    }

    /// Bottom levels and merged meshes built so far (tests: a move builds none).
    fn structure_builds(&self) -> usize {
        self.read().structure_builds()
    }

    /// What the last ray batch on the scene's GPU took (a dict: wall and GPU time, submissions,
    /// bytes up and down), or None where its rays trace on the CPU or before the first.
    fn last_gpu_batch<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        match self.read().last_gpu_batch().map_err(to_py)? {
            Some(s) => Ok(Some(crate::stats::batch(py, &s)?)),
            None => Ok(None),
        }
    }

    /// What the last query did (a dict: `name`, `device`, for GPU work `gpu`, the batch as
    /// `last_gpu_batch` gives it, and `note` after a GPU fault or a device limit), or None
    /// before the first (`QueryScene::last_query`, `stats::last_query`).
    fn last_query<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        crate::stats::last_query(py, &self.read().last_query())
    }

    /// What the GPU's two levels hold and have written (a dict), or None before their first
    /// ray query (`QueryScene::gpu_uploads`).
    fn gpu_uploads<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, pyo3::types::PyDict>>> {
        let Some(u) = self.read().gpu_uploads() else {
            return Ok(None);
        };
        let d = pyo3::types::PyDict::new(py);
        d.set_item("mesh_bytes", u.mesh_bytes)?;
        d.set_item("mesh_uploads", u.mesh_uploads)?;
        d.set_item("top_nodes", u.top_nodes)?;
        d.set_item("top_records", u.top_records)?;
        d.set_item("written_bytes", u.written_bytes)?;
        d.set_item("blas_builds", u.blas_builds)?;
        d.set_item("tlas_builds", u.tlas_builds)?;
        Ok(Some(d))
    }

    fn ids(&self) -> Vec<u32> {
        self.read().ids().collect()
    }

    #[getter]
    fn triangle_count(&self) -> usize {
        self.read().triangle_count()
    }

    fn device(&self, py: Python<'_>) -> PyResult<String> {
        py.detach(|| self.read().device()).map_err(to_py)
    }

    fn accel(&self, py: Python<'_>) -> PyResult<&'static str> {
        py.detach(|| self.read().accel_name()).map_err(to_py)
    }

    /// `Scene.scan`: `sensor` from each pose of `pose` (flat `(E * 4, 4)`), rays made where
    /// they are traced (`crate::sensor::scan`).
    #[pyo3(signature = (sensor, pose, pose_end, outputs, points_frame, nthreads = 0))]
    #[allow(clippy::too_many_arguments)]
    fn scan<'py>(
        &self,
        py: Python<'py>,
        sensor: PyRef<'py, crate::sensor::NativeSensor>,
        pose: PyReadonlyArray2<'py, f32>,
        pose_end: Option<PyReadonlyArray2<'py, f32>>,
        outputs: Vec<String>,
        points_frame: &str,
        nthreads: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let scene = self.read();
        crate::sensor::scan(py, &scene, &sensor, pose, pose_end, outputs, points_frame, nthreads)
    }

    /// `nthreads`: CPU threads (0: all cores), as Open3D's.
    #[pyo3(signature = (rays, nthreads = 0, tnear = None, tfar = None, mask = None))]
    fn cast_rays<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        nthreads: usize,
        tnear: Option<&Bound<'py, PyAny>>,
        tfar: Option<&Bound<'py, PyAny>>,
        mask: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let r = rows::<f32, 6>(&rays, "rays")?;
        let args = RayArgs::extract(tnear, tfar, mask)?;
        let o = args.options()?;
        let h = py
            .detach(|| on_threads(nthreads, || self.read().cast_rays_with(r, &o)))?
            .map_err(to_py)?;
        let d = PyDict::new(py);
        d.set_item("t_hit", h.t_hit.into_pyarray(py))?;
        d.set_item("geometry_ids", h.geometry_ids.into_pyarray(py))?;
        d.set_item("primitive_ids", h.primitive_ids.into_pyarray(py))?;
        d.set_item("primitive_uvs", rows_out(py, h.primitive_uvs)?)?;
        d.set_item("primitive_normals", rows_out(py, h.primitive_normals)?)?;
        Ok(d)
    }

    #[pyo3(signature = (rays, tnear = None, tfar = None, nthreads = 0, mask = None))]
    fn test_occlusions<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        tnear: Option<&Bound<'py, PyAny>>,
        tfar: Option<&Bound<'py, PyAny>>,
        nthreads: usize,
        mask: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let r = rows::<f32, 6>(&rays, "rays")?;
        let args = RayArgs::extract(tnear, tfar, mask)?;
        let opts = args.options()?;
        let o = py
            .detach(|| on_threads(nthreads, || self.read().test_occlusions_with(r, &opts)))?
            .map_err(to_py)?;
        Ok(o.into_pyarray(py))
    }

    #[pyo3(signature = (rays, nthreads = 0, tnear = None, tfar = None, mask = None))]
    fn count_intersections<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        nthreads: usize,
        tnear: Option<&Bound<'py, PyAny>>,
        tfar: Option<&Bound<'py, PyAny>>,
        mask: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray1<i32>>> {
        let r = rows::<f32, 6>(&rays, "rays")?;
        let args = RayArgs::extract(tnear, tfar, mask)?;
        let o = args.options()?;
        let c = py
            .detach(|| on_threads(nthreads, || self.read().count_intersections_with(r, &o)))?
            .map_err(to_py)?;
        // Open3D's dtype (int32): a ray crossing two billion faces is not a case.
        let c: Vec<i32> = c.into_iter().map(|c| c.min(i32::MAX as u32) as i32).collect();
        Ok(c.into_pyarray(py))
    }

    #[pyo3(signature = (rays, nthreads = 0, tnear = None, tfar = None, mask = None))]
    fn list_intersections<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        nthreads: usize,
        tnear: Option<&Bound<'py, PyAny>>,
        tfar: Option<&Bound<'py, PyAny>>,
        mask: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let r = rows::<f32, 6>(&rays, "rays")?;
        let args = RayArgs::extract(tnear, tfar, mask)?;
        let o = args.options()?;
        let l = py
            .detach(|| on_threads(nthreads, || self.read().list_intersections_with(r, &o)))?
            .map_err(to_py)?;
        let d = PyDict::new(py);
        d.set_item("ray_splits", l.ray_splits.into_pyarray(py))?;
        d.set_item("ray_ids", l.ray_ids.into_pyarray(py))?;
        d.set_item("geometry_ids", l.geometry_ids.into_pyarray(py))?;
        d.set_item("primitive_ids", l.primitive_ids.into_pyarray(py))?;
        d.set_item("primitive_uvs", rows_out(py, l.primitive_uvs)?)?;
        d.set_item("t_hit", l.t_hit.into_pyarray(py))?;
        Ok(d)
    }

    #[pyo3(signature = (points, nthreads = 0))]
    fn compute_closest_points<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        nthreads: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let p = rows::<f32, 3>(&points, "query_points")?;
        let c = py
            .detach(|| on_threads(nthreads, || self.read().compute_closest_points(p)))?
            .map_err(to_py)?;
        let d = PyDict::new(py);
        d.set_item("points", rows_out(py, c.points)?)?;
        d.set_item("geometry_ids", c.geometry_ids.into_pyarray(py))?;
        d.set_item("primitive_ids", c.primitive_ids.into_pyarray(py))?;
        d.set_item("primitive_uvs", rows_out(py, c.primitive_uvs)?)?;
        d.set_item("primitive_normals", rows_out(py, c.primitive_normals)?)?;
        Ok(d)
    }

    /// `what`: "distance", "signed_distance", "occupancy" or "winding_number"; `accuracy`: the
    /// winding numbers' (libigl's beta; `QueryScene::compute_signed_distance_at`), unused by
    /// "distance".
    #[pyo3(signature = (what, points, nthreads = 0, accuracy = gridtrace::accel::winding::BETA))]
    fn point_values<'py>(
        &self,
        py: Python<'py>,
        what: &str,
        points: PyReadonlyArray2<'py, f32>,
        nthreads: usize,
        accuracy: f64,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let p = rows::<f32, 3>(&points, "query_points")?;
        let v = py
            .detach(|| {
                on_threads(nthreads, || {
                    let s = self.read();
                    match what {
                        "distance" => s.compute_distance(p),
                        "signed_distance" => s.compute_signed_distance_at(p, accuracy),
                        "occupancy" => s.compute_occupancy_at(p, accuracy),
                        _ => s.winding_numbers_at(p, accuracy),
                    }
                })
            })?
            .map_err(to_py)?;
        Ok(v.into_pyarray(py))
    }
}
