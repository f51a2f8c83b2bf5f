//! Every GPU variant (`gpu::variants`) against the default kernels on the same adapter
//! (lavapipe in CI): the same images and the same hits, for every structure the variant
//! applies to. A variant is a speed choice only; these tests are what allows the hardware run
//! to pick any of them. No timing here (lavapipe runs the shaders on the CPU).
//!
//! Exact where the variant keeps the walk's visiting order (ray order, appends, statistics,
//! checks, the short stacks): every pixel bit for bit, every hit's t, triangle and
//! barycentrics, every ray count. The 8-wide BVH visits children in octant order, so where two
//! triangles are hit at the same t (a ray through a shared edge) it may keep the other one:
//! same hit or miss and t for every ray but one in 10,000, a different triangle only at such
//! ties, and at most 0.1% of pixels more than 2 levels apart.
//!
//! Fails, not skips, without an adapter; GRIDTRACE_SKIP_GPU=1 skips knowingly.

use gridtrace::AccelParams;
use gridtrace::accel::StructureId;
use std::sync::{Arc, Mutex};

use gridtrace::accel::{Accel, AccelKind, Hit, Resolution};
use gridtrace::gpu::variants::{Appends, BvhLayout, GpuVariants};
use gridtrace::gpu::{GpuContext, GpuRenderer};
use gridtrace::render::Ablation;
use gridtrace::scene::{PreparedScene, builtin};
use gridtrace::testing::{differing_pixels, on_triangle_boundary, ray_set, skip_gpu};
use gridtrace::{Image, Mode, RenderOptions};

static GPU_LOCK: Mutex<()> = Mutex::new(());

fn context() -> Arc<GpuContext> {
    Arc::new(
        GpuContext::new().unwrap_or_else(|e| panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}")),
    )
}

fn v(s: &str) -> GpuVariants {
    s.parse().unwrap()
}

/// The variants checked: the hardware suite's, the short stacks at one and two entries (so
/// that nearly every walk overflows and climbs), the wide BVH with each stack, and every
/// change at once. Subgroup appends only where the adapter has subgroup operations (elsewhere
/// `subgroup_appends_need_the_adapters_subgroups` checks they are refused).
fn variants(ctx: &GpuContext) -> Vec<GpuVariants> {
    let mut all = GpuVariants::suite()[1..].to_vec();
    for s in [
        "stack=short1",
        "stack=short2",
        "bvh=wide8,stack=short",
        "bvh=wide8,stack=short1",
        "bvh=wide8,stack=short,order=tiles,appends=workgroup,stats=off,checks=off",
    ] {
        all.push(v(s));
    }
    if !ctx.subgroups {
        eprintln!(
            "{}: no subgroup operations, appends=subgroup not compared",
            ctx.info.name
        );
        all.retain(|v| v.appends != Appends::Subgroup);
    }
    all
}

/// `appends=subgroup` on an adapter without subgroup operations is an error naming the variant,
/// the adapter and the alternative, not a failed shader compile; where the adapter has them the
/// variant is among those compared with the default above.
#[test]
fn subgroup_appends_need_the_adapters_subgroups() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let ctx = context();
    assert!(variants(&ctx).iter().any(|v| v.appends == Appends::Subgroup) == ctx.subgroups);
    if ctx.subgroups {
        return;
    }
    let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let e = GpuRenderer::new(ctx.clone(), &scene, &v("appends=subgroup"))
        .err()
        .expect("refused");
    let e = e.to_string();
    assert!(
        e.contains("appends=subgroup") && e.contains(&ctx.info.name) && e.contains("appends=workgroup"),
        "{e}"
    );
}

/// Whether `v`'s results may differ from the default's at ties (the wide BVH's visiting order).
fn tie_order_differs(v: &GpuVariants, structure: StructureId) -> bool {
    structure == StructureId::Bvh && v.bvh == BvhLayout::Wide8
}

/// The scene prepared for every structure the GPU has (the grid serves `grid` and `pc`).
fn per_structure(ctx: &GpuContext, scene: &PreparedScene) -> Vec<(AccelKind, PreparedScene)> {
    gridtrace::testing::gpu_kinds(ctx)
        .into_iter()
        .filter(|k| *k != AccelKind::ProximityCloud)
        .map(|k| (k, scene.with_accel(k, &AccelParams::NONE).unwrap()))
        .collect()
}

fn render(gpu: &mut GpuRenderer, scene: &PreparedScene, opts: &RenderOptions) -> (Image, [u64; 3]) {
    let (img, s) = gpu.render(&scene.camera, &scene.lights, opts).unwrap();
    let r = s.render.rays;
    (img, [r.eye, r.shadow, r.reflection])
}

fn compare_images(what: &str, exact: bool, want: &(Image, [u64; 3]), got: &(Image, [u64; 3])) {
    if exact {
        assert!(want.0.pixels() == got.0.pixels(), "{what}: pixels differ");
        assert_eq!(want.1, got.1, "{what}: ray counts");
    } else {
        let frac = differing_pixels(&want.0.to_rgb8(), &got.0.to_rgb8(), 2);
        assert!(frac <= 0.001, "{what}: {:.3}% of pixels differ", frac * 100.0);
        for (a, b) in want.1.iter().zip(&got.1) {
            assert!(
                a.abs_diff(*b) * 1000 <= (*a).max(1),
                "{what}: ray counts {:?} vs {:?}",
                want.1,
                got.1
            );
        }
    }
}

/// Images (every mode; heat only where the walk's work is the default's) and ray counts of the
/// built-in scenes, for every variant and every structure it applies to, with and without
/// queue compaction.
#[test]
fn variants_render_the_default_images() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let ctx = context();
    for name in ["knot-box", "mirror-spheres"] {
        let scene = builtin::scene(name).unwrap().prepare(Resolution::default()).unwrap();
        for (kind, scene) in per_structure(&ctx, &scene) {
            let structure = kind.structure();
            if structure == StructureId::Brute && name != "knot-box" {
                // Brute force on the spheres' triangles takes minutes on lavapipe; the knot
                // box checks its kernels with every variant.
                continue;
            }
            let mut base = GpuRenderer::new(ctx.clone(), &scene, &GpuVariants::default()).unwrap();
            let mut checked = 0;
            for var in variants(&ctx).into_iter().filter(|v| v.applies_to(structure)) {
                let mut gpu = GpuRenderer::new(ctx.clone(), &scene, &var).unwrap();
                assert_eq!(gpu.variants(), var);
                let walk_changed = structure == StructureId::Bvh
                    && (var.bvh != GpuVariants::default().bvh || var.stack != GpuVariants::default().stack);
                for mode in Mode::ALL.into_iter().filter(|m| *m != Mode::Heat || !walk_changed) {
                    // Without compaction the queues keep slots by invocation (ray order, the
                    // appends and the statistics change that path); the walks never see it.
                    for no_compaction in [false, true].into_iter().filter(|&nc| !nc || !walk_changed) {
                        let mut opts = RenderOptions::new(157, 83, mode);
                        opts.ablation = Ablation {
                            no_compaction,
                            ..Ablation::default()
                        };
                        let what = format!(
                            "{name} {structure} {} {} compaction={}",
                            mode.name(),
                            var.changes(),
                            !no_compaction
                        );
                        let want = render(&mut base, &scene, &opts);
                        let got = render(&mut gpu, &scene, &opts);
                        compare_images(&what, !tie_order_differs(&var, structure), &want, &got);
                        checked += 1;
                    }
                }
            }
            eprintln!("{name} {structure}: {checked} images equal to the default's");
            assert!(checked > 0);
        }
    }
}

/// Tiles order where a tile starts mid-row: a frame over `MAX_TILE_PIXELS` is two tiles, the
/// second starting inside a row, with a band under 8 rows and a frame width that is not a
/// multiple of 8 (1100 x 960: the second tile is the last 824 pixels of row 953 and 6 rows).
#[test]
fn tiles_order_across_tile_boundaries() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let ctx = context();
    let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let mut base = GpuRenderer::new(ctx.clone(), &scene, &GpuVariants::default()).unwrap();
    let mut tiles = GpuRenderer::new(ctx.clone(), &scene, &v("order=tiles,appends=workgroup")).unwrap();
    let opts = RenderOptions::new(1100, 960, Mode::Cast);
    const { assert!(1100 * 960 > gridtrace::gpu::MAX_TILE_PIXELS && !gridtrace::gpu::MAX_TILE_PIXELS.is_multiple_of(1100)) };
    let want = render(&mut base, &scene, &opts);
    let got = render(&mut tiles, &scene, &opts);
    compare_images("knot-box 1100x960 tiles", true, &want, &got);
}

/// Closest and any hits of adversarial rays (`testing::ray_set`) for every variant that changes
/// a walk: the BVH's layouts and stacks, and the unchecked modules for every structure.
#[test]
fn variants_give_the_default_hits() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let ctx = context();
    let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let grid = Accel::build(scene.accel.tris.clone(), AccelKind::Grid, &AccelParams::NONE).unwrap();
    let rays = ray_set(&grid, 40_000, 0x5EED);
    for (kind, scene) in per_structure(&ctx, &scene) {
        let structure = kind.structure();
        let mut base = GpuRenderer::new(ctx.clone(), &scene, &GpuVariants::default()).unwrap();
        let want = base.intersect(&rays).unwrap();
        let want_any = base.occluded(&rays).unwrap();
        let hits = want.iter().filter(|h| h.is_hit()).count();
        assert!(hits > rays.len() / 10, "{structure}: the rays must hit");
        for var in variants(&ctx).into_iter().filter(|v| v.applies_to(structure)) {
            let mut gpu = GpuRenderer::new(ctx.clone(), &scene, &var).unwrap();
            let got = gpu.intersect(&rays).unwrap();
            let got_any = gpu.occluded(&rays).unwrap();
            let what = format!("{structure} {}", var.changes());
            assert_eq!(got_any, want_any, "{what}: any hit");
            if !tie_order_differs(&var, structure) {
                let same =
                    |a: &Hit, b: &Hit| a.t.to_bits() == b.t.to_bits() && a.tri == b.tri && a.u == b.u && a.v == b.v;
                let bad = want.iter().zip(&got).filter(|(a, b)| !same(a, b)).count();
                assert_eq!(bad, 0, "{what}: {bad} hits differ");
                continue;
            }
            // Ties: a different triangle only where both are hit at the same t, by the CPU's
            // test, or by the GPU's on both triangles' boundaries (a shared edge: the GPU's f32
            // edge function accepts both sides where the CPU's f64 one picks one,
            // `testing::gpu_disagreements`).
            let mut bad = 0;
            for ((r, a), b) in rays.iter().zip(&want).zip(&got) {
                let tie = a.is_hit()
                    && b.is_hit()
                    && (scene.accel.tris[a.tri as usize]
                        .intersect(r.origin, r.dir, 0.0, f32::INFINITY)
                        .zip(scene.accel.tris[b.tri as usize].intersect(r.origin, r.dir, 0.0, f32::INFINITY))
                        .is_some_and(|(x, y)| x.t == y.t)
                        || ((a.t - b.t).abs() <= 1e-6 * a.t.abs().max(1e-6)
                            && on_triangle_boundary(a)
                            && on_triangle_boundary(b)));
                if a.is_hit() != b.is_hit() || (a.tri != b.tri && !tie) || (a.tri == b.tri && a.t != b.t) {
                    bad += 1;
                }
            }
            eprintln!("{what}: {bad} of {} hits differ", rays.len());
            assert!(bad <= rays.len() / 10_000, "{what}: {bad} hits differ");
        }
    }
}
