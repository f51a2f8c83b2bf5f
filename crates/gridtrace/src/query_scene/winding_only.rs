//! Winding numbers of a scene whose merged mesh is not built (`compute_winding_number`,
//! `compute_occupancy` on the CPU as a scene's first queries): the faces merged as `Merged`
//! merges them, zero-area ones dropped, and the fast winding tree over them in Morton order
//! (`FastWinding::build`), without the ray structure the merged mesh would build first. On
//! the Stanford Dragon that structure (the SAH BVH of `accel="bvh"`) took 0.67-0.77 s of a
//! 1.24 s whole call (docs/benchmarks.md, "Winding numbers against libigl"); the Morton tree
//! takes 0.2 s. A winding number is a sum over every face, so the faces' order is free and
//! the answers are the merged path's within the tree's accuracy. Dropped with the merged mesh
//! on any change; where the merged mesh is built, its tree answers (reusing its BVH).

use std::sync::Arc;

use rayon::prelude::*;

use super::QueryScene;
use super::geometry::is_degenerate;
use crate::Result;
use crate::accel::TriAccel;
use crate::accel::winding::FastWinding;

/// The scene's faces in world space and their winding tree.
pub(super) struct WindingOnly {
    pub tris: Vec<TriAccel>,
    pub tree: FastWinding,
}

impl QueryScene {
    /// The winding numbers' own faces and tree, built now if they are not; `None` where the
    /// merged mesh is built (its tree answers) or the queries trace on a GPU (the merged
    /// mesh's renderer walks its tree there).
    pub(super) fn winding_only(&self) -> Result<Option<Arc<WindingOnly>>> {
        if self.traces_on_gpu() || self.merged.lock().unwrap_or_else(|p| p.into_inner()).is_some() {
            return Ok(None);
        }
        let mut slot = self.winding_only.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(w) = slot.as_ref() {
            return Ok(Some(w.clone()));
        }
        // Parallel over each geometry's faces, not over the geometries: a scene of one mesh
        // (the common case) had converted its faces on one core (the Stanford Dragon's
        // 871,414: about 30 ms of a 0.2 s build, the other core idle).
        let mut tris: Vec<TriAccel> = Vec::new();
        for g in self.geometries.values() {
            let world = g.world_vertices();
            let faces = g.faces();
            tris.par_extend(faces.par_iter().with_min_len(4096).filter_map(|&f| {
                (!is_degenerate(&world, f)).then(|| {
                    let [a, b, c] = f.map(|k| glam::Vec3::from(world[k as usize]));
                    TriAccel::new(a, b, c)
                })
            }));
        }
        let tree = FastWinding::build(&tris);
        let w = Arc::new(WindingOnly { tris, tree });
        *slot = Some(w.clone());
        Ok(Some(w))
    }
}

#[cfg(test)]
mod tests {
    use glam::{Mat4, Vec3};

    use crate::QueryScene;
    use crate::query::{Backend, QueryOptions};
    use crate::testing::{cuboid, soup_arrays, triangle_soup};

    /// A fresh CPU scene's winding numbers and occupancy build no ray structure, answer as the
    /// merged mesh's tree does within the accuracy's bound, and follow a change (the faces'
    /// tree dropped with the merged mesh).
    #[test]
    fn winding_numbers_without_the_ray_structure() {
        let mut s = QueryScene::new(QueryOptions {
            backend: Backend::Cpu,
            ..Default::default()
        });
        let (v, f) = cuboid(Vec3::splat(-1.0), Vec3::splat(1.0));
        s.add_triangles(v.clone(), f.clone(), None).unwrap();
        let (sv, sf) = soup_arrays(&triangle_soup(500, 4));
        let shift = Some(Mat4::from_translation(Vec3::X * 2.0));
        s.add_triangles(sv.clone(), sf.clone(), shift).unwrap();
        let mut soup_alone = QueryScene::new(QueryOptions {
            backend: Backend::Cpu,
            ..Default::default()
        });
        soup_alone.add_triangles(sv, sf, shift).unwrap();
        let points: Vec<[f32; 3]> = (0..400)
            .map(|i| {
                let a = i as f32 * 0.37;
                [3.0 * a.sin(), 2.0 * (1.3 * a).cos(), 1.5 * (0.7 * a).sin()]
            })
            .collect();
        let alone = s.winding_numbers(&points).unwrap();
        let occupancy = s.compute_occupancy(&points).unwrap();
        assert_eq!(s.structure_builds(), 0, "no ray structure for winding numbers");
        // A ray query builds the merged mesh; its tree answers from then on.
        s.cast_rays(&[[0.0, 0.0, -5.0, 0.0, 0.0, 1.0]]).unwrap();
        assert_eq!(s.structure_builds(), 1);
        let merged = s.winding_numbers(&points).unwrap();
        let worst = alone
            .iter()
            .zip(&merged)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(worst < 0.01, "apart by {worst}");
        assert!(alone.iter().any(|&w| w.abs() > 0.9), "some points inside the box");
        assert_eq!(occupancy, s.compute_occupancy(&points).unwrap());
        // A change drops both; the faces' tree answers again, for the scene as it is now.
        s.remove(0).unwrap();
        assert_eq!(
            s.winding_numbers(&points).unwrap(),
            soup_alone.winding_numbers(&points).unwrap()
        );
        assert_eq!(s.structure_builds(), 1);
    }
}
