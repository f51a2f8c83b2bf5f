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

/// Winding numbers on the two levels (each instance's tree, summed; mirrors flipping the sign)
/// equal the merged scene's: exactly summed (`accuracy = inf`) within float rounding of the
/// sum and brute force's; at the default accuracy within the far-field terms' bound (points
/// off the faces by 1e-3 or more); signed distances with the merged sign away from the surface
/// (|w - 0.5| > 0.05) and the distance within 1e-5; occupancy the same there. No mesh
/// structure built for them.
#[test]
fn two_levels_winding_numbers_and_signs_as_merged() {
    use gridtrace::accel::winding::winding_number_brute;
    let scene = instanced(cpu(AccelKind::Bvh), 60, 3);
    let (flat, tris, _, _) = flat(&scene, cpu(AccelKind::Bvh));
    let mut pts = points(&tris, 2000, 4);
    // And the instances' centres and points about them (inside the spheres).
    let mut rng = Rng::new(1);
    for id in scene.ids() {
        let c = scene.geometry(id).unwrap().transform().w_axis.truncate();
        for _ in 0..4 {
            let d = Vec3::new(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2), rng.range(-0.2, 0.2));
            pts.push((c + d).to_array());
        }
    }
    let exact = scene.winding_numbers_at(&pts, f64::INFINITY).unwrap();
    let fast = scene.winding_numbers(&pts).unwrap();
    let (flat_exact, flat_fast) = (
        flat.winding_numbers_at(&pts, f64::INFINITY).unwrap(),
        flat.winding_numbers(&pts).unwrap(),
    );
    let sd = scene.compute_signed_distance(&pts).unwrap();
    let flat_sd = flat.compute_signed_distance(&pts).unwrap();
    let occ = scene.compute_occupancy(&pts).unwrap();
    let flat_occ = flat.compute_occupancy(&pts).unwrap();
    assert_eq!(scene.structure_builds(), 3, "one structure a mesh, no merged mesh");
    let (mut worst_exact, mut worst_fast, mut inside) = (0f32, 0f32, 0);
    for (i, p) in pts.iter().enumerate() {
        let what = format!("point {i} {p:?}");
        if !Vec3::from(*p).is_finite() {
            assert!(
                exact[i].is_nan() && fast[i].is_nan() && sd[i].is_nan() && occ[i].is_nan(),
                "{what}"
            );
            continue;
        }
        if flat_sd[i].abs() < 1e-3 {
            continue; // on a face: the winding number jumps there
        }
        if i % 10 == 0 {
            let brute = winding_number_brute(&tris, Vec3::from(*p));
            assert!(
                (exact[i] - brute).abs() <= 1e-4,
                "{what}: {} vs brute force {brute}",
                exact[i]
            );
        }
        worst_exact = worst_exact.max((exact[i] - flat_exact[i]).abs());
        worst_fast = worst_fast.max((fast[i] - flat_fast[i]).abs());
        if (flat_fast[i] - 0.5).abs() > 0.05 {
            inside += usize::from(flat_fast[i] > 0.5);
            assert_eq!(sd[i].is_sign_negative(), flat_sd[i].is_sign_negative(), "{what}: sign");
            assert!(
                close(sd[i].abs(), flat_sd[i].abs()),
                "{what}: {} vs {}",
                sd[i],
                flat_sd[i]
            );
            assert_eq!(occ[i], flat_occ[i], "{what}: occupancy");
        }
    }
    eprintln!("winding numbers apart from the merged scene's: exact {worst_exact}, fast {worst_fast}; {inside} inside");
    assert!(worst_exact <= 1e-4, "exact sums apart by {worst_exact}");
    assert!(worst_fast <= 0.02, "fast sums apart by {worst_fast}");
    assert!(inside > 40, "only {inside} points inside");
}

/// A scene with one instance under an uneven scale answers its point queries on the merged
/// mesh, bit for bit the flat scene's (the same world-space mesh), and builds that mesh after
/// each move; made all similarities again, it answers on the two levels.
#[test]
fn other_transforms_answer_on_the_merged_mesh() {
    let mut scene = instanced(cpu(AccelKind::Bvh), 30, 5);
    let ids: Vec<u32> = scene.ids().collect();
    let uneven = Mat4::from_scale(Vec3::new(1.0, 1.5, 0.8)) * scene.geometry(ids[4]).unwrap().transform();
    scene.set_transform(ids[4], uneven).unwrap();
    assert!(scene.geometry(ids[4]).unwrap().similarity().is_none());
    assert!(scene.geometry(ids[5]).unwrap().similarity().is_some());
    for step in 0..2 {
        let (flat, tris, _, _) = flat(&scene, cpu(AccelKind::Bvh));
        let pts = points(&tris, 800, 6);
        let before = scene.structure_builds();
        let (a, b) = (
            scene.compute_closest_points(&pts).unwrap(),
            flat.compute_closest_points(&pts).unwrap(),
        );
        assert_eq!(
            scene.structure_builds(),
            before + 1,
            "step {step}: the merged mesh built"
        );
        assert_eq!(format!("{:?}", a.points), format!("{:?}", b.points), "step {step}");
        let d = scene.compute_distance(&pts).unwrap();
        let e = flat.compute_distance(&pts).unwrap();
        assert!(d.iter().zip(&e).all(|(x, y)| x.to_bits() == y.to_bits()), "step {step}");
        let sd = scene.compute_signed_distance(&pts).unwrap();
        let flat_sd = flat.compute_signed_distance(&pts).unwrap();
        assert!(
            sd.iter().zip(&flat_sd).all(|(x, y)| x.to_bits() == y.to_bits()),
            "step {step}"
        );
        let moved = Mat4::from_translation(Vec3::X * 0.3) * scene.geometry(ids[4]).unwrap().transform();
        scene.set_transform(ids[4], moved).unwrap();
    }
    // Back to a similarity: the two levels answer, and a move builds nothing more.
    scene.set_transform(ids[4], Mat4::from_rotation_z(0.3)).unwrap();
    scene.compute_distance(&[[0.0; 3]]).unwrap();
    let builds = scene.structure_builds();
    scene.set_transform(ids[4], Mat4::from_rotation_z(0.6)).unwrap();
    let d = scene.compute_distance(&[[0.0, 0.0, 9.0]]).unwrap();
    assert_eq!(scene.structure_builds(), builds);
    let (flat, _, _, _) = flat(&scene, cpu(AccelKind::Bvh));
    assert!(close(d[0], flat.compute_distance(&[[0.0, 0.0, 9.0]]).unwrap()[0]));
}
