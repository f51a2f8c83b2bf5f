//! Counts and lists of every hit on the GPU (lavapipe in CI; `gpu::AllHits`): the same answers
//! as the CPU's (`count_intersections`, `list_intersections`: Open3D's rule, nearest first,
//! equal `t` by geometry then face) on every structure the GPU traces, on both GPU paths (the
//! merged mesh's renderer; the two levels, with instances that move and per-ray intervals and
//! masks), with bad rays, ties at shared diagonals and ties of different geometries at one `t`;
//! a list split over several passes equals one pass; a ray with more hits than a pass holds is
//! refused with `Error::Limit`, naming the limit (what the scenes do with it: gpu_faults.rs).

use std::sync::{Arc, Mutex};

use glam::{Mat4, Quat, Vec3};
use gridtrace::QueryScene;
use gridtrace::accel::{AccelKind, Resolution};
use gridtrace::gpu::{AllHits, GpuContext, GpuRenderer, GpuVariants, LIST_PASS_LIMIT, RaySlice};
use gridtrace::query::{Backend, QueryOptions};
use gridtrace::query_scene::{InstanceOf, Intersections, PerRay, RayOptions};
use gridtrace::scene::builtin;
use gridtrace::testing::{cuboid, gpu_kinds, open3d_cube, ray_set, skip_gpu, soup_arrays, triangle_soup};
use gridtrace::util::Rng;

// One test at a time on the device: lavapipe uses every core for each dispatch anyway.
static GPU_LOCK: Mutex<()> = Mutex::new(());

/// Two soups (many hits a ray, slivers), a box, and Open3D's cube twice at one place (ties of
/// different geometries at one `t`, and within each the shared diagonals'); with `instanced`
/// the first soup is placed twice more as instances (the scene then walks two levels where
/// the GPU carries the structure), one of them masked to bit 2 only.
fn scene(backend: Backend, accel: AccelKind, instanced: bool) -> QueryScene {
    let mut s = QueryScene::new(QueryOptions {
        backend,
        accel: accel.into(),
        ..Default::default()
    });
    let (v, f) = soup_arrays(&triangle_soup(600, 3));
    let soup = s.add_triangles(v, f, None).unwrap();
    let (v, f) = soup_arrays(&triangle_soup(400, 8));
    s.add_triangles(v, f, Some(Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0))))
        .unwrap();
    let (v, f) = cuboid(Vec3::new(-2.0, -2.0, -2.0), Vec3::new(2.5, 2.0, 2.0));
    s.add_triangles(v, f, None).unwrap();
    for _ in 0..2 {
        let (v, f) = open3d_cube();
        s.add_triangles(v, f, None).unwrap();
    }
    if instanced {
        let turned = Mat4::from_scale_rotation_translation(
            Vec3::splat(0.6),
            Quat::from_euler(glam::EulerRot::ZYX, 0.5, 0.2, -0.3),
            Vec3::new(-0.4, 0.3, 0.2),
        );
        s.add_instance(InstanceOf::Geometry(soup), Some(turned), u32::MAX)
            .unwrap();
        s.add_instance(
            InstanceOf::Geometry(soup),
            Some(Mat4::from_translation(Vec3::Y * 0.3)),
            0b100,
        )
        .unwrap();
    }
    s
}

/// Rays from inside and around the scene in every direction, Open3D's diagonal rays through
/// the cubes (ties), a miss, and bad rows (NaN, a zero direction) that count nothing.
fn rays() -> Vec<[f32; 6]> {
    let mut rng = Rng::new(0x2545_f491_4f6c_dd1d);
    let mut next = || rng.range(-1.0, 1.0);
    let mut out: Vec<[f32; 6]> = (0..1500)
        .map(|_| {
            let o = [next() * 2.5, next() * 2.5, next() * 2.5];
            [o[0], o[1], o[2], next(), next(), next()]
        })
        .collect();
    out.extend([
        [0.5, 0.5, -1.0, 0.0, 0.0, 1.0],
        [0.5, 0.5, 0.5, 0.0, 0.0, 1.0],
        [0.25, 0.75, -3.0, 0.0, 0.0, 1.0],
        [10.0, 10.0, 10.0, 1.0, 0.0, 0.0],
        [f32::NAN, 0.0, 0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    ]);
    out
}

fn context() -> Option<GpuContext> {
    if skip_gpu() {
        return None;
    }
    Some(GpuContext::new().unwrap_or_else(|e| panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}")))
}

/// The same lists: splits, rays, geometries and faces exactly, t within 1e-5 relative (the
/// GPU's triangle test may round a last bit its own way), u and v within 1e-4.
fn assert_same_lists(want: &Intersections, got: &Intersections, what: &str) {
    assert_eq!(want.ray_splits, got.ray_splits, "{what}: splits");
    assert_eq!(want.ray_ids, got.ray_ids, "{what}: ray ids");
    assert_eq!(want.geometry_ids, got.geometry_ids, "{what}: geometry ids");
    assert_eq!(want.primitive_ids, got.primitive_ids, "{what}: faces");
    for (k, (a, b)) in want.t_hit.iter().zip(&got.t_hit).enumerate() {
        assert!(
            (a - b).abs() <= 1e-5 * a.abs().max(1.0),
            "{what}: hit {k}: t {a} and {b}"
        );
    }
    for (a, b) in want.primitive_uvs.iter().zip(&got.primitive_uvs) {
        assert!(
            (a[0] - b[0]).abs() <= 1e-4 && (a[1] - b[1]).abs() <= 1e-4,
            "{what}: uv {a:?} {b:?}"
        );
    }
}

#[test]
fn counts_and_lists_equal_the_cpu_on_every_structure_and_path() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let Some(ctx) = context() else { return };
    let rays = rays();
    let n = rays.len();
    // Per-ray intervals and masks: every third ray starts at 0.5 and ends at 3, every other
    // sees bit 2 only (the masked instance, and no geometry added by `add_triangles`, whose
    // mask is every bit: so those rays see everything, the masked instance included).
    let t_near: Vec<f32> = (0..n).map(|i| if i % 3 == 0 { 0.5 } else { 0.0 }).collect();
    let t_far: Vec<f32> = (0..n).map(|i| if i % 3 == 0 { 3.0 } else { f32::INFINITY }).collect();
    let mask: Vec<u32> = (0..n).map(|i| if i % 2 == 0 { 0b100 } else { 0b1 }).collect();
    let per_ray = RayOptions {
        t_near: PerRay::Each(&t_near),
        t_far: PerRay::Each(&t_far),
        mask: PerRay::Each(&mask),
    };
    for kind in gpu_kinds(&ctx) {
        for instanced in [false, true] {
            let what = format!("{} ({})", kind.name(), if instanced { "instances" } else { "merged" });
            let cpu = scene(Backend::Cpu, kind, instanced);
            let gpu = scene(Backend::Gpu, kind, instanced);
            let want = cpu.count_intersections(&rays).unwrap();
            let got = gpu.count_intersections(&rays).unwrap();
            let last = gpu.last_query();
            assert_eq!((last.name, last.device), ("count_intersections", "gpu"), "{what}");
            let stats = last.gpu.expect("the GPU's statistics");
            assert_eq!(stats.rays, n as u64, "{what}");
            // A count a ray down, and the timestamps.
            assert!(stats.downloaded_bytes >= 4 * n as u64, "{what}");
            let differ = want.iter().zip(&got).filter(|(a, b)| a != b).count();
            assert_eq!(differ, 0, "{what}: {differ} of {n} counts differ");
            // Many rays hit several faces.
            let many = want.iter().filter(|&&c| c >= 3).count();
            assert!(many > n / 20, "{what}: {many} rays of {n} hit three faces or more");
            assert_eq!(&got[n - 3..], &[0, 0, 0], "{what}: a miss and two bad rows");
            let lists = gpu.list_intersections(&rays).unwrap();
            // The two cubes at one place: hits of different geometries at one t, both listed.
            let ties = (1..lists.t_hit.len())
                .filter(|&k| {
                    lists.ray_ids[k] == lists.ray_ids[k - 1]
                        && lists.t_hit[k] == lists.t_hit[k - 1]
                        && lists.geometry_ids[k] != lists.geometry_ids[k - 1]
                })
                .count();
            assert!(ties >= 4, "{what}: {ties} ties of two geometries");
            assert_same_lists(&cpu.list_intersections(&rays).unwrap(), &lists, &what);
            if instanced {
                let want = cpu.count_intersections_with(&rays, &per_ray).unwrap();
                assert_eq!(
                    want,
                    gpu.count_intersections_with(&rays, &per_ray).unwrap(),
                    "{what}: per ray"
                );
                assert_same_lists(
                    &cpu.list_intersections_with(&rays, &per_ray).unwrap(),
                    &gpu.list_intersections_with(&rays, &per_ray).unwrap(),
                    &format!("{what}: per ray"),
                );
            }
        }
    }
}

/// The instances moved: the GPU's counts follow (the top level uploaded alone).
#[test]
fn counts_follow_a_move() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    if context().is_none() {
        return;
    }
    let rays = rays();
    let kind = AccelKind::Bvh;
    let mut cpu = scene(Backend::Cpu, kind, true);
    let mut gpu = scene(Backend::Gpu, kind, true);
    assert_eq!(
        cpu.count_intersections(&rays).unwrap(),
        gpu.count_intersections(&rays).unwrap()
    );
    let moved = Mat4::from_rotation_translation(Quat::from_rotation_x(1.0), Vec3::new(0.3, -0.2, 0.1));
    cpu.set_transform(5, moved).unwrap();
    gpu.set_transform(5, moved).unwrap();
    let builds = gpu.structure_builds();
    let want = cpu.count_intersections(&rays).unwrap();
    assert_eq!(want, gpu.count_intersections(&rays).unwrap());
    assert_eq!(gpu.structure_builds(), builds, "a move builds no mesh structure");
}

/// The renderer's lists: cut into chunks and into passes of as few hits as the longest list,
/// they equal one
/// chunk in one pass bit for bit, with one round trip for each chunk's counts and one for each
/// pass; a ray with more hits than a pass holds is refused with `Error::Limit`, naming the limit.
#[test]
fn lists_split_over_passes_equal_one_pass() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let Some(ctx) = context() else { return };
    let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let ctx = Arc::new(ctx);
    let mut whole = GpuRenderer::new(ctx.clone(), &scene, &GpuVariants::default()).unwrap();
    let mut split = GpuRenderer::new(ctx, &scene, &GpuVariants::default()).unwrap();
    split.set_max_tile_pixels(300);
    let rays = ray_set(&scene.accel, 1000, 5);
    let source = RaySlice::new(&rays);
    let run = |r: &mut GpuRenderer, answer| {
        let mut counts = Vec::new();
        let mut hits = Vec::new();
        r.all_hits(&source, (0.0, f32::INFINITY), u32::MAX, &[0], answer, |first, c, h| {
            assert_eq!(first, counts.len());
            counts.extend_from_slice(c);
            hits.extend(h.iter().map(|h| (h.t.to_bits(), h.tri, h.u.to_bits(), h.v.to_bits())));
        })
        .map(|()| (counts, hits))
    };
    let (want_counts, want_hits) = run(&mut whole, AllHits::Lists).unwrap();
    assert_eq!(whole.last_query_stats().round_trips, 2);
    assert_eq!(want_hits.len() as u32, want_counts.iter().sum::<u32>());
    assert!(want_counts.iter().any(|&c| c >= 2) && want_counts.contains(&0));
    let (counts, _) = run(&mut whole, AllHits::Counts).unwrap();
    assert_eq!(counts, want_counts);
    let most = *want_counts.iter().max().unwrap();
    split.set_max_list_hits(most - 1);
    // A size, not a fault (`Error::Limit`): the ray, its hits, what a pass holds, the limit.
    match run(&mut split, AllHits::Lists) {
        Err(e @ gridtrace::Error::Limit { .. }) => {
            let m = e.to_string();
            let ray = want_counts.iter().position(|&c| c == most).unwrap();
            let words = format!("ray {ray}'s hits in one list pass: {most} asked, {} allowed", most - 1);
            assert!(m.contains(&words) && m.contains(LIST_PASS_LIMIT), "{m}");
        }
        other => panic!("expected the list pass's limit, got {:?}", other.map(|_| ())),
    }
    split.set_max_list_hits(most);
    let (counts, hits) = run(&mut split, AllHits::Lists).unwrap();
    assert_eq!((counts, hits), (want_counts, want_hits.clone()));
    let s = split.last_query_stats();
    assert_eq!(s.chunks, 4, "1000 rays in chunks of 300");
    assert!(s.round_trips > 4 + 4, "{s:?}: the passes of at most {most} hits");
}
