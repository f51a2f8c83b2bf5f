//! The two-level tests' scene: many instances of two small meshes, each under its own random
//! transform and mask, so that the CPU's two levels, the GPU's and the driver's instances are
//! held to each other on the same draws (`compare_hits`).

use glam::{Mat4, Quat, Vec3};

use super::{gpu_disagreements, on_triangle_boundary, t_close};
use crate::accel::{Hit, Ray};
use crate::query::QueryOptions;
use crate::query_scene::{InstanceOf, QueryScene, RayHits};
use crate::scene::procedural;
use crate::util::Rng;

/// `n` instances of two meshes (an icosphere, a torus knot, in turn) under random rotations,
/// scales (a third uneven, a seventh mirrored) and translations in a cube of side 16, each
/// with `mask(rng)` (drawn after its transform). The two geometries placed first serve only as
/// the instances' source and are removed: their meshes live on in the instances, whose ids are
/// `2..n + 2`.
pub fn instanced_scene(opts: QueryOptions, seed: u64, n: u32, mask: impl Fn(&mut Rng) -> u32) -> QueryScene {
    let mut rng = Rng::new(seed);
    let arrays = |m: &crate::Mesh| -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        (m.positions.iter().map(|p| p.to_array()).collect(), m.triangles.clone())
    };
    let meshes = [
        arrays(&procedural::icosphere(Vec3::ZERO, 0.6, 1)),
        arrays(&procedural::torus_knot(2, 3, 0.15, 24, 5)),
    ];
    let mut s = QueryScene::new(opts);
    let first = [
        s.add_triangles(meshes[0].0.clone(), meshes[0].1.clone(), None).unwrap(),
        s.add_triangles(meshes[1].0.clone(), meshes[1].1.clone(), None).unwrap(),
    ];
    for i in 0..n {
        let axis = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize_or(Vec3::Z);
        let mut scale = Vec3::splat(rng.range(0.4, 2.0));
        if i % 3 == 0 {
            scale *= Vec3::new(1.0, rng.range(0.5, 1.5), rng.range(0.5, 1.5));
        }
        if i % 7 == 0 {
            scale.x = -scale.x;
        }
        let m = Mat4::from_scale_rotation_translation(
            scale,
            Quat::from_axis_angle(axis, rng.range(0.0, std::f32::consts::TAU)),
            Vec3::new(rng.range(-8.0, 8.0), rng.range(-8.0, 8.0), rng.range(-8.0, 8.0)),
        );
        let m_i = mask(&mut rng);
        let id = s
            .add_instance(InstanceOf::Geometry(first[(i % 2) as usize]), Some(m), m_i)
            .unwrap();
        assert_eq!(id, i + 2, "instances are numbered after the two geometries");
    }
    s.remove(first[0]).unwrap();
    s.remove(first[1]).unwrap();
    s
}

/// `scene` made again from its parts (`QueryScene::parts`, `from_parts`) with `opts`: a fresh
/// scene in the moved scene's state, whose answers a move must give bit for bit.
pub fn rebuilt(scene: &QueryScene, opts: QueryOptions) -> QueryScene {
    let (meshes, instances) = scene.parts();
    let meshes = meshes.iter().map(|m| (m.vertices.clone(), m.faces.clone())).collect();
    QueryScene::from_parts(opts, scene.next_id(), meshes, instances).unwrap()
}

/// Move `step` (from 1) of the two-level tests: each of `ids` turned by `0.3 * step` about z
/// and shifted, after its own transform (one `set_transforms`), and `ids[3]` masked out.
pub fn move_step(scene: &mut QueryScene, ids: &[u32], step: u32) {
    let moved: Vec<Mat4> = ids
        .iter()
        .map(|&id| {
            Mat4::from_rotation_z(0.3 * step as f32)
                * Mat4::from_translation(Vec3::new(0.5, -0.2, 0.1 * step as f32))
                * scene.geometry(id).unwrap().transform()
        })
        .collect();
    scene.set_transforms(ids, &moved).unwrap();
    scene.set_mask(ids[3], 0).unwrap();
}

/// Ray `i`'s answer in a batch as a `Hit` (`t`, the face within its geometry, `u`, `v`; a miss
/// `tri = u32::MAX`, as `INVALID_ID`).
pub fn ray_hit(h: &RayHits, i: usize) -> Hit {
    Hit {
        t: h.t_hit[i],
        tri: h.primitive_ids[i],
        u: h.primitive_uvs[i][0],
        v: h.primitive_uvs[i][1],
    }
}

/// The GPU's answers (`g`, `occ`) to `rays` against the CPU's (`c`): hit or miss as
/// `gpu_disagreements` allows, t within 1e-5 relative or the two triangle tests' rounding
/// (`t_close`), the same instance and face or else a face's boundary, and the same normal.
/// Returns (hits compared, t within rounding only, other faces on a boundary, hit-or-miss
/// excused), for the caller to bound.
pub fn compare_hits(what: &str, rays: &[Ray], c: &RayHits, g: &RayHits, occ: &[bool]) -> [usize; 4] {
    let as_hits = |h: &RayHits| -> Vec<Hit> { (0..h.len()).map(|i| ray_hit(h, i)).collect() };
    let (bad, excused) = gpu_disagreements(rays, &as_hits(c), &as_hits(g), occ);
    assert!(bad.is_empty(), "{what}: rays {bad:?} disagree");
    let (mut hits, mut rounding, mut boundary) = (0, 0, 0);
    for (i, r) in rays.iter().enumerate() {
        if !(c.t_hit[i].is_finite() && g.t_hit[i].is_finite()) {
            continue;
        }
        hits += 1;
        let (a, b) = (c.t_hit[i], g.t_hit[i]);
        if (a - b).abs() > 1e-5 * a.abs().max(b.abs()) {
            assert!(t_close(r, a, b), "{what} ray {i}: t {a} vs {b}");
            rounding += 1;
        }
        if (c.geometry_ids[i], c.primitive_ids[i]) != (g.geometry_ids[i], g.primitive_ids[i]) {
            let on_edge = [c, g].iter().any(|h| on_triangle_boundary(&ray_hit(h, i)));
            assert!(
                on_edge,
                "{what} ray {i}: cpu {} gpu {}",
                c.geometry_ids[i], g.geometry_ids[i]
            );
            boundary += 1;
        } else {
            let (nc, ng) = (Vec3::from(c.primitive_normals[i]), Vec3::from(g.primitive_normals[i]));
            assert!(nc.abs_diff_eq(ng, 1e-5), "{what} ray {i}: normal {nc} vs {ng}");
        }
    }
    [hits, rounding, boundary, excused]
}
