//! Winding numbers on the GPU (lavapipe in CI; `GpuRenderer::winding_numbers`): the CPU's fast
//! winding tree uploaded once and walked the same way gives the CPU's winding numbers within
//! f32 rounding of the same terms (1e-4), at every accuracy, on closed meshes and an open soup,
//! for the trees of two structures (the BVH's own tree, and the one built for a grid); the
//! signs of signed distance and occupancy equal the CPU's away from the surface; the tree goes
//! up once (12 bytes a point up and 4 down after that); a move uploads the rebuilt tree;
//! `accuracy = inf` stays the CPU's exact sum.

use std::sync::Mutex;

use glam::{Mat4, Quat, Vec3};
use gridtrace::QueryScene;
use gridtrace::accel::AccelKind;
use gridtrace::query::{Backend, QueryOptions};
use gridtrace::query_scene::InstanceOf;
use gridtrace::testing::{open3d_cube, skip_gpu, soup_arrays, triangle_soup};
use gridtrace::util::Rng;

static GPU_LOCK: Mutex<()> = Mutex::new(());

/// A closed box, a closed turned box inside another's reach (overlap: winding 2 there), and an
/// open soup (no inside: smooth values between).
fn scene(backend: Backend, accel: AccelKind) -> (QueryScene, u32) {
    let mut s = QueryScene::new(QueryOptions {
        backend,
        accel: accel.into(),
        ..Default::default()
    });
    let (v, f) = open3d_cube();
    let to_centre = Mat4::from_scale_rotation_translation(Vec3::splat(2.0), Quat::IDENTITY, Vec3::splat(-1.0));
    let boxed = s.add_triangles(v, f, Some(to_centre)).unwrap();
    // The instance places the unit cube (the mesh's own vertices), 1.6 a side, turned.
    let turned = Mat4::from_scale_rotation_translation(
        Vec3::splat(1.6),
        Quat::from_euler(glam::EulerRot::ZYX, 0.4, 0.3, 0.2),
        Vec3::new(0.2, -0.4, -0.6),
    );
    let moved = s
        .add_instance(InstanceOf::Geometry(boxed), Some(turned), u32::MAX)
        .unwrap();
    let (v, f) = soup_arrays(&triangle_soup(800, 21));
    s.add_triangles(v, f, Some(Mat4::from_translation(Vec3::new(-0.5, 2.5, 0.0))))
        .unwrap();
    (s, moved)
}

/// `s` as a static scene on the CPU: each geometry's world-space vertices and faces as a
/// geometry of its own, untransformed, in id order. Its point queries run on its merged mesh,
/// the very mesh (the same floats) the GPU scene merges, so its winding numbers come from the
/// tree the GPU walks. The moving scene's own CPU answers would not: with every instance a
/// similarity it sums each instance's own tree (`query_scene/two_level_points.rs`), the same
/// within the accuracy's bound, not the same bits.
fn merged_on_cpu(s: &QueryScene, accel: AccelKind) -> QueryScene {
    let mut flat = QueryScene::new(QueryOptions {
        backend: Backend::Cpu,
        accel: accel.into(),
        ..Default::default()
    });
    for id in s.ids() {
        let g = s.geometry(id).unwrap();
        flat.add_triangles(g.world_vertices(), g.faces().to_vec(), None)
            .unwrap();
    }
    flat
}

fn points(n: usize) -> Vec<[f32; 3]> {
    let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
    let mut next = || rng.range(-1.0, 1.0);
    let mut out: Vec<[f32; 3]> = (0..n)
        .map(|_| [next() * 2.5, next() * 2.5 + 1.0, next() * 2.5])
        .collect();
    out.push([f32::NAN, 0.0, 0.0]);
    out.push([100.0, 50.0, -30.0]);
    out
}

fn gpu_present() -> bool {
    if skip_gpu() {
        return false;
    }
    gridtrace::gpu::GpuContext::new()
        .unwrap_or_else(|e| panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}"));
    true
}

/// The largest difference, NaN where both are NaN counted 0 (a NaN against a number fails).
fn worst(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| match (x.is_nan(), y.is_nan()) {
            (true, true) => 0.0,
            (false, false) => (x - y).abs(),
            _ => f32::INFINITY,
        })
        .fold(0.0, f32::max)
}

#[test]
fn gpu_winding_numbers_equal_the_cpu_tree() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    if !gpu_present() {
        return;
    }
    let pts = points(3000);
    for kind in [AccelKind::Bvh, AccelKind::Grid] {
        let cpu = merged_on_cpu(&scene(Backend::Cpu, kind).0, kind);
        let (gpu, _) = scene(Backend::Gpu, kind);
        // The CPU's merged mesh built (a distance needs it), so that its winding numbers come
        // from the tree the GPU walks (a fresh CPU scene answers from its faces' own tree:
        // winding_only.rs, the same within the accuracy's bound, not the same bits).
        cpu.compute_distance(&[[0.0, 0.0, -9.0]]).unwrap();
        for accuracy in [1.0, 2.0, 8.0] {
            let want = cpu.winding_numbers_at(&pts, accuracy).unwrap();
            let got = gpu.winding_numbers_at(&pts, accuracy).unwrap();
            let w = worst(&want, &got);
            assert!(w <= 1e-4, "{} accuracy {accuracy}: apart by {w}", kind.name());
            // Inside both boxes, inside one, outside, and the soup's fractions all occur.
            let most = want.iter().copied().filter(|x| x.is_finite()).fold(0.0, f32::max);
            assert!(
                want.iter().any(|&x| (x - 2.0).abs() < 0.01),
                "{}: most {most}",
                kind.name()
            );
            assert!(want.iter().any(|&x| (x - 1.0).abs() < 0.01));
            assert!(want.iter().any(|&x| x.abs() < 0.01));
            assert!(want.iter().any(|&x| x > 0.05 && x < 0.95));
        }
        let last = gpu.last_query();
        assert_eq!((last.name, last.device), ("compute_winding_number", "gpu"));
        let stats = last.gpu.expect("the GPU's statistics");
        // The tree went up with the first batch; this one sent the points, 12 bytes each, and
        // the chunk's constants, and brought 4 bytes a point down (and the timestamps).
        let n = pts.len() as u64;
        assert!(
            stats.uploaded_bytes >= 12 * n && stats.uploaded_bytes < 12 * n + 4096,
            "{stats:?}"
        );
        assert!(
            stats.downloaded_bytes >= 4 * n && stats.downloaded_bytes < 4 * n + 4096,
            "{stats:?}"
        );
        // Signs and occupancy as the CPU's, away from the surface (where the winding number
        // is not within rounding of one half).
        let w = cpu.winding_numbers(&pts).unwrap();
        let away: Vec<bool> = w.iter().map(|x| (x - 0.5).abs() > 1e-3).collect();
        let (sa, sb) = (
            cpu.compute_signed_distance(&pts).unwrap(),
            gpu.compute_signed_distance(&pts).unwrap(),
        );
        let (oa, ob) = (
            cpu.compute_occupancy(&pts).unwrap(),
            gpu.compute_occupancy(&pts).unwrap(),
        );
        for i in (0..pts.len()).filter(|&i| away[i]) {
            assert_eq!(
                sa[i].is_sign_negative(),
                sb[i].is_sign_negative(),
                "point {i}: {} {}",
                sa[i],
                sb[i]
            );
            assert_eq!(oa[i], ob[i], "point {i}");
        }
        assert!(ob[pts.len() - 2].is_nan() && sb[pts.len() - 2].is_nan());
        assert_eq!(gpu.last_query().name, "compute_occupancy");
        assert_eq!(gpu.last_query().device, "gpu");
        assert_eq!(cpu.last_query().device, "cpu");
        // The exact sum is the CPU's whatever the backend.
        let exact = gpu.winding_numbers_at(&pts[..200], f64::INFINITY).unwrap();
        assert_eq!(gpu.last_query().device, "cpu");
        assert_eq!(
            worst(&exact, &cpu.winding_numbers_at(&pts[..200], f64::INFINITY).unwrap()),
            0.0
        );
    }
}

/// A move rebuilds the tree on the CPU and the GPU's batch uploads it: the answers follow.
#[test]
fn gpu_winding_numbers_follow_a_move() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    if !gpu_present() {
        return;
    }
    let pts = points(1000);
    let (mut moving, moved) = scene(Backend::Cpu, AccelKind::Bvh);
    let cpu = merged_on_cpu(&moving, AccelKind::Bvh);
    let (mut gpu, _) = scene(Backend::Gpu, AccelKind::Bvh);
    let point = [[0.0, 0.0, -9.0]];
    cpu.compute_distance(&point).unwrap();
    let first = gpu.winding_numbers(&pts).unwrap();
    assert!(worst(&first, &cpu.winding_numbers(&pts).unwrap()) <= 1e-4);
    let again = gpu.winding_numbers(&pts).unwrap();
    assert_eq!(worst(&first, &again), 0.0);
    let to = Mat4::from_rotation_translation(Quat::from_rotation_y(0.7), Vec3::new(-0.6, 0.4, 0.3));
    moving.set_transform(moved, to).unwrap();
    gpu.set_transform(moved, to).unwrap();
    let cpu = merged_on_cpu(&moving, AccelKind::Bvh);
    cpu.compute_distance(&point).unwrap();
    let want = cpu.winding_numbers(&pts).unwrap();
    let got = gpu.winding_numbers(&pts).unwrap();
    assert!(worst(&want, &got) <= 1e-4);
    assert!(worst(&first, &got) > 0.5, "the move changed the answers");
}

/// A winding tree deeper than the GPU walk's stack (`GpuContext::lower_wind_stack`, as a mesh
/// deeper than `WIND_STACK` would be) is a limit, not a fault. Under `auto` the CPU answers
/// that query alone (the merged mesh's winding numbers exactly; `last_query` "cpu", a note
/// naming the limit) and the scene keeps its GPU: the next distance query runs there. Under
/// `gpu` it is the caller's error, `Error::Limit` naming the stack, what the tree asks and
/// what the walk allows.
#[test]
fn winding_trees_over_the_walks_stack_are_a_limit() {
    use gridtrace::Error;
    use gridtrace::gpu::{GpuContext, WIND_STACK_LIMIT};
    if skip_gpu() {
        return;
    }
    let _gpu = GPU_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let points: Vec<[f32; 3]> = {
        let mut rng = Rng::new(77);
        (0..300)
            .map(|_| [rng.range(-1.5, 1.5), rng.range(-1.5, 3.5), rng.range(-1.5, 1.5)])
            .collect()
    };
    let ctx = std::sync::Arc::new(GpuContext::new().expect("a GPU adapter (lavapipe in CI)"));
    let (mut s, _) = scene(Backend::Auto, AccelKind::Bvh);
    // The merged mesh's tree over its BVH (built by a distance query first), which the GPU
    // walks and the query falls back to.
    let flat = merged_on_cpu(&s, AccelKind::Bvh);
    flat.compute_distance(&points).unwrap();
    let want = flat.winding_numbers(&points).unwrap();
    s.adopt_device(ctx.clone());
    ctx.lower_wind_stack(1);
    for round in 0..2 {
        let got = s.winding_numbers(&points).unwrap();
        let same = got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same, "round {round}: not the CPU scene's answers");
        let last = s.last_query();
        assert_eq!(
            (last.name, last.device),
            ("compute_winding_number", "cpu"),
            "round {round}"
        );
        let note = last.note.unwrap_or_else(|| panic!("round {round}: no note"));
        assert!(
            note.contains(WIND_STACK_LIMIT) && note.contains("1 allowed"),
            "round {round}: {note}"
        );
        assert!(s.gpu_failure().is_none(), "round {round}: the scene failed over");
        s.compute_distance(&points).unwrap();
        assert_eq!(s.last_query().device, "gpu", "round {round}: the next query");
    }
    let (mut s, _) = scene(Backend::Gpu, AccelKind::Bvh);
    s.adopt_device(ctx.clone());
    match s.winding_numbers(&points) {
        Err(Error::Limit {
            limit, asked, allowed, ..
        }) => {
            assert_eq!((limit, allowed), (WIND_STACK_LIMIT, 1));
            assert!(asked > 1, "the tree asks {asked}");
        }
        other => panic!("expected the limit, got {:?}", other.map(|_| ())),
    }
    assert!(s.gpu_failure().is_none());
}
