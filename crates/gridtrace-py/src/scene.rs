//! `NativeScene`: the native part of `gridtrace.Scene` (Open3D's `RaycastingScene` names over
//! `gridtrace::QueryScene`). Arrays arrive flat and checked by the Python side (`(N, 6)` rays,
//! `(N, 3)` points, float32, C order); results go back as dicts of flat numpy arrays, which
//! Python reshapes to the caller's leading shape. Every query releases the GIL and holds only
//! a shared lock, so several Python threads query one scene at once; changes take the lock
//! alone.

use std::path::PathBuf;
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

use glam::Mat4;
use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use gridtrace::query_scene::{Geometry, QueryScene};

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
    let r: [[f32; 4]; 4] = [rows[0], rows[1], rows[2], rows[3]];
    Ok(Some(Mat4::from_cols_array_2d(&r).transpose()))
}

fn key_error(id: u32) -> PyErr {
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

    /// Rebuilds a scene from `parts()` (unpickling).
    #[staticmethod]
    #[pyo3(signature = (accel, accel_params, backend, next_id, geometries, gpu_variant = ""))]
    #[allow(clippy::type_complexity)]
    fn from_parts(
        py: Python<'_>,
        accel: &str,
        accel_params: &str,
        backend: &str,
        next_id: u32,
        geometries: Vec<(
            u32,
            PyReadonlyArray2<'_, f32>,
            PyReadonlyArray2<'_, u32>,
            PyReadonlyArray2<'_, f32>,
        )>,
        gpu_variant: &str,
    ) -> PyResult<Self> {
        let opts = options(accel, accel_params, backend, gpu_variant)?;
        let mut parts = Vec::with_capacity(geometries.len());
        for (id, v, f, t) in &geometries {
            parts.push((
                *id,
                Geometry {
                    vertices: rows::<f32, 3>(v, "vertices")?.to_vec(),
                    faces: rows::<u32, 3>(f, "faces")?.to_vec(),
                    transform: transform(Some(t.clone()))?.unwrap_or(Mat4::IDENTITY),
                },
            ));
        }
        let scene = py
            .detach(move || QueryScene::from_parts(opts, next_id, parts))
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

    /// (next_id, [(id, vertices, faces, transform)]): what pickling keeps.
    #[allow(clippy::type_complexity)]
    fn parts<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(u32, Vec<(u32, Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>)>)> {
        let s = self.read();
        let mut out = Vec::new();
        for id in s.ids() {
            let g = s.geometry(id).expect("listed ids exist");
            let faces: Vec<u32> = g.faces.iter().flatten().copied().collect();
            let t: Vec<[f32; 4]> = g.transform.transpose().to_cols_array_2d().to_vec();
            out.push((
                id,
                rows_out(py, g.vertices.clone())?,
                faces.into_pyarray(py).reshape([g.faces.len(), 3])?.into_any(),
                rows_out(py, t)?,
            ));
        }
        Ok((s.next_id(), out))
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
    #[pyo3(signature = (rays, nthreads = 0))]
    fn cast_rays<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        nthreads: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let r = rows::<f32, 6>(&rays, "rays")?;
        let h = py
            .detach(|| on_threads(nthreads, || self.read().cast_rays(r)))?
            .map_err(to_py)?;
        let d = PyDict::new(py);
        d.set_item("t_hit", h.t_hit.into_pyarray(py))?;
        d.set_item("geometry_ids", h.geometry_ids.into_pyarray(py))?;
        d.set_item("primitive_ids", h.primitive_ids.into_pyarray(py))?;
        d.set_item("primitive_uvs", rows_out(py, h.primitive_uvs)?)?;
        d.set_item("primitive_normals", rows_out(py, h.primitive_normals)?)?;
        Ok(d)
    }

    #[pyo3(signature = (rays, tnear, tfar, nthreads = 0))]
    fn test_occlusions<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        tnear: f32,
        tfar: f32,
        nthreads: usize,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let r = rows::<f32, 6>(&rays, "rays")?;
        let o = py
            .detach(|| on_threads(nthreads, || self.read().test_occlusions(r, tnear, tfar)))?
            .map_err(to_py)?;
        Ok(o.into_pyarray(py))
    }

    #[pyo3(signature = (rays, nthreads = 0))]
    fn count_intersections<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        nthreads: usize,
    ) -> PyResult<Bound<'py, PyArray1<i32>>> {
        let r = rows::<f32, 6>(&rays, "rays")?;
        let c = py
            .detach(|| on_threads(nthreads, || self.read().count_intersections(r)))?
            .map_err(to_py)?;
        // Open3D's dtype (int32): a ray crossing two billion faces is not a case.
        let c: Vec<i32> = c.into_iter().map(|c| c.min(i32::MAX as u32) as i32).collect();
        Ok(c.into_pyarray(py))
    }

    #[pyo3(signature = (rays, nthreads = 0))]
    fn list_intersections<'py>(
        &self,
        py: Python<'py>,
        rays: PyReadonlyArray2<'py, f32>,
        nthreads: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let r = rows::<f32, 6>(&rays, "rays")?;
        let l = py
            .detach(|| on_threads(nthreads, || self.read().list_intersections(r)))?
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

    /// `what`: "distance", "signed_distance", "occupancy" or "winding_number".
    #[pyo3(signature = (what, points, nthreads = 0))]
    fn point_values<'py>(
        &self,
        py: Python<'py>,
        what: &str,
        points: PyReadonlyArray2<'py, f32>,
        nthreads: usize,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let p = rows::<f32, 3>(&points, "query_points")?;
        let v = py
            .detach(|| {
                on_threads(nthreads, || {
                    let s = self.read();
                    match what {
                        "distance" => s.compute_distance(p),
                        "signed_distance" => s.compute_signed_distance(p),
                        "occupancy" => s.compute_occupancy(p),
                        _ => s.winding_numbers(p),
                    }
                })
            })?
            .map_err(to_py)?;
        Ok(v.into_pyarray(py))
    }
}
