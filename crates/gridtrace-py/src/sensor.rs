//! `NativeSensor`: the native part of `gridtrace.Camera` and `gridtrace.Lidar` (a
//! `gridtrace::sensor::Sensor`), the scan behind `Scene.scan`, and Open3D's
//! `create_rays_pinhole` makers. Poses arrive as flat `(E * 4, 4)` float32 arrays (the Python
//! side stacks and checks shapes); results go back as flat numpy arrays that Python reshapes
//! to `(E, rows, cols, ...)`.

use numpy::{IntoPyArray, PyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use gridtrace::query_scene::QueryScene;
use gridtrace::sensor::{self, Camera, Frame, Lidar, Pose, ScanOutputs, Sensor};

use crate::{on_threads, to_py};

/// A camera or a LiDAR.
#[pyclass(module = "gridtrace._gridtrace", frozen)]
pub struct NativeSensor {
    pub(crate) inner: Sensor,
}

/// `(E * 4, 4)` rows as `E` checked poses; `name` names the argument in errors.
fn poses(a: &PyReadonlyArray2<'_, f32>, name: &str) -> PyResult<Vec<Pose>> {
    let shape = a.shape();
    let flat = a
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name} must be C-contiguous")))?;
    if shape[1] != 4 || shape[0] % 4 != 0 || shape[0] == 0 {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (4, 4) or (E, 4, 4), got {shape:?} rows"
        )));
    }
    flat.chunks_exact(16)
        .enumerate()
        .map(|(e, m)| {
            let rows: [[f32; 4]; 4] = [
                [m[0], m[1], m[2], m[3]],
                [m[4], m[5], m[6], m[7]],
                [m[8], m[9], m[10], m[11]],
                [m[12], m[13], m[14], m[15]],
            ];
            let what = if shape[0] == 4 {
                name.to_string()
            } else {
                format!("{name}[{e}]")
            };
            sensor::check_pose(&what, &rows).map_err(to_py)
        })
        .collect()
}

fn rays_out<'py>(py: Python<'py>, rays: Vec<[f32; 6]>) -> Bound<'py, PyArray1<f32>> {
    let flat: Vec<f32> = bytemuck::allocation::cast_vec(rays);
    flat.into_pyarray(py)
}

fn outputs(names: &[String], points_frame: &str) -> PyResult<ScanOutputs> {
    let mut o = ScanOutputs::default();
    for n in names {
        match n.as_str() {
            "range" => o.range = true,
            "depth" => o.depth = true,
            "points" => {
                o.points = Some(match points_frame {
                    "world" => Frame::World,
                    "sensor" => Frame::Sensor,
                    f => {
                        return Err(PyValueError::new_err(format!(
                            "points_frame must be 'world' or 'sensor', got {f:?}"
                        )));
                    }
                })
            }
            "geometry_ids" => o.geometry_ids = true,
            "primitive_ids" => o.primitive_ids = true,
            "normals" => o.normals = true,
            "incidence" => o.incidence = true,
            other => {
                return Err(PyValueError::new_err(format!(
                    "outputs: unknown output {other:?}; known: range, depth, points, geometry_ids, \
                     primitive_ids, normals, incidence"
                )));
            }
        }
    }
    Ok(o)
}

/// `scene.scan`, the GIL released while it runs.
#[allow(clippy::too_many_arguments)]
pub(crate) fn scan<'py>(
    py: Python<'py>,
    scene: &QueryScene,
    native: &NativeSensor,
    pose: PyReadonlyArray2<'py, f32>,
    pose_end: Option<PyReadonlyArray2<'py, f32>>,
    output_names: Vec<String>,
    points_frame: &str,
    nthreads: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let ps = poses(&pose, "pose")?;
    let ends = pose_end.as_ref().map(|p| poses(p, "pose_end")).transpose()?;
    let outs = outputs(&output_names, points_frame)?;
    let r = py
        .detach(|| {
            on_threads(nthreads, || {
                sensor::scan(scene, &native.inner, &ps, ends.as_deref(), outs)
            })
        })?
        .map_err(to_py)?;
    let d = PyDict::new(py);
    let flat3 = |v: Vec<[f32; 3]>| -> Vec<f32> { bytemuck::allocation::cast_vec(v) };
    if let Some(v) = r.range {
        d.set_item("range", v.into_pyarray(py))?;
    }
    if let Some(v) = r.depth {
        d.set_item("depth", v.into_pyarray(py))?;
    }
    if let Some(v) = r.points {
        d.set_item("points", flat3(v).into_pyarray(py))?;
    }
    if let Some(v) = r.geometry_ids {
        d.set_item("geometry_ids", v.into_pyarray(py))?;
    }
    if let Some(v) = r.primitive_ids {
        d.set_item("primitive_ids", v.into_pyarray(py))?;
    }
    if let Some(v) = r.normals {
        d.set_item("normals", flat3(v).into_pyarray(py))?;
    }
    if let Some(v) = r.incidence {
        d.set_item("incidence", v.into_pyarray(py))?;
    }
    Ok(d)
}

/// A LiDAR's table as Python reads it: `(elevations_deg, azimuth_steps, azimuth_range_deg,
/// min_range, max_range)`.
type LidarTable = (Vec<f32>, u32, (f32, f32), f32, f32);

#[pymethods]
impl NativeSensor {
    #[staticmethod]
    #[pyo3(signature = (intrinsic_matrix, width_px, height_px, min_range = 0.0, max_range = f32::INFINITY))]
    fn camera(
        intrinsic_matrix: [[f64; 3]; 3],
        width_px: u32,
        height_px: u32,
        min_range: f32,
        max_range: f32,
    ) -> PyResult<Self> {
        let c = Camera::new(intrinsic_matrix, width_px, height_px)
            .and_then(|c| c.with_range(min_range, max_range))
            .map_err(to_py)?;
        Ok(NativeSensor { inner: c.into() })
    }

    #[staticmethod]
    #[pyo3(signature = (fov_deg, width_px, height_px, min_range = 0.0, max_range = f32::INFINITY))]
    fn camera_from_fov(fov_deg: f64, width_px: u32, height_px: u32, min_range: f32, max_range: f32) -> PyResult<Self> {
        let c = Camera::from_fov(fov_deg, width_px, height_px)
            .and_then(|c| c.with_range(min_range, max_range))
            .map_err(to_py)?;
        Ok(NativeSensor { inner: c.into() })
    }

    #[staticmethod]
    #[pyo3(signature = (elevations_deg, azimuth_steps, azimuth_range_deg, min_range, max_range, azimuth_offsets_deg, origin_offsets))]
    fn lidar(
        elevations_deg: Vec<f32>,
        azimuth_steps: u32,
        azimuth_range_deg: (f32, f32),
        min_range: f32,
        max_range: f32,
        azimuth_offsets_deg: Vec<f32>,
        origin_offsets: Vec<[f32; 3]>,
    ) -> PyResult<Self> {
        let l = Lidar::new(elevations_deg, azimuth_steps, azimuth_range_deg, min_range, max_range)
            .and_then(|l| l.with_azimuth_offsets(azimuth_offsets_deg))
            .and_then(|l| l.with_origin_offsets(origin_offsets))
            .map_err(to_py)?;
        Ok(NativeSensor { inner: l.into() })
    }

    #[staticmethod]
    #[pyo3(signature = (name, azimuth_steps = None))]
    fn preset(name: &str, azimuth_steps: Option<u32>) -> PyResult<Self> {
        let l = sensor::preset(name, azimuth_steps).map_err(to_py)?;
        Ok(NativeSensor { inner: l.into() })
    }

    /// `(rows, cols)`.
    fn shape(&self) -> (usize, usize) {
        self.inner.shape()
    }

    /// The LiDAR's table as the Python class shows it: `(elevations_deg, azimuth_steps,
    /// azimuth_range_deg, min_range, max_range)`; `None` for a camera.
    fn lidar_table(&self) -> Option<LidarTable> {
        match &self.inner {
            Sensor::Lidar(l) => Some((
                l.elevations_deg.clone(),
                l.azimuth_steps,
                l.azimuth_range_deg,
                l.min_range,
                l.max_range,
            )),
            Sensor::Camera(_) => None,
        }
    }

    /// The rays of each pose, flat `(E * rows * cols * 6,)`.
    #[pyo3(signature = (pose, pose_end = None))]
    fn rays<'py>(
        &self,
        py: Python<'py>,
        pose: PyReadonlyArray2<'py, f32>,
        pose_end: Option<PyReadonlyArray2<'py, f32>>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let ps = poses(&pose, "pose")?;
        let ends = pose_end.as_ref().map(|p| poses(p, "pose_end")).transpose()?;
        let mut all = Vec::new();
        for (e, p) in ps.iter().enumerate() {
            all.extend(self.inner.rays(p, ends.as_ref().map(|x| &x[e])).map_err(to_py)?);
        }
        Ok(rays_out(py, all))
    }
}

/// Open3D's `create_rays_pinhole(intrinsic_matrix, extrinsic_matrix, width_px, height_px)`,
/// flat.
#[pyfunction]
pub fn create_rays_pinhole<'py>(
    py: Python<'py>,
    intrinsic_matrix: [[f64; 3]; 3],
    extrinsic_matrix: [[f64; 4]; 4],
    width_px: u32,
    height_px: u32,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    let r = sensor::create_rays_pinhole(&intrinsic_matrix, &extrinsic_matrix, width_px, height_px).map_err(to_py)?;
    Ok(rays_out(py, r))
}

/// Open3D's `create_rays_pinhole(fov_deg, center, eye, up, width_px, height_px)`, flat.
#[pyfunction]
pub fn create_rays_pinhole_fov<'py>(
    py: Python<'py>,
    fov_deg: f64,
    center: [f64; 3],
    eye: [f64; 3],
    up: [f64; 3],
    width_px: u32,
    height_px: u32,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    let r = sensor::create_rays_pinhole_fov(fov_deg, center, eye, up, width_px, height_px).map_err(to_py)?;
    Ok(rays_out(py, r))
}
