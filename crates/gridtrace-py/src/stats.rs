//! What a frame or a ray batch took, as Python dicts with the CLI's meanings (`render`'s and
//! `rays`' `gpu` lines): `wall_ms` from the first upload to the result in host memory,
//! `gpu_ms` the device's own time (`None` without timestamp queries, and on the CPU), host
//! round trips and bytes each way, the stages' milliseconds, and the host's share of the wall
//! time (`host_ms`: prepare, wait, readout).

use gridtrace::Frame;
use gridtrace::gpu::{GpuQueryStats, GpuTimings};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The keys a frame and a batch share.
fn common<'py>(
    py: Python<'py>,
    wall_ms: f64,
    timings: Option<&GpuTimings>,
    transfers: (u32, u64, u64),
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("wall_ms", wall_ms)?;
    let gpu_ms = timings.filter(|t| t.from_timestamps).map(|t| t.total_ms);
    d.set_item("gpu_ms", gpu_ms)?;
    d.set_item("round_trips", transfers.0)?;
    d.set_item("uploaded_bytes", transfers.1)?;
    d.set_item("downloaded_bytes", transfers.2)?;
    let stages = PyDict::new(py);
    if let Some(t) = timings.filter(|t| t.from_timestamps) {
        for (name, ms) in &t.stages_ms {
            stages.set_item(*name, *ms)?;
        }
    }
    d.set_item("stages_ms", stages)?;
    // Where the wall time went on the host: preparing and submitting, waiting for the device,
    // reading the results out (they add up to wall_ms; empty on the CPU).
    let host = PyDict::new(py);
    if let Some(t) = timings {
        host.set_item("prepare", t.host.prepare_ms)?;
        host.set_item("wait", t.host.wait_ms)?;
        host.set_item("readout", t.host.readout_ms)?;
    }
    d.set_item("host_ms", host)?;
    Ok(d)
}

/// A rendered frame's figures; `backend` is `"gpu"` or `"cpu"` (whose transfers are 0).
pub fn frame<'py>(py: Python<'py>, f: &Frame) -> PyResult<Bound<'py, PyDict>> {
    let d = match &f.gpu {
        Some(g) => common(
            py,
            g.wall_ms,
            Some(&g.timings),
            (g.round_trips, g.uploaded_bytes, g.downloaded_bytes),
        )?,
        None => common(py, f.stats.render_ms, None, (0, 0, 0))?,
    };
    d.set_item("backend", if f.gpu.is_some() { "gpu" } else { "cpu" })?;
    d.set_item("tiles", f.gpu.as_ref().map_or(0, |g| g.tiles))?;
    let r = f.stats.rays;
    d.set_item("rays", (r.eye, r.shadow, r.reflection))?;
    d.set_item("mrays_per_s", f.stats.mrays_per_s())?;
    Ok(d)
}

/// A GPU ray batch's figures.
pub fn batch<'py>(py: Python<'py>, s: &GpuQueryStats) -> PyResult<Bound<'py, PyDict>> {
    let d = common(
        py,
        s.wall_ms,
        Some(&s.timings),
        (s.round_trips, s.uploaded_bytes, s.downloaded_bytes),
    )?;
    d.set_item("rays", s.rays)?;
    d.set_item("chunks", s.chunks)?;
    Ok(d)
}

/// What a scene's or a mesh's last query did (`LastQuery`), one shape for both: `name`,
/// `device` (`"gpu"` or `"cpu"`), `gpu` (the batch as `batch` gives it, or None on the CPU)
/// and `note` (on the query that met a GPU fault under `auto`, what failed; else None); None
/// before the first query.
pub fn last_query<'py>(py: Python<'py>, q: &gridtrace::query::LastQuery) -> PyResult<Option<Bound<'py, PyDict>>> {
    if q.name.is_empty() {
        return Ok(None);
    }
    let d = PyDict::new(py);
    d.set_item("name", q.name)?;
    d.set_item("device", q.device)?;
    match &q.gpu {
        Some(s) => d.set_item("gpu", batch(py, s)?)?,
        None => d.set_item("gpu", py.None())?,
    }
    d.set_item("note", q.note.as_deref())?;
    Ok(Some(d))
}
