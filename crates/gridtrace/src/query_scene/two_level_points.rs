//! Nearest points on the two levels (`compute_closest_points`, `compute_distance`, the magnitude
//! of `compute_signed_distance`) where every instance is placed by a similarity (rotation,
//! reflection, uniform scale, translation: `Geometry::similarity`), so that a move builds no
//! merged mesh for them.
//!
//! For each point the top level is walked nearest box first (`TopLevel::nearest`: branch and
//! bound on the squared distance from the point to each instance's world box, a box strictly
//! farther than the best so far skipped). At each instance reached the point is carried into
//! the mesh's own space and that mesh's structure finds its nearest point there
//! (`Accel::closest_point`, the search every structure has, tie rule included); under a
//! similarity that point, carried back by the instance's transform, is the nearest point of the
//! placed mesh. Its world distance is measured from the world points, so the answer is the
//! merged mesh's up to rounding (the merged mesh's faces are the world vertices rounded once
//! more). The world boxes are padded (`two_level::padded`), so a box's distance is a lower
//! bound on its instance's.
//!
//! Where two instances are equally near, the smaller id wins, as the merged mesh's smaller
//! merged face does (its faces are in ascending id); within an instance, its structure's tie
//! rule. Masks do not apply to point queries (the merged mesh holds every geometry): every
//! instance is searched.
//!
//! Any other transform (an uneven scale, a shear) maps the nearest point in own space to a
//! point that need not be the nearest in world space: a scene with one such instance answers
//! its point queries on the merged mesh, as before (`QueryScene::point_levels`).

use std::sync::Arc;

use glam::{Affine3A, Vec3};
use rayon::prelude::*;

use super::QueryScene;
use super::geometry::normal_to_world;
use super::two_level::TwoLevel;
use crate::Result;
use crate::accel::closest::ClosestPoint;

/// Points a worker takes at a time.
const BATCH: usize = 64;

/// The nearest point of the scene to a query point, found on the two levels: `world` in world
/// terms (point, squared distance, u and v; `tri` the index of the instance in
/// `TwoLevel::placed`, `u32::MAX` for none) and the triangle of that instance's structure.
#[derive(Debug, Clone, Copy)]
pub(super) struct LevelPoint {
    pub world: ClosestPoint,
    pub tri: u32,
}

/// The two levels and each instance's own-to-world transform, for one query.
pub(super) struct PointLevels {
    pub two: Arc<TwoLevel>,
    to_world: Vec<Affine3A>,
}

impl QueryScene {
    /// The two levels the point queries walk, where they may: a scene that moves (`moving`: a
    /// static one answers on its merged mesh, one structure over every triangle, built once),
    /// traced on the CPU (a GPU's point queries run on its merged mesh), whose every instance
    /// is placed by a similarity. `None` otherwise: the merged mesh answers.
    pub(super) fn point_levels(&self) -> Result<Option<PointLevels>> {
        if !self.moving || self.traces_on_gpu() || self.geometries.values().any(|g| g.similarity().is_none()) {
            return Ok(None);
        }
        let two = self.two_level()?;
        two.check_cpu(false)?;
        let to_world = two
            .placed
            .iter()
            .map(|p| Affine3A::from_mat4(self.geometries[&p.id].transform()))
            .collect();
        Ok(Some(PointLevels { two, to_world }))
    }
}

impl PointLevels {
    /// The nearest point to each of `points`, on all cores.
    pub fn nearest_all(&self, points: &[[f32; 3]]) -> Vec<LevelPoint> {
        points
            .par_iter()
            .with_min_len(BATCH)
            .map(|&p| self.nearest(Vec3::from(p)))
            .collect()
    }

    /// The nearest point to `p` (module notes): `ClosestPoint::INVALID` for a point that is
    /// not finite, `ClosestPoint::NONE` where there is no instance.
    pub fn nearest(&self, p: Vec3) -> LevelPoint {
        let mut best = LevelPoint {
            world: if p.is_finite() {
                ClosestPoint::NONE
            } else {
                ClosestPoint::INVALID
            },
            tri: u32::MAX,
        };
        let placed = &self.two.placed;
        self.two.top().nearest(p, |i, _, best_d2| {
            let here = &placed[i as usize];
            let c = self.two.accel_of(i).closest_point(here.to_local.transform_point3(p));
            if !c.is_found() {
                return best_d2;
            }
            let point = self.to_world[i as usize].transform_point3(c.point);
            let d2 = (point - p).length_squared();
            let found = best.world.is_found();
            if !found || d2 < best_d2 || (d2 == best_d2 && here.id < placed[best.world.tri as usize].id) {
                best = LevelPoint {
                    world: ClosestPoint {
                        point,
                        dist_sq: d2,
                        tri: i,
                        u: c.u,
                        v: c.v,
                    },
                    tri: c.tri,
                };
                return d2;
            }
            best_d2
        });
        best
    }

    /// The winding number of every instance's faces together at each of `points` (NaN for a
    /// point that is not finite), on all cores: each instance's own winding tree at the point
    /// carried into its space, summed, with the sign flipped for a mirroring instance (a
    /// mirror turns a face's orientation, and so its solid angle's sign; any other invertible
    /// affine map keeps the exact winding number). The far-field sums are taken in each
    /// mesh's own space, so the answer is the merged tree's within the accuracy's bound, not
    /// to the bit. Each point visits every instance (an open mesh far away still winds
    /// around it a little); a distant instance is one far-field term at its tree's root.
    pub fn winding_numbers(&self, points: &[[f32; 3]], accuracy: f64) -> Vec<f32> {
        let placed = &self.two.placed;
        let sign: Vec<f32> = placed
            .iter()
            .map(|p| p.to_local.matrix3.determinant().signum())
            .collect();
        for i in 0..placed.len() as u32 {
            self.two.winding_of(i); // built before the workers share it
        }
        points
            .par_iter()
            .with_min_len(BATCH)
            .map_init(Vec::new, |stack, &p| {
                let p = Vec3::from(p);
                if !p.is_finite() {
                    return f32::NAN;
                }
                (0..placed.len() as u32)
                    .map(|i| {
                        let local = placed[i as usize].to_local.transform_point3(p);
                        let tris = &self.two.accel_of(i).tris;
                        sign[i as usize] * self.two.winding_of(i).winding_number_with(tris, local, accuracy, stack)
                    })
                    .sum()
            })
            .collect()
    }

    /// A found point's geometry id, its face's index in that geometry's faces, and the face's
    /// world-space unit geometric normal.
    pub fn name(&self, c: &LevelPoint) -> (u32, u32, Vec3) {
        let i = c.world.tri;
        let placed = &self.two.placed[i as usize];
        let n_local = self.two.accel_of(i).tris[c.tri as usize].normal();
        let n = (normal_to_world(&placed.to_local) * n_local).normalize_or_zero();
        (placed.id, self.two.prim_of(i, c.tri), n)
    }
}
