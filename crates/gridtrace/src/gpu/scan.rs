//! Scans on the device: a sensor's rays made where they are traced. The host sends the sensor's
//! table (each cell's ray in the sensor's frame, 24 bytes a cell, once: it stays on the device
//! while scans use the same table) and each environment's column poses (48 bytes a column); the
//! batch kernel makes every ray from them (`batch.wgsl`, stride 0) and the usual walks trace
//! them. A LiDAR of 16 x 1,800 cells sends 86 KB of poses a scan where its rays would be 691 KB,
//! and 64 environments go in one batch. The answers come down as the caller asks: `t` alone for
//! a range (4 bytes a ray), or the hits.

use super::queries::{Answer, ChunkAnswers, SensorLayout, WireSource};
use super::renderer::{GpuRenderer, MAX_SCAN_RAYS};
use crate::{Error, Result};

/// A scan's rays: nothing on the wire, `n` rays made on the device.
struct SensorRays {
    n: usize,
    layout: SensorLayout,
}

impl WireSource for SensorRays {
    fn len(&self) -> usize {
        self.n
    }
    fn stride(&self) -> usize {
        0
    }
    fn write(&self, _first: usize, _out: wgpu::WriteOnly<'_, [u8]>) -> bool {
        true
    }
    fn invalid(&self) -> Error {
        Error::InvalidInput("a scan's rays are made on the device from checked poses".into())
    }
    fn sensor(&self) -> Option<SensorLayout> {
        Some(self.layout)
    }
}

/// A pose as the kernel reads it: the sensor-to-world matrix's three columns, then the
/// translation.
pub type PoseColumns = [f32; 12];

/// A scan's rays as the device makes them: each cell's ray in the sensor's frame (origin, unit
/// direction; row-major, `cols` a row) and each environment's poses, `pose_cols` of them (one a
/// column for a rolling scan, else one).
#[derive(Debug, Clone, Copy)]
pub struct ScanRays<'a> {
    pub table: &'a [[f32; 6]],
    pub cols: usize,
    pub poses: &'a [PoseColumns],
    pub pose_cols: usize,
}

impl ScanRays<'_> {
    /// Rays of the scan: cells times environments.
    pub fn len(&self) -> usize {
        self.table.len() * (self.poses.len() / self.pose_cols.max(1))
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl GpuRenderer {
    /// Lowers the rays of a scan's submission to `rays` (at least 1): tests make a small scan of
    /// many submissions with it.
    #[doc(hidden)]
    pub fn set_max_scan_rays(&mut self, rays: u32) {
        self.max_scan_rays = rays.clamp(1, MAX_SCAN_RAYS);
    }

    /// Traces a sensor from `rays.poses.len() / rays.pose_cols` environments (`ScanRays`). Ray
    /// `e * cells + cell` is cell `cell` of the table carried into the world by its column's
    /// pose of environment `e` (its one pose), and answers
    /// `answer` within `interval` (closest hits: `Answer::Range` or `Answer::Hits`), handed to
    /// `take` chunk by chunk as `cast` does. The table goes up only when it differs from the
    /// last scan's; the bytes sent are in `last_query_stats`.
    pub fn scan(
        &mut self,
        rays: &ScanRays,
        interval: (f32, f32),
        answer: Answer,
        take: impl FnMut(usize, ChunkAnswers<'_>),
    ) -> Result<()> {
        let ScanRays {
            table,
            cols,
            poses,
            pose_cols,
        } = *rays;
        if answer == Answer::Occlusion {
            return Err(Error::InvalidInput("a scan answers closest hits, not occlusion".into()));
        }
        if cols == 0
            || table.is_empty()
            || !table.len().is_multiple_of(cols)
            || !(pose_cols == 1 || pose_cols == cols)
            || !poses.len().is_multiple_of(pose_cols)
        {
            return Err(Error::InvalidInput(format!(
                "scan: a table of {} cells and {} poses ({pose_cols} an environment) do not make whole \
                 rows of {cols} columns",
                table.len(),
                poses.len()
            )));
        }
        let n = (poses.len() / pose_cols)
            .checked_mul(table.len())
            .filter(|&n| n <= u32::MAX as usize)
            .ok_or_else(|| {
                Error::InvalidInput(format!(
                    "scan: {} environments of {} cells are more than 2^32 rays in one batch",
                    poses.len() / pose_cols,
                    table.len()
                ))
            })?;
        let table_floats = table.len() * 6;
        let layout = SensorLayout {
            cells: table.len() as u32,
            cols: cols as u32,
            poses_at: u32::try_from(table_floats)
                .map_err(|_| Error::InvalidInput("scan: a sensor table over 2^32 floats".into()))?,
            pose_cols: pose_cols as u32,
        };
        let table_bytes = (table_floats * size_of::<f32>()) as u64;
        let poses_bytes = size_of_val(poses) as u64;
        self.ensure_batch_device(self.chunk_items(n, true) as u64, table_bytes + poses_bytes);
        let device = self.batches.device.as_ref().expect("made just above");
        let q = &self.ctx.queue;
        let mut sent = poses_bytes;
        if self.batches.sensor_table.as_deref() != Some(table) {
            q.write_buffer(&device.sensor, 0, bytemuck::cast_slice(table));
            self.batches.sensor_table = Some(table.to_vec());
            sent += table_bytes;
        }
        if poses_bytes > 0 {
            q.write_buffer(&device.sensor, table_bytes, bytemuck::cast_slice(poses));
        }
        let source = SensorRays { n, layout };
        self.cast(&source, interval, answer, take)?;
        self.last_query.uploaded_bytes += sent;
        Ok(())
    }
}
