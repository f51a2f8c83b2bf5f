//! A query's rays as the GPU's wire takes them (`gpu::WireSource`): the caller's origin and
//! direction arrays (either may be one value broadcast over the other), written as 24-byte
//! rays straight into the batch's mapped upload and checked on the way, in parallel, with the
//! rule and the error of the CPU's batches (`batch.rs`). No array of rays is made.

use crate::Error;
use crate::gpu::WireSource;

use super::batch::{first_bad_ray, is_valid_ray, ray_parts};

/// Rays `origins[i] + t * dirs[i]` of a batch of `n` (its broadcast length).
pub(super) struct SplitRays<'a> {
    pub origins: &'a [[f32; 3]],
    pub dirs: &'a [[f32; 3]],
    pub n: usize,
}

impl WireSource for SplitRays<'_> {
    fn len(&self) -> usize {
        self.n
    }

    fn stride(&self) -> usize {
        6
    }

    fn write(&self, first: usize, out: wgpu::WriteOnly<'_, [u8]>) -> bool {
        let (out, _) = out.into_chunks::<24>();
        let count = out.len();
        let mut all_valid = true;
        out.write_iter((first..first + count).map(|i| {
            let (o, d) = ray_parts(self.origins, self.dirs, i);
            all_valid &= is_valid_ray(o, d);
            bytemuck::cast::<[f32; 6], [u8; 24]>([o.x, o.y, o.z, d.x, d.y, d.z])
        }));
        all_valid
    }

    fn invalid(&self) -> Error {
        first_bad_ray(self.origins, self.dirs, 0, self.n)
    }
}
