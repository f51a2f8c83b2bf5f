//! Moving meshes: frames of the built-in animated scene, with the structure updated in place
//! (grids rebuilt on the CPU or on the GPU, the BVH refitted, the irregular grid rebuilt), equal
//! fresh renders of a scene prepared from scratch at the same vertex positions. Bad updates
//! (wrong length, NaN) are errors that leave the previous mesh in place.
//!
//! CPU updates must give the very same image as a fresh build (same triangles, same grid, same
//! normals). The refitted BVH and the GPU differ from a fresh CPU render only at ties and
//! exact edges: at most 0.5% of pixels may differ by more than 2 levels, as in tests/gpu.rs.
//!
//! The GPU half fails, not skips, without an adapter (lavapipe in CI); GRIDTRACE_SKIP_GPU=1
//! skips it knowingly.

use gridtrace::AccelParams;
use std::sync::Arc;

use glam::Vec3;
use gridtrace::accel::AccelKind;
use gridtrace::gpu::{GpuContext, GpuRenderer};
use gridtrace::scene::animated::Animation;
use gridtrace::scene::{PreparedScene, RebuildOn, Scene};
use gridtrace::testing::{differing_pixels, skip_gpu};
use gridtrace::{Mode, RenderOptions};

/// Times that deform the knot and squash a sphere (the helper's tests show both happen).
const TIMES: [f32; 3] = [0.35, 1.7, 4.2];

fn opts() -> RenderOptions {
    RenderOptions::new(96, 72, Mode::Shadow)
}

/// The scene prepared from scratch with the animation's vertices at `time`.
fn fresh(anim: &Animation, time: f32, accel: AccelKind) -> PreparedScene {
    let mut scene: Scene = anim.scene.clone();
    scene.mesh.positions = anim.positions_at(time);
    // Area-weighted normals of the moved mesh, as an update computes them.
    scene.mesh.normals.clear();
    scene.prepare_for(accel, &AccelParams::NONE).unwrap()
}

fn cpu_image(scene: &PreparedScene) -> Vec<u8> {
    gridtrace::cpu::render(scene, &opts(), None).unwrap().0.to_rgb8()
}

#[test]
fn cpu_updates_equal_fresh_builds() {
    let anim = Animation::by_name("animated").unwrap();
    for accel in [AccelKind::ProximityCloud, AccelKind::Bvh, AccelKind::Irregular] {
        let mut scene = anim.scene.prepare_for(accel, &AccelParams::NONE).unwrap();
        for &t in &TIMES {
            let up = scene.update_vertices(&anim.positions_at(t), RebuildOn::Cpu).unwrap();
            let want = fresh(&anim, t, accel);
            let got = cpu_image(&scene);
            let expect = cpu_image(&want);
            if accel == AccelKind::Bvh {
                assert_eq!(up.how, "refitted");
                let d = differing_pixels(&got, &expect, 2);
                assert!(d <= 0.005, "bvh refit at t={t}: {:.3}% of pixels differ", d * 100.0);
            } else {
                assert_eq!(up.how, "rebuilt");
                assert_eq!(
                    got,
                    expect,
                    "{} at t={t}: update differs from a fresh build",
                    accel.name()
                );
            }
        }
    }
}

#[test]
fn bad_updates_leave_the_mesh_in_place() {
    let anim = Animation::by_name("bouncing-spheres").unwrap();
    let mut scene = anim.scene.prepare_for(AccelKind::Grid, &AccelParams::NONE).unwrap();
    scene.update_vertices(&anim.positions_at(0.5), RebuildOn::Cpu).unwrap();
    let before = cpu_image(&scene);
    let tris = scene.accel.tris.clone();
    let mut p = anim.positions_at(1.0);
    p.pop();
    let e = scene.update_vertices(&p, RebuildOn::Cpu).unwrap_err().to_string();
    assert!(e.contains("vertices"), "{e}");
    let mut p = anim.positions_at(1.0);
    p[17].y = f32::NAN;
    let e = scene.update_vertices(&p, RebuildOn::Cpu).unwrap_err().to_string();
    assert!(e.contains("vertex 17") && e.contains("NaN"), "{e}");
    assert_eq!(scene.accel.tris, tris);
    assert_eq!(cpu_image(&scene), before);
}

/// A grid left to the GPU is not traced stale on the CPU: that is an error, not a wrong image.
#[test]
fn stale_cpu_grid_is_refused() {
    let anim = Animation::by_name("bouncing-spheres").unwrap();
    let mut scene = anim.scene.prepare_for(AccelKind::Grid, &AccelParams::NONE).unwrap();
    scene
        .update_vertices(&anim.positions_at(0.5), RebuildOn::Device)
        .unwrap();
    let e = gridtrace::cpu::render(&scene, &opts(), None).unwrap_err().to_string();
    assert!(e.contains("GPU"), "{e}");
    scene.update_vertices(&anim.positions_at(0.5), RebuildOn::Cpu).unwrap();
    assert_eq!(cpu_image(&scene), cpu_image(&fresh(&anim, 0.5, AccelKind::Grid)));
}

/// GPU frames: the grid rebuilt on the device every frame (and the BVH refitted and uploaded)
/// against fresh CPU renders.
#[test]
fn gpu_frames_equal_fresh_cpu_renders() {
    if skip_gpu() {
        return;
    }
    let ctx = Arc::new(GpuContext::new().expect("a GPU adapter (lavapipe in CI)"));
    let anim = Animation::by_name("animated").unwrap();
    // `hwrt` (where the adapter has ray queries: always in CI) rebuilds its acceleration
    // structures on the device at every update; its reference is the CPU's BVH.
    let hwrt = gridtrace::testing::gpu_runs(&ctx, AccelKind::Hwrt).then_some(AccelKind::Hwrt);
    for accel in [AccelKind::ProximityCloud, AccelKind::Grid, AccelKind::Bvh]
        .into_iter()
        .chain(hwrt)
    {
        let mut scene = anim.scene.prepare_for(accel, &AccelParams::NONE).unwrap();
        let mut gpu = GpuRenderer::new(ctx.clone(), &scene, &gridtrace::gpu::GpuVariants::default()).unwrap();
        for &t in &TIMES {
            scene.update_vertices(&anim.positions_at(t), RebuildOn::Device).unwrap();
            let up = gpu.update_vertices(&scene).unwrap();
            if accel.uses_grid() {
                let b = up.build.expect("the grid is built on the GPU");
                assert!(b.cpu_fallback.is_none(), "{:?}", b.cpu_fallback);
            }
            let (image, _) = gpu.render(&scene.camera, &scene.lights, &opts()).unwrap();
            let on_cpu = if accel.entry().cpu { accel } else { AccelKind::Bvh };
            let expect = cpu_image(&fresh(&anim, t, on_cpu));
            let d = differing_pixels(&image.to_rgb8(), &expect, 2);
            assert!(
                d <= 0.005,
                "{} at t={t}: {:.3}% of pixels differ",
                accel.name(),
                d * 100.0
            );
        }
    }
    // A vertex array of the wrong length never reaches the GPU: the scene refuses it.
    let mut scene = anim.scene.prepare_for(AccelKind::Grid, &AccelParams::NONE).unwrap();
    assert!(scene.update_vertices(&[Vec3::ZERO; 3], RebuildOn::Device).is_err());
    assert!(!scene.accel.structure_stale);
}
