//! Point queries (`compute_closest_points`, `compute_distance`, `compute_signed_distance`,
//! `compute_occupancy`). A moving scene on the CPU whose instances are all placed by
//! similarities finds its nearest points on the two levels (`two_level_points.rs`: no merged
//! mesh built after a move); otherwise, on the merged mesh: nearest points through the
//! structure's own search, on the CPU's cores
//! (`AccelStructure::closest_points_batch`: shells of cells on the grids, branch and bound on
//! the BVH, eight searches interleaved; the brute-force answer, tie rule included,
//! `accel::closest`) or, where the backend traces on a GPU, there (`GpuRenderer::closest_points`:
//! the same searches in WGSL, the same answers within rounding). The inside/outside decision
//! (winding numbers) follows the same choice: the fast winding tree walked on the GPU
//! (`GpuRenderer::winding_numbers`) or on the CPU's cores; `accuracy = inf` (the exact `f64`
//! sum) on the CPU.
//!
//! **Inside or outside** is decided by the generalised winding number of all the scene's
//! faces together (`accel::winding`, fast far-field sums): inside when it exceeds 0.5. For
//! closed, consistently oriented meshes (normals `(v1 - v0) x (v2 - v0)` facing out) that is
//! exact away from the surface: 1 inside, 0 outside (2 inside two overlapping closed meshes,
//! still inside). For an open mesh (holes, a single sheet) it is a smooth inside-ness: a point
//! is inside where the surface wraps it more than half way (behind a hemisphere's opening, in
//! front of a plane: about 0.5 and either side). Open3D decides by the parity of ray hits, which
//! a ray through an edge or a hole can flip; the winding number has no such failure on closed
//! meshes and degrades gracefully on open ones. On the surface the sign is whatever rounding
//! gives; the distance there is (near) zero.

use glam::Vec3;
use rayon::prelude::*;

use super::merged::Merged;
use super::{INVALID_ID, QueryScene};
use crate::Result;
use crate::accel::closest::ClosestPoint;
use crate::accel::winding::{BETA, check_accuracy, is_inside};

/// Nearest points, one entry per query point (Open3D's `compute_closest_points` keys). A
/// point with a non-finite coordinate, or any point of an empty scene: a NaN point, ids
/// `INVALID_ID`, uv and normal zero.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ClosestPoints {
    pub points: Vec<[f32; 3]>,
    pub geometry_ids: Vec<u32>,
    pub primitive_ids: Vec<u32>,
    /// Barycentric weights of the face's second and third vertex at the nearest point.
    pub primitive_uvs: Vec<[f32; 2]>,
    /// Unit geometric normal of the face in world space (zero for a zero-area face).
    pub primitive_normals: Vec<[f32; 3]>,
}

/// Points a worker takes at a time.
const BATCH: usize = 256;

impl QueryScene {
    /// The nearest point of the scene to each query point.
    pub fn compute_closest_points(&self, points: &[[f32; 3]]) -> Result<ClosestPoints> {
        let _record = self.recording("compute_closest_points");
        if let Some(levels) = self.point_levels()? {
            let closest = levels.nearest_all(points);
            return Ok(answers(&closest, |c| {
                c.world.is_found().then(|| {
                    let (geometry, prim, normal) = levels.name(c);
                    (c.world, geometry, prim, normal)
                })
            }));
        }
        let m = self.merged()?;
        let closest = self.closest(&m, points)?;
        Ok(answers(&closest, |c| {
            c.is_found().then(|| {
                let (geometry, prim) = m.name(c.tri);
                (
                    *c,
                    geometry,
                    prim,
                    m.tris()[c.tri as usize].normal().normalize_or_zero(),
                )
            })
        }))
    }

    /// The distance from each point to the scene: NaN for a point that is not finite, inf in
    /// an empty scene.
    pub fn compute_distance(&self, points: &[[f32; 3]]) -> Result<Vec<f32>> {
        let _record = self.recording("compute_distance");
        if let Some(levels) = self.point_levels()? {
            return Ok(levels.nearest_all(points).iter().map(|c| c.world.distance()).collect());
        }
        let m = self.merged()?;
        Ok(self.closest(&m, points)?.iter().map(ClosestPoint::distance).collect())
    }

    /// The distance, negative inside (module notes: winding number > 0.5), at the default
    /// accuracy (`accel::winding::BETA`).
    pub fn compute_signed_distance(&self, points: &[[f32; 3]]) -> Result<Vec<f32>> {
        self.compute_signed_distance_at(points, BETA)
    }

    /// `compute_signed_distance` with the winding numbers' `accuracy` (libigl's beta: larger is
    /// more accurate, `inf` exact; `accel::winding::check_accuracy`).
    pub fn compute_signed_distance_at(&self, points: &[[f32; 3]], accuracy: f64) -> Result<Vec<f32>> {
        let _record = self.recording("compute_signed_distance");
        let accuracy = check_accuracy(accuracy)?;
        let (distance, winding) = match self.point_levels()? {
            Some(levels) => (
                levels.nearest_all(points).iter().map(|c| c.world.distance()).collect(),
                self.scene_winding_numbers(points, accuracy)?,
            ),
            None => {
                let m = self.merged()?;
                let closest = self.closest(&m, points)?;
                let distance: Vec<f32> = closest.iter().map(ClosestPoint::distance).collect();
                (distance, winding_numbers(self, &m, points, accuracy)?)
            }
        };
        Ok(distance
            .into_iter()
            .zip(winding)
            .map(|(d, w)| if is_inside(w) { -d } else { d })
            .collect())
    }

    /// 1 inside, 0 outside (module notes), NaN for a point that is not finite.
    pub fn compute_occupancy(&self, points: &[[f32; 3]]) -> Result<Vec<f32>> {
        self.compute_occupancy_at(points, BETA)
    }

    /// `compute_occupancy` with the winding numbers' `accuracy` (as `compute_signed_distance_at`).
    pub fn compute_occupancy_at(&self, points: &[[f32; 3]], accuracy: f64) -> Result<Vec<f32>> {
        let _record = self.recording("compute_occupancy");
        let accuracy = check_accuracy(accuracy)?;
        Ok(self
            .scene_winding_numbers(points, accuracy)?
            .into_iter()
            .map(|w| match w {
                w if w.is_nan() => f32::NAN,
                w if is_inside(w) => 1.0,
                _ => 0.0,
            })
            .collect())
    }

    /// The generalised winding number of the scene's faces at each point (NaN for a point that
    /// is not finite; 0 everywhere in an empty scene).
    pub fn winding_numbers(&self, points: &[[f32; 3]]) -> Result<Vec<f32>> {
        self.winding_numbers_at(points, BETA)
    }

    /// `winding_numbers` with an `accuracy` (as `compute_signed_distance_at`).
    pub fn winding_numbers_at(&self, points: &[[f32; 3]], accuracy: f64) -> Result<Vec<f32>> {
        let _record = self.recording("compute_winding_number");
        let accuracy = check_accuracy(accuracy)?;
        self.scene_winding_numbers(points, accuracy)
    }

    /// The winding numbers at `points`: on the two levels where the nearest points are
    /// (`point_levels`: each instance's own tree, summed), else the faces' own tree where the
    /// merged mesh is not built (`winding_only.rs`: no ray structure built for them), else the
    /// merged mesh's.
    fn scene_winding_numbers(&self, points: &[[f32; 3]], accuracy: f64) -> Result<Vec<f32>> {
        if let Some(levels) = self.point_levels()? {
            return Ok(levels.winding_numbers(points, accuracy));
        }
        if let Some(w) = self.winding_only()? {
            return Ok(w.tree.winding_numbers_at(&w.tris, points, accuracy));
        }
        let m = self.merged()?;
        winding_numbers(self, &m, points, accuracy)
    }

    /// The structure's nearest point for each point (an error when it is stale).
    fn closest(&self, m: &Merged, points: &[[f32; 3]]) -> Result<Vec<ClosestPoint>> {
        let Some(mesh) = m.mesh.as_ref() else {
            return Ok(points
                .iter()
                .map(|p| {
                    if Vec3::from(*p).is_finite() {
                        ClosestPoint::NONE
                    } else {
                        ClosestPoint::INVALID
                    }
                })
                .collect());
        };
        // The mesh decides where (as `cast_rays`): the GPU's search where the backend traces on
        // one, else (or if `auto` found no GPU) the CPU's.
        self.on_mesh(
            mesh,
            |gpu| gpu.closest_points(&mesh.prepared().accel.tris, points),
            || mesh.closest_points_with(crate::query::Backend::Cpu, points),
        )
    }
}

/// The winding numbers of the merged mesh's faces at `points`: on the GPU where the mesh
/// traces there (`GpuRenderer::winding_numbers`: the CPU's tree uploaded once and walked the
/// same way), else (and for `accuracy = inf`, the exact `f64` sum) on the CPU's cores.
fn winding_numbers(s: &QueryScene, m: &Merged, points: &[[f32; 3]], accuracy: f64) -> Result<Vec<f32>> {
    let on_cpu = || Ok(m.winding().winding_numbers_at(m.tris(), points, accuracy));
    match m.mesh.as_ref() {
        None => Ok(points
            .iter()
            .map(|p| if Vec3::from(*p).is_finite() { 0.0 } else { f32::NAN })
            .collect()),
        Some(mesh) if accuracy.is_finite() => {
            s.on_mesh(mesh, |gpu| gpu.winding_numbers(m.winding(), points, accuracy), on_cpu)
        }
        Some(_) => on_cpu(),
    }
}

/// The closest points' arrays from one answer a point: `found(c)` names the world answer, its
/// geometry, primitive and unit normal, or `None` for a miss (NaN point, `INVALID_ID`s).
fn answers<T: Sync>(
    closest: &[T],
    found: impl Fn(&T) -> Option<(ClosestPoint, u32, u32, glam::Vec3)> + Sync,
) -> ClosestPoints {
    let n = closest.len();
    let mut out = ClosestPoints {
        points: vec![[f32::NAN; 3]; n],
        geometry_ids: vec![INVALID_ID; n],
        primitive_ids: vec![INVALID_ID; n],
        primitive_uvs: vec![[0.0; 2]; n],
        primitive_normals: vec![[0.0; 3]; n],
    };
    (
        &mut out.points[..],
        &mut out.geometry_ids[..],
        &mut out.primitive_ids[..],
        &mut out.primitive_uvs[..],
        &mut out.primitive_normals[..],
    )
        .into_par_iter()
        .zip(closest)
        .with_min_len(BATCH)
        .for_each(|((p, g, id, uv, normal), c)| {
            if let Some((c, geometry, prim, n)) = found(c) {
                *p = c.point.to_array();
                (*g, *id) = (geometry, prim);
                *uv = [c.u, c.v];
                *normal = n.to_array();
            }
        });
    out
}
