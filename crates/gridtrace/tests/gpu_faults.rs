//! Device faults that cannot be made on demand (a lost device, memory gone), injected through
//! the paths real ones take (`GpuContext::inject_fault`): with `auto` the tracer hands the work
//! to the CPU for good and says so, the frame is still made and equals the CPU's; with `gpu`
//! the fault is an error that names it; the query meshes (`TraceMesh`) and scenes
//! (`QueryScene`: counts, lists, winding numbers, signed distance, on both GPU paths) follow
//! the same rule, and a scene's `last_query` says which device answered and carries the note.
//! A list over a device limit is no fault (`Error::Limit`): under `auto` the CPU answers that
//! query alone and the next goes to the GPU; under `gpu` the error names the limit. A scene
//! over the device's limits is `backend_sends_a_scene_the_device_cannot_hold_to_the_cpu` in
//! gpu.rs.
//!
//! Fails, not skips, without an adapter (lavapipe in CI); GRIDTRACE_SKIP_GPU=1 skips knowingly.

use std::sync::Arc;

use gridtrace::accel::Resolution;
use gridtrace::gpu::{Fault, GpuContext};
use gridtrace::scene::builtin;
use gridtrace::testing::skip_gpu;
use gridtrace::{Backend, Error, Mode, Placement, RenderOptions, Tracer};

fn ctx() -> Arc<GpuContext> {
    Arc::new(GpuContext::new().expect("a GPU adapter (lavapipe in CI)"))
}

#[test]
fn auto_hands_a_lost_device_to_the_cpu() {
    if skip_gpu() {
        return;
    }
    for fault in [Fault::DeviceLost, Fault::OutOfMemory] {
        let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
        let opts = RenderOptions::new(48, 32, Mode::Shadow);
        let (want, _) = gridtrace::cpu::render(&scene, &opts, None).unwrap();
        let ctx = ctx();
        let mut notes = Vec::new();
        // `open` with a device given: the software adapter is used as a GPU would be.
        let mut tracer = Tracer::open(
            scene.clone(),
            &Placement::on_device(Backend::Auto, ctx.clone()),
            &mut notes,
        )
        .unwrap();
        assert!(tracer.gpu().is_some());
        let (camera, lights) = (scene.camera, scene.lights.clone());
        assert!(tracer.render(&camera, &lights, &opts).unwrap().gpu.is_some());
        ctx.inject_fault(fault);
        let f = tracer.render(&camera, &lights, &opts).unwrap();
        assert!(f.gpu.is_none() && tracer.gpu().is_none(), "{fault:?}: still on the GPU");
        assert!(f.image.pixels() == want.pixels(), "{fault:?}: the CPU's frame differs");
        let notes = tracer.take_notes();
        assert!(
            notes.len() == 1 && notes[0].contains("the GPU failed") && notes[0].contains("CPU"),
            "{fault:?}: {notes:?}"
        );
        // For good: the next frame is the CPU's without another note.
        assert!(tracer.render(&camera, &lights, &opts).unwrap().gpu.is_none());
        assert!(tracer.take_notes().is_empty());
    }
}

#[test]
fn gpu_backend_reports_the_fault() {
    if skip_gpu() {
        return;
    }
    let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let opts = RenderOptions::new(48, 32, Mode::Cast);
    let ctx = ctx();
    let mut notes = Vec::new();
    let mut tracer = Tracer::open(
        scene.clone(),
        &Placement::on_device(Backend::Gpu, ctx.clone()),
        &mut notes,
    )
    .unwrap();
    ctx.inject_fault(Fault::DeviceLost);
    for _ in 0..2 {
        // A lost device stays lost: every later frame says so too.
        match tracer.render(&scene.camera, &scene.lights, &opts) {
            Err(Error::Gpu(m)) => assert!(m.contains("lost"), "{m}"),
            other => panic!("expected a device-lost error, got {:?}", other.map(|f| f.stats)),
        }
    }
    let ctx = self::ctx();
    let mut tracer = Tracer::open(
        scene.clone(),
        &Placement::on_device(Backend::Gpu, ctx.clone()),
        &mut notes,
    )
    .unwrap();
    ctx.inject_fault(Fault::OutOfMemory);
    match tracer.render(&scene.camera, &scene.lights, &opts) {
        Err(Error::Gpu(m)) => assert!(m.contains("Out of Memory"), "{m}"),
        other => panic!("expected an out-of-memory error, got {:?}", other.map(|f| f.stats)),
    }
    // Memory that ran out once is reported once: the next frame is made.
    assert!(tracer.render(&scene.camera, &scene.lights, &opts).is_ok());
}

/// Moving the mesh after the device was lost: with `auto` the CPU rebuilds the structure the
/// GPU was keeping and traces the moved mesh.
#[test]
fn auto_update_after_a_lost_device() {
    if skip_gpu() {
        return;
    }
    let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let ctx = ctx();
    let mut notes = Vec::new();
    let mut tracer = Tracer::open(
        scene.clone(),
        &Placement::on_device(Backend::Auto, ctx.clone()),
        &mut notes,
    )
    .unwrap();
    ctx.inject_fault(Fault::DeviceLost);
    // The vertices, from the triangles that use them, moved along x.
    let mut moved = vec![glam::Vec3::ZERO; scene.normals.len()];
    for (t, ids) in scene.accel.tris.iter().zip(&scene.tri_vertices) {
        for (p, &i) in t.vertices().iter().zip(ids) {
            moved[i as usize] = *p + glam::Vec3::new(0.1, 0.0, 0.0);
        }
    }
    let up = tracer.update_vertices(&moved).unwrap();
    assert!(up.how.contains("CPU"), "{}", up.how);
    assert!(tracer.gpu().is_none());
    let opts = RenderOptions::new(48, 32, Mode::Cast);
    let mut want = scene.clone();
    want.update_vertices(&moved, gridtrace::scene::RebuildOn::Cpu).unwrap();
    let (want, _) = gridtrace::cpu::render(&want, &opts, None).unwrap();
    let got = tracer.render(&scene.camera, &scene.lights, &opts).unwrap();
    assert!(got.image.pixels() == want.pixels());
    assert_eq!(tracer.take_notes().len(), 1);
}

/// The query meshes (`rays`, Python's `Mesh` and `Scene`) follow the tracer's rule: under
/// `auto` a GPU fault hands the mesh to the CPU for good, the query that met it is answered
/// there (the CPU's answers, exactly), and `gpu_failure` and `device` say so; under `gpu` the
/// fault is the caller's error.
#[test]
fn query_meshes_hand_a_failed_gpu_to_the_cpu_under_auto() {
    use gridtrace::query::{QueryOptions, TraceMesh};
    if skip_gpu() {
        return;
    }
    let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let (vertices, faces) = gridtrace::testing::soup_arrays(&scene.accel.tris);
    let rays = gridtrace::testing::ray_set(&scene.accel, 3000, 7);
    let (origins, dirs): (Vec<[f32; 3]>, Vec<[f32; 3]>) =
        rays.iter().map(|r| (r.origin.to_array(), r.dir.to_array())).unzip();
    let points: Vec<[f32; 3]> = origins.iter().take(500).copied().collect();
    for fault in [Fault::DeviceLost, Fault::OutOfMemory] {
        let opts = QueryOptions {
            accel: "bvh".parse().unwrap(),
            backend: Backend::Auto,
            ..QueryOptions::default()
        };
        let mesh = TraceMesh::from_arrays(&vertices, &faces, &opts).unwrap();
        let want = mesh
            .intersect_with(Backend::Cpu, &origins, &dirs, 0.0, f32::INFINITY)
            .unwrap();
        let want_occ = mesh.occluded_with(Backend::Cpu, &origins, &dirs, 0.0, 1.0).unwrap();
        let want_points = mesh.closest_points_with(Backend::Cpu, &points).unwrap();
        let ctx = ctx();
        mesh.adopt_device_for_auto(ctx.clone()).unwrap();
        assert!(mesh.device().starts_with("gpu"), "{}", mesh.device());
        mesh.intersect(&origins, &dirs, 0.0, f32::INFINITY).unwrap();
        assert!(
            mesh.last_gpu_batch().is_some(),
            "{fault:?}: the first batch ran on the GPU"
        );
        ctx.inject_fault(fault);
        let got = mesh.intersect(&origins, &dirs, 0.0, f32::INFINITY).unwrap();
        assert!(
            got.t == want.t && got.tri == want.tri,
            "{fault:?}: the CPU's answers differ"
        );
        let why = mesh.gpu_failure().unwrap_or_else(|| panic!("{fault:?}: no note"));
        assert!(why.contains("the GPU failed") && why.contains("CPU"), "{why}");
        assert!(mesh.device().starts_with("cpu") && mesh.device().contains("the GPU failed"));
        // For good, and for every query.
        assert_eq!(mesh.occluded(&origins, &dirs, 0.0, 1.0).unwrap(), want_occ);
        let got_points = mesh.closest_points(&points).unwrap();
        assert!(
            got_points
                .iter()
                .zip(&want_points)
                .all(|(a, b)| a.tri == b.tri && a.dist_sq == b.dist_sq)
        );
    }
    // Under `gpu` the fault is the caller's, and the mesh stays on the GPU.
    let opts = QueryOptions {
        accel: "bvh".parse().unwrap(),
        ..QueryOptions::default()
    };
    let mesh = TraceMesh::from_arrays(&vertices, &faces, &opts).unwrap();
    let ctx = ctx();
    mesh.adopt_device_for_auto(ctx.clone()).unwrap();
    ctx.inject_fault(Fault::DeviceLost);
    match mesh.intersect_with(Backend::Gpu, &origins, &dirs, 0.0, f32::INFINITY) {
        Err(Error::Gpu(m)) => assert!(m.contains("lost"), "{m}"),
        other => panic!("expected a device-lost error, got {:?}", other.map(|h| h.t.len())),
    }
    assert!(mesh.gpu_failure().is_none());
}

/// The scene queries that run on the GPU besides closest hits: counts and lists of every hit,
/// winding numbers, signed distance.
#[derive(Debug, Clone, Copy, PartialEq)]
enum SceneQuery {
    Count,
    List,
    Winding,
    SignedDistance,
}

/// A query's answer, compared exactly: a CPU that takes over gives the CPU's answers bit for
/// bit (the same walk, the same tree as a CPU scene's).
#[derive(Debug, PartialEq)]
enum SceneAnswer {
    Counts(Vec<u32>),
    Lists(gridtrace::query_scene::Intersections),
    /// f32 bits, so that NaN (a point that is not finite) compares equal to itself.
    Values(Vec<u32>),
}

impl SceneQuery {
    const ALL: [SceneQuery; 4] = [
        SceneQuery::Count,
        SceneQuery::List,
        SceneQuery::Winding,
        SceneQuery::SignedDistance,
    ];

    /// The name `last_query` gives it.
    fn name(self) -> &'static str {
        match self {
            SceneQuery::Count => "count_intersections",
            SceneQuery::List => "list_intersections",
            SceneQuery::Winding => "compute_winding_number",
            SceneQuery::SignedDistance => "compute_signed_distance",
        }
    }

    fn run(self, s: &gridtrace::QueryScene, rays: &[[f32; 6]], points: &[[f32; 3]]) -> gridtrace::Result<SceneAnswer> {
        let bits = |v: Vec<f32>| SceneAnswer::Values(v.iter().map(|x| x.to_bits()).collect());
        Ok(match self {
            SceneQuery::Count => SceneAnswer::Counts(s.count_intersections(rays)?),
            SceneQuery::List => SceneAnswer::Lists(s.list_intersections(rays)?),
            SceneQuery::Winding => bits(s.winding_numbers(points)?),
            SceneQuery::SignedDistance => bits(s.compute_signed_distance(points)?),
        })
    }
}

/// A soup (many hits a ray) and a closed box around part of it (points inside: winding number
/// 1), static: with the BVH and with the irregular grid the rays walk the GPU's two levels
/// (their bottom walks differ: binary nodes, grid cells); the point queries run on the merged
/// mesh's renderer either way.
fn fault_scene(backend: gridtrace::query::Backend, accel: &str) -> gridtrace::QueryScene {
    use gridtrace::testing::{cuboid, soup_arrays, triangle_soup};
    let mut s = gridtrace::QueryScene::new(gridtrace::query::QueryOptions {
        backend,
        accel: accel.parse().unwrap(),
        ..Default::default()
    });
    let (v, f) = soup_arrays(&triangle_soup(300, 5));
    s.add_triangles(v, f, None).unwrap();
    let (v, f) = cuboid(glam::Vec3::splat(-0.5), glam::Vec3::new(1.0, 0.8, 0.6));
    s.add_triangles(v, f, None).unwrap();
    s
}

/// Rays from around the scene in every direction, and points in and around the box (one not
/// finite).
fn fault_rays_and_points() -> (Vec<[f32; 6]>, Vec<[f32; 3]>) {
    let mut rng = gridtrace::util::Rng::new(41);
    let mut next = || rng.range(-1.0, 1.0);
    let rays = (0..600)
        .map(|_| [next() * 2.0, next() * 2.0, next() * 2.0, next(), next(), next()])
        .collect();
    let mut points: Vec<[f32; 3]> = (0..400).map(|_| [next() * 1.5, next() * 1.5, next() * 1.5]).collect();
    points.push([f32::NAN, 0.0, 0.0]);
    (rays, points)
}

/// `QueryScene` under `auto` on a device given (lavapipe, as a hardware adapter): a fault
/// (a lost device, memory gone) met by a count, a list, winding numbers or a signed distance,
/// on either GPU path, hands the scene to the CPU for good. The query that met it gives the
/// CPU scene's answer exactly, its `last_query` says "cpu" with no GPU batch and a note that
/// the GPU failed and the CPU took over (`gpu_failure` keeps it); the next query is the CPU's
/// too, without a new note. A fault met before the scene's first GPU work (the device lost
/// before the renderer is made) is handed over the same way.
#[test]
fn scene_queries_hand_a_failed_gpu_to_the_cpu_under_auto() {
    use gridtrace::query::Backend;
    if skip_gpu() {
        return;
    }
    let (rays, points) = fault_rays_and_points();
    for accel in ["bvh", "irregular"] {
        let cpu = fault_scene(Backend::Cpu, accel);
        // The merged mesh built first: its tree answers the winding numbers, as on the GPU
        // scene (whose first query builds it), not the faces' own tree.
        cpu.compute_distance(&points[..1]).unwrap();
        for query in SceneQuery::ALL {
            // The point queries run on the merged mesh whatever the structure: once is enough.
            if accel == "irregular" && matches!(query, SceneQuery::Winding | SceneQuery::SignedDistance) {
                continue;
            }
            let want = query.run(&cpu, &rays, &points).unwrap();
            if let SceneAnswer::Counts(c) = &want {
                assert!(c.iter().filter(|&&c| c >= 2).count() > 50, "rays with several hits");
            }
            for (fault, first_on_gpu) in [
                (Fault::DeviceLost, true),
                (Fault::OutOfMemory, true),
                (Fault::DeviceLost, false),
            ] {
                let what = format!("{accel} {query:?} {fault:?} (after a GPU query: {first_on_gpu})");
                let mut s = fault_scene(Backend::Auto, accel);
                let ctx = ctx();
                s.adopt_device(ctx.clone());
                if first_on_gpu {
                    query.run(&s, &rays, &points).unwrap();
                    let last = s.last_query();
                    assert_eq!((last.name, last.device), (query.name(), "gpu"), "{what}");
                    assert!(last.gpu.is_some_and(|g| g.uploaded_bytes > 0), "{what}");
                }
                ctx.inject_fault(fault);
                let got = query.run(&s, &rays, &points).unwrap();
                assert!(got == want, "{what}: the CPU's answers differ");
                let last = s.last_query();
                assert_eq!((last.name, last.device), (query.name(), "cpu"), "{what}");
                assert!(last.gpu.is_none(), "{what}");
                let note = last.note.unwrap_or_else(|| panic!("{what}: no note"));
                assert!(
                    note.contains("the GPU failed") && note.contains("CPU from now on"),
                    "{what}: {note}"
                );
                let why = s.gpu_failure().unwrap_or_else(|| panic!("{what}: no gpu_failure"));
                assert!(note.contains(&why), "{what}: {note} / {why}");
                assert!(s.device().unwrap().starts_with("cpu"), "{what}");
                // For good, without a new note: this query again, and every other.
                for q in SceneQuery::ALL {
                    let again = q.run(&s, &rays, &points).unwrap();
                    if q == query {
                        assert!(again == want, "{what}: again");
                    }
                    let last = s.last_query();
                    assert_eq!((last.name, last.device), (q.name(), "cpu"), "{what}: then {q:?}");
                    assert!(last.note.is_none() && last.gpu.is_none(), "{what}: then {q:?}");
                }
            }
        }
    }
}

/// Under `gpu` the same faults are the caller's: each query's error names the fault (a lost
/// device stays lost; memory that ran out is reported once, and the next query runs on the
/// GPU), and the scene does not leave the GPU.
#[test]
fn scene_queries_report_the_fault_under_gpu() {
    use gridtrace::query::Backend;
    if skip_gpu() {
        return;
    }
    let (rays, points) = fault_rays_and_points();
    for accel in ["bvh", "irregular"] {
        for query in SceneQuery::ALL {
            if accel == "irregular" && matches!(query, SceneQuery::Winding | SceneQuery::SignedDistance) {
                continue;
            }
            for (fault, words) in [(Fault::DeviceLost, "lost"), (Fault::OutOfMemory, "Out of Memory")] {
                let what = format!("{accel} {query:?} {fault:?}");
                let mut s = fault_scene(Backend::Gpu, accel);
                let ctx = ctx();
                s.adopt_device(ctx.clone());
                query.run(&s, &rays, &points).unwrap();
                assert_eq!(s.last_query().device, "gpu", "{what}");
                ctx.inject_fault(fault);
                match query.run(&s, &rays, &points) {
                    Err(Error::Gpu(m)) => assert!(m.contains(words), "{what}: {m}"),
                    other => panic!("{what}: expected the fault, got {:?}", other.map(|_| ())),
                }
                assert!(s.gpu_failure().is_none(), "{what}");
                let next = query.run(&s, &rays, &points);
                match fault {
                    Fault::DeviceLost => assert!(matches!(next, Err(Error::Gpu(_))), "{what}: still lost"),
                    Fault::OutOfMemory => {
                        next.unwrap_or_else(|e| panic!("{what}: the next query: {e}"));
                        assert_eq!(s.last_query().device, "gpu", "{what}: the next query");
                    }
                }
            }
        }
    }
}

/// Each ray's hits of `rays` on the CPU scene of `accel` (how the limit tests pick a limit one
/// ray's list meets and a batch that stays under it).
fn cpu_counts(accel: &str, rays: &[[f32; 6]]) -> Vec<u32> {
    fault_scene(gridtrace::query::Backend::Cpu, accel)
        .count_intersections(rays)
        .unwrap()
}

/// A list longer than one pass holds (`GpuContext::lower_list_hits`, as a device with smaller
/// bindings would) is a limit, not a fault: under `auto` the CPU answers that query alone
/// (the CPU scene's lists exactly; `last_query` "cpu" with a note naming the limit), the
/// scene keeps its GPU (`gpu_failure` none), the next query that fits runs on the GPU, and a
/// long list again is answered on the CPU again with the note. With both structures' walks.
#[test]
fn scene_lists_over_a_limit_are_answered_on_the_cpu_for_that_query_under_auto() {
    use gridtrace::gpu::LIST_PASS_LIMIT;
    use gridtrace::query::Backend;
    if skip_gpu() {
        return;
    }
    let (rays, _) = fault_rays_and_points();
    for accel in ["bvh", "irregular"] {
        let counts = cpu_counts(accel, &rays);
        let most = *counts.iter().max().unwrap();
        // The rays whose lists fit a pass of `most - 1` hits.
        let short: Vec<[f32; 6]> = rays
            .iter()
            .zip(&counts)
            .filter(|&(_, &c)| c < most)
            .map(|(r, _)| *r)
            .collect();
        let cpu = fault_scene(Backend::Cpu, accel);
        let (want, want_short) = (
            cpu.list_intersections(&rays).unwrap(),
            cpu.list_intersections(&short).unwrap(),
        );
        let mut s = fault_scene(Backend::Auto, accel);
        let ctx = ctx();
        s.adopt_device(ctx.clone());
        ctx.lower_list_hits(most - 1);
        for round in 0..2 {
            let what = format!("{accel}, round {round}");
            let got = s.list_intersections(&rays).unwrap();
            assert!(got == want, "{what}: the CPU's answers differ");
            let last = s.last_query();
            assert_eq!((last.name, last.device), ("list_intersections", "cpu"), "{what}");
            assert!(last.gpu.is_none(), "{what}");
            let note = last.note.unwrap_or_else(|| panic!("{what}: no note"));
            assert!(
                note.contains(LIST_PASS_LIMIT) && note.contains(&format!("{most} asked, {} allowed", most - 1)),
                "{what}: {note}"
            );
            assert!(note.contains("the next query goes to the GPU again"), "{what}: {note}");
            assert!(s.gpu_failure().is_none(), "{what}: the scene failed over");
            // The next query that fits is the GPU's, without a note.
            let got_short = s.list_intersections(&short).unwrap();
            let last = s.last_query();
            assert_eq!(last.device, "gpu", "{what}: the short list");
            assert!(last.note.is_none() && last.gpu.is_some(), "{what}: the short list");
            assert_eq!(got_short.ray_splits, want_short.ray_splits, "{what}: the short list");
            assert_eq!(
                got_short.primitive_ids, want_short.primitive_ids,
                "{what}: the short list"
            );
            // Counts meet no list pass: every ray's, on the GPU.
            assert_eq!(s.count_intersections(&rays).unwrap(), counts, "{what}");
            assert_eq!(s.last_query().device, "gpu", "{what}: the counts");
        }
    }
}

/// Under `gpu` the same limit is the caller's error (`Error::Limit`, naming the limit, the
/// hits asked and the hits a pass allows), and the next query that fits runs on the GPU.
#[test]
fn scene_lists_over_a_limit_report_the_limit_under_gpu() {
    use gridtrace::gpu::LIST_PASS_LIMIT;
    use gridtrace::query::Backend;
    if skip_gpu() {
        return;
    }
    let (rays, _) = fault_rays_and_points();
    for accel in ["bvh", "irregular"] {
        let counts = cpu_counts(accel, &rays);
        let most = *counts.iter().max().unwrap();
        let mut s = fault_scene(Backend::Gpu, accel);
        let ctx = ctx();
        s.adopt_device(ctx.clone());
        ctx.lower_list_hits(most - 1);
        match s.list_intersections(&rays) {
            Err(e @ Error::Limit { .. }) => {
                let m = e.to_string();
                let Error::Limit {
                    limit, asked, allowed, ..
                } = e
                else {
                    unreachable!()
                };
                assert_eq!(
                    (limit, asked, allowed),
                    (LIST_PASS_LIMIT, u64::from(most), u64::from(most - 1))
                );
                assert!(m.contains(LIST_PASS_LIMIT) && m.contains("list pass"), "{accel}: {m}");
            }
            other => panic!("{accel}: expected the limit, got {:?}", other.map(|_| ())),
        }
        assert!(s.gpu_failure().is_none(), "{accel}");
        s.count_intersections(&rays).unwrap();
        assert_eq!(s.last_query().device, "gpu", "{accel}: the next query");
    }
}
