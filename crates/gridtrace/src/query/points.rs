//! Closest points of a `TraceMesh`, on the backend its queries trace on: the structure's own
//! search on the CPU's cores (`accel::closest::closest_points`) or on the GPU
//! (`GpuRenderer::closest_points`), with the same answers (distances equal within rounding;
//! the same triangle unless two are equally near).

use super::{Backend, TraceMesh};
use crate::Result;
use crate::accel::closest::{ClosestPoint, closest_points};

impl TraceMesh {
    /// The nearest point of the mesh to each of `points`, on the mesh's backend; `tri` is a
    /// kept triangle's index (`original_index` gives the input face). A point with a
    /// non-finite coordinate gets `ClosestPoint::INVALID` (NaN distance).
    pub fn closest_points(&self, points: &[[f32; 3]]) -> Result<Vec<ClosestPoint>> {
        self.closest_points_with(self.backend, points)
    }

    /// `closest_points` on a given backend.
    pub fn closest_points_with(&self, backend: Backend, points: &[[f32; 3]]) -> Result<Vec<ClosestPoint>> {
        self.on_backend(
            "closest_points",
            backend,
            |gpu| gpu.closest_points(&self.scene.accel.tris, points),
            || closest_points(&self.scene.accel, points),
        )
    }
}
