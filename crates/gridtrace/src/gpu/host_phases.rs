//! Where a frame's or a batch's wall time went on the host: before the submission, waiting for
//! the device, reading the results out. Apart from `timing` (the device's clock), because the
//! context measures the wait and the readout where it maps the results.

/// Where a frame's or a batch's wall time went, on the host's clock (ms); the three add up to
/// the wall time. The first hardware run (H200, docs/benchmarks.md) found 1920x1080 frames
/// taking 13-30 ms of wall time for 0.5-5 ms of device time, and 1M-ray batches 37-90 ms for
/// 0.3-3 ms: this says which side of the submission the rest is on.
#[derive(Debug, Default, Clone, Copy, PartialEq, serde::Serialize)]
pub struct HostPhases {
    /// Before the submission: inputs written (rays, uniforms), outputs allocated, commands
    /// recorded and submitted.
    pub prepare_ms: f64,
    /// From the submission until the results are mapped: the device's work, the transfers
    /// both ways, and the driver's latency.
    pub wait_ms: f64,
    /// Copying and converting the mapped results into the caller's form.
    pub readout_ms: f64,
}

impl HostPhases {
    /// Adds a later submission's phases.
    pub fn add(&mut self, other: &HostPhases) {
        self.prepare_ms += other.prepare_ms;
        self.wait_ms += other.wait_ms;
        self.readout_ms += other.readout_ms;
    }

    /// Sets the preparation to what the waits and readouts of a frame or batch leave of its
    /// `wall_ms`: everything before and between its submissions.
    pub(crate) fn close(&mut self, wall_ms: f64) {
        self.prepare_ms = wall_ms - self.wait_ms - self.readout_ms;
    }
}

impl std::fmt::Display for HostPhases {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "prepare {:.2}, wait {:.2}, readout {:.2} ms",
            self.prepare_ms, self.wait_ms, self.readout_ms
        )
    }
}
