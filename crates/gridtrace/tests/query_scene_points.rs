//! Point queries of a moving `QueryScene` on its two levels (`query_scene/two_level_points.rs`):
//! instances under random similarity transforms (rotations, mirrors, uniform scales,
//! translations) answer closest points, distances and signed distances as the same scene
//! merged flat (one world-space mesh) and as brute force, on every structure the CPU walks,
//! with masks ignored as the merged mesh ignores them; a move followed by point queries builds
//! no mesh structure; a scene with one instance under another transform (an uneven scale)
//! answers on its merged mesh, bit for bit the flat scene's answers.

use glam::{Mat4, Quat, Vec3};
use gridtrace::Mesh;
use gridtrace::accel::closest::closest_point_brute;
use gridtrace::accel::{AccelKind, TriAccel};
use gridtrace::query::{Backend, QueryOptions};
use gridtrace::query_scene::{InstanceOf, QueryScene};
use gridtrace::scene::procedural;
use gridtrace::util::Rng;
use rayon::prelude::*;

type Arrays = (Vec<[f32; 3]>, Vec<[u32; 3]>);

fn arrays(m: &Mesh) -> Arrays {
    (m.positions.iter().map(|p| p.to_array()).collect(), m.triangles.clone())
}

/// The structures the CPU walks.
fn kinds() -> impl Iterator<Item = AccelKind> {
    AccelKind::ALL.into_iter().filter(|k| k.entry().cpu)
}

fn cpu(kind: AccelKind) -> QueryOptions {
    QueryOptions {
        accel: kind.into(),
        backend: Backend::Cpu,
        ..Default::default()
    }
}

/// A random similarity: a rotation, a uniform scale in [0.4, 2], a mirror one time in four, a
/// translation within `spread` of the origin.
fn similarity(rng: &mut Rng, spread: f32) -> Mat4 {
    let axis = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize_or(Vec3::Z);
    let mut scale = Vec3::splat(rng.range(0.4, 2.0));
    if rng.below(4) == 0 {
        scale[rng.below(3) as usize] *= -1.0;
    }
    Mat4::from_scale_rotation_translation(
        scale,
        Quat::from_axis_angle(axis, rng.range(0.0, std::f32::consts::TAU)),
        Vec3::new(
            rng.range(-spread, spread),
            rng.range(-spread, spread),
            rng.range(-spread, spread),
        ),
    )
}

/// Three small meshes (two closed: an icosphere and a torus knot; one open: a plane), placed
/// `n` times under random similarities with random masks (some zero), the three first
/// geometries removed (their meshes live on in the instances).
fn instanced(opts: QueryOptions, n: u32, seed: u64) -> QueryScene {
    let mut rng = Rng::new(seed);
    let meshes = [
        arrays(&procedural::icosphere(Vec3::ZERO, 0.6, 1)),
        arrays(&procedural::torus_knot(2, 3, 0.15, 24, 5)),
        arrays(&procedural::plane(1.5, 3)),
    ];
    let mut s = QueryScene::new(opts);
    let first: Vec<u32> = meshes
        .iter()
        .map(|(v, f)| s.add_triangles(v.clone(), f.clone(), None).unwrap())
        .collect();
    for i in 0..n {
        let m = similarity(&mut rng, 6.0);
        let mask = [0, 1, 2, u32::MAX][rng.below(4) as usize];
        s.add_instance(InstanceOf::Geometry(first[(i % 3) as usize]), Some(m), mask)
            .unwrap();
    }
    for id in first {
        s.remove(id).unwrap();
    }
    s
}

/// The scene's world-space triangles as one mesh (a static scene of one geometry: its point
/// queries run on the merged mesh), its non-degenerate triangles for brute force and their
/// (id, face) names, and every face's name (the flat mesh's primitive ids index it).
type Flat = (QueryScene, Vec<TriAccel>, Vec<(u32, u32)>, Vec<(u32, u32)>);

fn flat(scene: &QueryScene, opts: QueryOptions) -> Flat {
    let (mut v, mut f, mut tris, mut names) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut faces = Vec::new();
    for id in scene.ids() {
        let g = scene.geometry(id).unwrap();
        let base = v.len() as u32;
        let world = g.world_vertices();
        for (k, face) in g.faces().iter().enumerate() {
            f.push(face.map(|x| x + base));
            faces.push((id, k as u32));
            let [a, b, c] = face.map(|x| Vec3::from(world[x as usize]));
            if (b - a).cross(c - a).length_squared() > 0.0 {
                tris.push(TriAccel::new(a, b, c));
                names.push((id, k as u32));
            }
        }
        v.extend(world);
    }
    let mut s = QueryScene::new(opts);
    s.add_triangles(v, f, None).unwrap();
    (s, tris, names, faces)
}

/// Random points in and around the scene (a box of side 14, one of 40), points on the
/// instances' vertices and faces, and two bad ones.
fn points(tris: &[TriAccel], n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = Rng::new(seed);
    let mut out: Vec<[f32; 3]> = (0..n)
        .map(|i| {
            let s = [7.0, 20.0][i % 2];
            [rng.range(-s, s), rng.range(-s, s), rng.range(-s, s)]
        })
        .collect();
    for t in tris.iter().step_by(23) {
        let [a, b, c] = t.vertices();
        out.extend([a, (a + b + c) / 3.0].map(|p| p.to_array()));
    }
    out.push([f32::NAN, 0.0, 0.0]);
    out.push([0.0, f32::INFINITY, 0.0]);
    out
}

/// Whether two distances agree within 1e-5 relative, or 2e-6 absolute (points on a face: a
/// distance of rounding alone).
fn close(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a - b).abs() <= 1e-5 * a.abs().max(b.abs()) + 2e-6
}

/// `scene`'s closest points and distances against the flat scene's and brute force's: the
/// distances close, the same (geometry, face) but at ties (the face named as near as the
/// merged mesh's; those inside a face, not at an edge or vertex, counted), the point, uv and
/// normal the same. Returns (points compared, ties inside a face).
fn check_points(scene: &QueryScene, kind: AccelKind, what: &str) -> (usize, usize) {
    let (flat, tris, names, faces) = flat(scene, cpu(kind));
    let pts = points(&tris, 1500, 9);
    let got = scene.compute_closest_points(&pts).unwrap();
    let dist = scene.compute_distance(&pts).unwrap();
    let want = flat.compute_closest_points(&pts).unwrap();
    let want_dist = flat.compute_distance(&pts).unwrap();
    let truth: Vec<_> = pts
        .par_iter()
        .map(|p| closest_point_brute(&tris, Vec3::from(*p)))
        .collect();
    let face_of = |name: (u32, u32)| names.iter().position(|&n| n == name).unwrap();
    let mut ties = 0;
    for (i, p) in pts.iter().enumerate() {
        let what = format!("{what} {} point {i} {p:?}", kind.name());
        if !Vec3::from(*p).is_finite() {
            assert!(dist[i].is_nan() && got.geometry_ids[i] == u32::MAX, "{what}: bad point");
            continue;
        }
        assert!(
            close(dist[i], want_dist[i]),
            "{what}: {} vs merged {}",
            dist[i],
            want_dist[i]
        );
        assert!(
            close(dist[i], truth[i].distance()),
            "{what}: {} vs brute force",
            dist[i]
        );
        let at = Vec3::from(got.points[i]);
        assert!(
            close((at - Vec3::from(*p)).length(), dist[i]),
            "{what}: point and distance"
        );
        let name = (got.geometry_ids[i], got.primitive_ids[i]);
        if name != faces[want.primitive_ids[i] as usize] {
            // A tie: the face named is as near as the merged mesh's.
            let d = closest_point_brute(&tris[face_of(name)..face_of(name) + 1], Vec3::from(*p)).distance();
            assert!(
                close(d, want_dist[i]),
                "{what}: {name:?} at {d}, merged {}",
                want_dist[i]
            );
            // At an edge or a vertex the faces that share it tie, and which one's rounding
            // comes out nearer differs between the spaces: those are not counted.
            let [u, v] = got.primitive_uvs[i];
            if u.min(v).min(1.0 - u - v) > 1e-4 {
                ties += 1;
            }
            continue;
        }
        assert!(
            at.abs_diff_eq(Vec3::from(want.points[i]), 1e-5 * at.abs().max_element().max(1.0)),
            "{what}: point"
        );
        let (u, v) = (got.primitive_uvs[i], want.primitive_uvs[i]);
        assert!(
            (u[0] - v[0]).abs() < 1e-3 && (u[1] - v[1]).abs() < 1e-3,
            "{what}: uv {u:?} vs {v:?}"
        );
        assert!(
            Vec3::from(got.primitive_normals[i]).abs_diff_eq(Vec3::from(want.primitive_normals[i]), 1e-4),
            "{what}: normal"
        );
    }
    (pts.len(), ties)
}

/// Closest points and distances on the two levels equal the merged mesh's and brute force's,
/// on every structure, at 10 and 100 instances, before and after moves; the moves and the
/// point queries after them build no mesh structure.
#[test]
fn two_levels_answer_points_as_merged_and_brute_force() {
    for kind in kinds() {
        for n in [10, 100] {
            let mut scene = instanced(cpu(kind), n, 7 + n as u64);
            let (compared, ties) = check_points(&scene, kind, &format!("{n} instances"));
            assert!(ties * 100 <= compared, "{}: {ties} ties of {compared}", kind.name());
            let builds = scene.structure_builds();
            assert_eq!(builds, 3, "{}: one structure a mesh", kind.name());
            let mut rng = Rng::new(n as u64);
            let ids: Vec<u32> = scene.ids().collect();
            for step in 0..2 {
                let moved: Vec<Mat4> = ids.iter().map(|_| similarity(&mut rng, 6.0)).collect();
                scene.set_transforms(&ids, &moved).unwrap();
                let pts = [[0.5, -0.25, 1.0], [3.0, 2.0, -4.0]];
                scene.compute_distance(&pts).unwrap();
                scene.compute_closest_points(&pts).unwrap();
                assert_eq!(scene.structure_builds(), builds, "{}: step {step} built", kind.name());
                let (compared, ties) = check_points(&scene, kind, &format!("{n} instances, step {step}"));
                assert!(ties * 100 <= compared, "{}: {ties} ties of {compared}", kind.name());
            }
        }
    }
}
