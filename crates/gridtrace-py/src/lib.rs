//! Python bindings: `gridtrace._gridtrace`, wrapped by the pure-Python `gridtrace` package
//! (which handles broadcasting and dtypes). Every call releases the GIL while it works.

use std::path::PathBuf;

mod scene;
mod sensor;
mod stats;
mod threads;

use threads::on_threads;

use std::sync::RwLock;

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

use gridtrace::query::{Backend, QueryOptions, TraceMesh};
use gridtrace::{AccelSpec, Error, Mode, PixelFormat, RenderOptions};

fn to_py(e: Error) -> PyErr {
    match e {
        // "ValueError: ray 3 has ...": the exception's type says what "invalid input: " would.
        Error::InvalidInput(m) => PyValueError::new_err(m),
        Error::Parse { .. } | Error::Scene(_) => PyValueError::new_err(e.to_string()),
        Error::Io { .. } => pyo3::exceptions::PyOSError::new_err(e.to_string()),
        Error::Gpu(_) | Error::Limit { .. } => PyRuntimeError::new_err(e.to_string()),
    }
}

/// `s` as the argument `what`; a ValueError naming the argument once: the library's own messages
/// mostly name it already ("accel must be ...", "GPU variant ..."), and then take no prefix.
fn parse<T: std::str::FromStr<Err = String>>(what: &str, s: &str) -> PyResult<T> {
    s.parse::<T>().map_err(|e| PyValueError::new_err(named(what, &e)))
}

/// `message` about the argument `what`, naming it once: as it is when it names `what` already
/// ("accel must be ..."); with the library's words for it replaced by the Python name where it
/// uses them ("GPU variant bvh=x: ..." becomes "gpu_variant bvh=x: ..."); else prefixed.
fn named(what: &str, message: &str) -> String {
    // Some parsers check with the library's own errors, whose text starts so (as `to_py`).
    let message = message.strip_prefix("invalid input: ").unwrap_or(message);
    if message.contains(what) {
        return message.to_string();
    }
    let words = what.replace('_', " ");
    // ASCII lowercasing keeps byte offsets, so the match's place in `message` is the same.
    match message.to_ascii_lowercase().find(&words) {
        Some(at) if words != what => format!("{}{what}{}", &message[..at], &message[at + words.len()..]),
        _ => format!("{what}: {message}"),
    }
}

/// `accel` (`NAME` or `NAME:KEY=VALUE,...`) with `accel_params` (more `KEY=VALUE` pairs for the
/// same structure), as the CLI's `--accel` and `--accel-params`.
fn accel_spec(accel: &str, accel_params: &str) -> PyResult<AccelSpec> {
    let spec: AccelSpec = parse("accel", accel)?;
    let more: gridtrace::AccelParams = parse("accel_params", accel_params)?;
    spec.with_params(&more)
        .map_err(|e| PyValueError::new_err(named("accel_params", &e)))
}

fn options(accel: &str, accel_params: &str, backend: &str, gpu_variant: &str) -> PyResult<QueryOptions> {
    Ok(QueryOptions {
        accel: accel_spec(accel, accel_params)?,
        backend: parse("backend", backend)?,
        gpu_variants: parse("gpu_variant", gpu_variant)?,
    })
}

/// An (N, 3) C-contiguous array as a slice of rows, without copying.
fn rows3<'a, T: numpy::Element + bytemuck::Pod>(a: &'a PyReadonlyArray2<'_, T>, what: &str) -> PyResult<&'a [[T; 3]]> {
    let shape = a.shape();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (N, 3), got {shape:?}"
        )));
    }
    let flat = a
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{what} must be C-contiguous")))?;
    // The length is a multiple of 3 (checked above), so the cast cannot fail.
    Ok(bytemuck::cast_slice(flat))
}

/// A ray batch as the library takes it: the backend, the origins and the directions.
type Batch<'a> = (Backend, &'a [[f32; 3]], &'a [[f32; 3]]);

/// The backend and the two point arrays of a ray batch.
fn batch<'a>(
    backend: &str,
    origins: &'a PyReadonlyArray2<'_, f32>,
    directions: &'a PyReadonlyArray2<'_, f32>,
) -> PyResult<Batch<'a>> {
    Ok((
        parse("backend", backend)?,
        rows3(origins, "origins")?,
        rows3(directions, "directions")?,
    ))
}

/// An accelerated triangle mesh (native part of `gridtrace.Mesh`).
#[pyclass(module = "gridtrace._gridtrace", frozen)]
struct NativeMesh {
    /// Queries share it; `update_vertices` takes it alone.
    inner: RwLock<TraceMesh>,
    /// The vertices and faces as given, for `vertices`, `faces` and pickling: the structure
    /// keeps neither (its triangles are precomputed, zero-area faces dropped). Taken after
    /// `inner` when both are.
    arrays: RwLock<MeshArrays>,
}

/// A mesh's vertices (as last moved) and faces (all of them, in input order).
struct MeshArrays {
    vertices: Vec<[f32; 3]>,
    faces: Vec<[u32; 3]>,
}

impl NativeMesh {
    fn new_from(mesh: TraceMesh, vertices: Vec<[f32; 3]>, faces: Vec<[u32; 3]>) -> Self {
        NativeMesh {
            inner: RwLock::new(mesh),
            arrays: RwLock::new(MeshArrays { vertices, faces }),
        }
    }

    fn mesh(&self) -> std::sync::RwLockReadGuard<'_, TraceMesh> {
        self.inner.read().unwrap_or_else(|p| p.into_inner())
    }

    fn arrays(&self) -> std::sync::RwLockReadGuard<'_, MeshArrays> {
        self.arrays.read().unwrap_or_else(|p| p.into_inner())
    }
}

#[pymethods]
impl NativeMesh {
    #[new]
    #[pyo3(signature = (vertices, faces, accel, accel_params, backend, gpu_variant = ""))]
    fn new(
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f32>,
        faces: PyReadonlyArray2<'_, u32>,
        accel: &str,
        accel_params: &str,
        backend: &str,
        gpu_variant: &str,
    ) -> PyResult<Self> {
        let opts = options(accel, accel_params, backend, gpu_variant)?;
        let v = rows3(&vertices, "vertices")?.to_vec();
        let f = rows3(&faces, "faces")?.to_vec();
        let inner = py.detach(|| TraceMesh::from_arrays(&v, &f, &opts)).map_err(to_py)?;
        Ok(NativeMesh::new_from(inner, v, f))
    }

    #[staticmethod]
    #[pyo3(signature = (path, accel, accel_params, backend, gpu_variant = ""))]
    fn load(
        py: Python<'_>,
        path: PathBuf,
        accel: &str,
        accel_params: &str,
        backend: &str,
        gpu_variant: &str,
    ) -> PyResult<Self> {
        let opts = options(accel, accel_params, backend, gpu_variant)?;
        let (inner, v, f) = py
            .detach(move || -> gridtrace::Result<_> {
                let mesh = gridtrace::io::load_mesh(&path)?;
                let v: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.to_array()).collect();
                let f = mesh.triangles.clone();
                Ok((TraceMesh::from_mesh(mesh, &opts)?, v, f))
            })
            .map_err(to_py)?;
        Ok(NativeMesh::new_from(inner, v, f))
    }

    /// Moves the vertices (an (N, 3) float32 array of the mesh's N vertices); the structure is
    /// updated where the mesh traces. Errors leave the previous mesh in place.
    fn update_vertices(&self, py: Python<'_>, vertices: PyReadonlyArray2<'_, f32>) -> PyResult<()> {
        let v = rows3(&vertices, "vertices")?.to_vec();
        py.detach(|| {
            let mut mesh = self.inner.write().unwrap_or_else(|p| p.into_inner());
            mesh.update_vertices(&v)?;
            // Under the structure's lock, so no reader sees the arrays ahead of the structure.
            self.arrays.write().unwrap_or_else(|p| p.into_inner()).vertices = v;
            Ok(())
        })
        .map_err(to_py)
    }

    /// The vertices, (N, 3) float32 (a copy).
    fn vertices<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let a = self.arrays();
        let flat: Vec<f32> = a.vertices.iter().flatten().copied().collect();
        flat.into_pyarray(py).reshape([a.vertices.len(), 3])
    }

    /// The faces, (M, 3) uint32 (a copy).
    fn faces<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<u32>>> {
        let a = self.arrays();
        let flat: Vec<u32> = a.faces.iter().flatten().copied().collect();
        flat.into_pyarray(py).reshape([a.faces.len(), 3])
    }

    #[getter]
    fn triangle_count(&self) -> usize {
        self.mesh().triangle_count()
    }

    /// What the last ray batch on the GPU took (a dict), or None while none has run there.
    fn last_gpu_batch<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, pyo3::types::PyDict>>> {
        match py.detach(|| self.mesh().last_gpu_batch()) {
            Some(s) => Ok(Some(stats::batch(py, &s)?)),
            None => Ok(None),
        }
    }

    /// What the last answered query did (a dict, the shape of `Scene.last_query`'s), or None
    /// before the first (`TraceMesh::last_query`).
    fn last_query<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, pyo3::types::PyDict>>> {
        let q = py.detach(|| self.mesh().last_query());
        stats::last_query(py, &q)
    }

    fn device(&self, py: Python<'_>, backend: &str) -> PyResult<String> {
        let b: Backend = parse("backend", backend)?;
        Ok(py.detach(|| self.mesh().device_for(b)))
    }

    /// Returns (t, tri, u, v, normal) as numpy arrays. `threads`: CPU threads (0: all cores).
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    #[pyo3(signature = (origins, directions, t_min, t_max, backend, threads = 0))]
    fn intersect<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: PyReadonlyArray2<'py, f32>,
        t_min: f32,
        t_max: f32,
        backend: &str,
        threads: usize,
    ) -> PyResult<(
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<u32>>,
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray2<f32>>,
    )> {
        let (b, o, d) = batch(backend, &origins, &directions)?;
        let hits = py
            .detach(|| on_threads(threads, || self.mesh().intersect_with(b, o, d, t_min, t_max)))?
            .map_err(to_py)?;
        let n = hits.len();
        // The same allocation, seen as 3n floats: no copy (12 bytes a ray, in fresh pages).
        let normal: Vec<f32> = bytemuck::allocation::cast_vec(hits.normal);
        let normal = normal.into_pyarray(py).reshape([n, 3])?;
        Ok((
            hits.t.into_pyarray(py),
            hits.tri.into_pyarray(py),
            hits.u.into_pyarray(py),
            hits.v.into_pyarray(py),
            normal,
        ))
    }

    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (origins, directions, t_min, t_max, backend, threads = 0))]
    fn occluded<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'py, f32>,
        directions: PyReadonlyArray2<'py, f32>,
        t_min: f32,
        t_max: f32,
        backend: &str,
        threads: usize,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (b, o, d) = batch(backend, &origins, &directions)?;
        let occ = py
            .detach(|| on_threads(threads, || self.mesh().occluded_with(b, o, d, t_min, t_max)))?
            .map_err(to_py)?;
        Ok(occ.into_pyarray(py))
    }
}

/// Renders a built-in scene, a scene file or a mesh file; returns (H, W, 3) uint8 sRGB.
#[pyfunction]
#[pyo3(signature = (scene, width, height, mode, accel, accel_params, backend, eye, target, gpu_variant = ""))]
#[allow(clippy::too_many_arguments)]
fn render<'py>(
    py: Python<'py>,
    scene: &str,
    width: u32,
    height: u32,
    mode: &str,
    accel: &str,
    accel_params: &str,
    backend: &str,
    eye: Option<[f32; 3]>,
    target: Option<[f32; 3]>,
    gpu_variant: &str,
) -> PyResult<(Bound<'py, PyArray3<u8>>, Bound<'py, pyo3::types::PyDict>)> {
    let variants: gridtrace::gpu::GpuVariants = parse("gpu_variant", gpu_variant)?;
    let mode: Mode = parse("mode", mode)?;
    let spec = accel_spec(accel, accel_params)?;
    let backend = parse::<Backend>("backend", backend)?;
    let scene_name = scene.to_string();
    let (rgb, frame, accel_name, notes) = py
        .detach(move || -> gridtrace::Result<(Vec<u8>, gridtrace::Frame, String, Vec<String>)> {
            let mut s = match gridtrace::scene::builtin::scene(&scene_name) {
                Some(s) => s,
                None => {
                    let path = std::path::Path::new(&scene_name);
                    // A bare word that is no file is a mistyped scene name, not a mesh file
                    // "with no extension": say so and list the names, as the CLI does.
                    if path.extension().is_none() && !path.exists() {
                        let names: Vec<_> = gridtrace::scene::builtin::SCENES.iter().map(|(n, _)| *n).collect();
                        return Err(gridtrace::Error::InvalidInput(format!(
                            "unknown scene '{scene_name}'; built-in scenes: {} (or a path to a .toml scene file or a mesh file)",
                            names.join(", ")
                        )));
                    }
                    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml")) {
                        gridtrace::scene::file::load_scene(path)?
                    } else {
                        gridtrace::scene::builtin::mesh_scene(gridtrace::io::load_mesh(path)?, true)
                    }
                }
            };
            if let Some(e) = eye {
                s.camera.eye = e.into();
            }
            if let Some(t) = target {
                s.camera.target = t.into();
            }
            // The CLI's path: the device, `auto`'s pick (its note kept), the scene, its upload.
            let opened = gridtrace::open_scene(&s, &spec, gridtrace::Work::Render, backend, variants)?;
            let (mut tracer, mut notes, accel) = (opened.tracer, opened.notes, opened.accel);
            let opts = RenderOptions::new(width, height, mode).with_pixels(PixelFormat::Srgb8);
            let (camera, lights) = (tracer.scene.camera, tracer.scene.lights.clone());
            let mut frame = tracer.render(&camera, &lights, &opts)?;
            notes.extend(tracer.take_notes());
            // The image goes to Python as bytes; the figures stay.
            let image = std::mem::replace(&mut frame.image, gridtrace::Image::new(1, 1));
            let image = if mode == Mode::Heat {
                image.heat_to_color()
            } else {
                image
            };
            Ok((image.to_rgb8(), frame, accel.name().to_string(), notes))
        })
        .map_err(to_py)?;
    let stats = stats::frame(py, &frame)?;
    // What was chosen, as the CLI prints it: the structure, and `auto`'s pick and why with
    // every other choice that was not the one asked for.
    stats.set_item("accel", accel_name)?;
    stats.set_item("notes", notes)?;
    Ok((
        rgb.into_pyarray(py).reshape([height as usize, width as usize, 3])?,
        stats,
    ))
}

#[pymodule]
fn _gridtrace(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NativeMesh>()?;
    m.add_class::<scene::NativeScene>()?;
    m.add_class::<sensor::NativeSensor>()?;
    m.add_function(wrap_pyfunction!(sensor::create_rays_pinhole, m)?)?;
    m.add_function(wrap_pyfunction!(sensor::create_rays_pinhole_fov, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(threads::_last_threads, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MAX_THREADS", gridtrace::util::MAX_THREADS)?;
    // The registry's names, with "auto" first: what `accel=` accepts (aliases aside).
    let accels: Vec<&str> = std::iter::once("auto")
        .chain(gridtrace::accel::registry::ENTRIES.iter().map(|e| e.name))
        .collect();
    m.add("ACCELS", accels)?;
    // Each structure's build parameters in words, as `accel="NAME:..."` and `accel_params=` take them.
    let params: std::collections::BTreeMap<&str, &str> = gridtrace::accel::registry::ENTRIES
        .iter()
        .map(|e| (e.name, e.params))
        .collect();
    m.add("ACCEL_PARAMS", params)?;
    m.add("GPU_VARIANTS", gpu_variants(m.py())?)?;
    Ok(())
}

/// The library's table of GPU variants (`gpu::variants::VARIANTS`), as `gpu_variant=` takes
/// them: key -> {"values" (the default first), "numbered" (`(prefix, min, max)` for values such
/// as `short3`, else `None`), "default", "structures" (the ones whose walk it changes; `None`:
/// every structure), "help"}.
fn gpu_variants(py: Python<'_>) -> PyResult<Bound<'_, pyo3::types::PyDict>> {
    use pyo3::types::PyDict;
    let all = PyDict::new(py);
    for r in &gridtrace::gpu::variants::VARIANTS {
        let row = PyDict::new(py);
        row.set_item("values", pyo3::types::PyTuple::new(py, r.values().collect::<Vec<_>>())?)?;
        row.set_item("numbered", r.numbered.map(|n| (n.prefix, n.min, n.max)))?;
        row.set_item("default", r.default_value())?;
        let structures = (!r.structures.is_empty()).then(|| r.structures.iter().map(|s| s.name()).collect::<Vec<_>>());
        row.set_item(
            "structures",
            structures.map(|s| pyo3::types::PyTuple::new(py, s)).transpose()?,
        )?;
        row.set_item("help", r.help)?;
        all.set_item(r.key, row)?;
    }
    Ok(all)
}
