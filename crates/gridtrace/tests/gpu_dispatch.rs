//! The 2-D dispatch path (more than `MAX_GROUPS_X` workgroups in one dispatch: a frame's queue
//! past 2M rays, a grid build past 2M cells) gives the same results as the 1-D one. Reaching it
//! for real takes frames too large for a software adapter, so this file lowers the threshold
//! (`set_max_groups_x`) for its own process: every dispatch of a small frame, a ray batch and a
//! grid build goes 2-D, and is compared with the same work dispatched 1-D. Its own test binary,
//! so no other test compiles kernels while the threshold is lowered.
//!
//! Fails, not skips, without an adapter (lavapipe in CI); GRIDTRACE_SKIP_GPU=1 skips knowingly.

use gridtrace::AccelParams;
use std::sync::Arc;

use gridtrace::accel::Resolution;
use gridtrace::gpu::constants::{MAX_GROUPS_X, max_groups_x, set_max_groups_x};
use gridtrace::gpu::{GpuContext, GpuGrid, GpuRenderer};
use gridtrace::scene::builtin;
use gridtrace::testing::{ray_set, skip_gpu};
use gridtrace::{Mode, RenderOptions};

#[test]
fn two_d_dispatches_equal_one_d() {
    if skip_gpu() {
        return;
    }
    assert_eq!(max_groups_x(), MAX_GROUPS_X);
    let one_d = Arc::new(GpuContext::new().expect("a GPU adapter (lavapipe in CI)"));
    // Three workgroups in x: a 64x48 frame (48 groups) runs as 3 x 16, its queues and the grid
    // build's passes likewise.
    set_max_groups_x(3);
    let two_d = Arc::new(GpuContext::new().unwrap());
    let scene = builtin::scene("knot-box").unwrap();
    let grid = scene.prepare(Resolution::default()).unwrap();
    let rays = ray_set(&grid.accel, 5000, 3);
    for accel in gridtrace::testing::gpu_kinds(&one_d) {
        let prepared = scene.prepare_for(accel, &AccelParams::NONE).unwrap();
        let mut a = GpuRenderer::new(one_d.clone(), &prepared, &gridtrace::gpu::GpuVariants::default()).unwrap();
        let mut b = GpuRenderer::new(two_d.clone(), &prepared, &gridtrace::gpu::GpuVariants::default()).unwrap();
        for mode in [Mode::Cast, Mode::Shadow, Mode::Trace, Mode::Heat] {
            let opts = RenderOptions::new(64, 48, mode);
            let (ia, sa) = a.render(&prepared.camera, &prepared.lights, &opts).unwrap();
            let (ib, sb) = b.render(&prepared.camera, &prepared.lights, &opts).unwrap();
            assert!(
                ia.pixels() == ib.pixels(),
                "{} {mode:?}: 2-D dispatch changed the image",
                accel.name()
            );
            assert_eq!(sa.render.rays, sb.render.rays, "{} {mode:?}", accel.name());
        }
        let ha = a.intersect(&rays).unwrap();
        let hb = b.intersect(&rays).unwrap();
        assert!(ha == hb, "{}: 2-D dispatch changed the hits", accel.name());
        let oa = a.occluded(&rays).unwrap();
        let ob = b.occluded(&rays).unwrap();
        assert_eq!(oa, ob, "{}: 2-D dispatch changed occlusion", accel.name());
    }
    let tris = grid.accel.tris;
    let (ga, _) = GpuGrid::build_from(one_d, &tris, Resolution::default()).unwrap();
    let (gb, _) = GpuGrid::build_from(two_d, &tris, Resolution::default()).unwrap();
    let (ca, ra) = ga.read_back().unwrap();
    let (cb, rb) = gb.read_back().unwrap();
    assert_eq!(ra, rb, "2-D dispatch changed the grid's references");
    assert!(
        ca.iter()
            .zip(&cb)
            .all(|(x, y)| (x.start, x.count, x.dist) == (y.start, y.count, y.dist)),
        "2-D dispatch changed the grid's cells"
    );
    set_max_groups_x(MAX_GROUPS_X);
}
