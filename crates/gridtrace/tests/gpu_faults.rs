//! Device faults that cannot be made on demand (a lost device, memory gone), injected through
//! the paths real ones take (`GpuContext::inject_fault`): with `auto` the tracer hands the work
//! to the CPU for good and says so, the frame is still made and equals the CPU's; with `gpu`
//! the fault is an error that names it; the query meshes (`TraceMesh`) follow the same rule.
//! A scene over the device's limits is
//! `backend_sends_a_scene_the_device_cannot_hold_to_the_cpu` in gpu.rs.
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
