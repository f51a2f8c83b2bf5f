//! `hwrt` (rays traced by the GPU's ray-tracing hardware through ray queries) where the shared
//! tests do not reach it: the shared GPU tests (tests/gpu.rs, edges.rs, gpu_closest.rs,
//! gpu_variants.rs, gpu_dispatch.rs, animation.rs, query_scene.rs) run it against the CPU's
//! BVH and brute force wherever the adapter has ray queries (`testing::gpu_runs`; under CI=1
//! they must). Here: it is refused on the CPU and on an adapter without ray queries with an
//! error that names what is missing, `auto` never picks it on a software adapter, the adapter
//! line says whether ray queries are there, and its hits name the triangles and barycentrics
//! every walk names.

use gridtrace::AccelParams;
use std::sync::Arc;

use gridtrace::accel::{AccelChoice, AccelKind, Hit, NoCounters, Resolution, TracedOn, Work};
use gridtrace::gpu::{GpuContext, GpuRenderer};
use gridtrace::query::{QueryOptions, TraceMesh};
use gridtrace::scene::builtin;
use gridtrace::testing::{gpu_runs, ray_set, skip_gpu};
use gridtrace::{Backend, Placement, Tracer};

fn hwrt_scene() -> gridtrace::PreparedScene {
    builtin::knot_box()
        .prepare_for(AccelKind::Hwrt, &AccelParams::NONE)
        .unwrap()
}

/// On the CPU, `hwrt` is an error naming it and the GPU, for frames and for ray batches; the
/// queries that are not ray queries (closest points) answer by its BVH.
#[test]
fn hwrt_on_the_cpu_is_an_error() {
    let e = Tracer::open(hwrt_scene(), &Placement::cpu(), &mut Vec::new())
        .err()
        .expect("hwrt refused on the CPU")
        .to_string();
    assert!(
        e.contains("'hwrt'") && e.contains("GPU") && e.contains("ray queries"),
        "{e}"
    );
    let (v, f) = gridtrace::testing::soup_arrays(&gridtrace::testing::triangle_soup(40, 3));
    let opts = QueryOptions {
        accel: AccelKind::Hwrt.into(),
        backend: Backend::Cpu,
        ..Default::default()
    };
    let mesh = TraceMesh::from_arrays(&v, &f, &opts).unwrap();
    let (o, d) = ([[0.0f32, 0.0, -5.0]], [[0.0f32, 0.0, 1.0]]);
    let e = mesh
        .intersect(&o, &d, 0.0, f32::INFINITY)
        .expect_err("hwrt's rays refused on the CPU")
        .to_string();
    assert!(e.contains("'hwrt'"), "{e}");
    assert!(mesh.occluded(&o, &d, 0.0, f32::INFINITY).is_err());
    let p = mesh.closest_points(&[[0.1, 0.2, 0.3]]).unwrap();
    assert!(p[0].dist_sq.is_finite());
}

/// `auto` picks `hwrt` only on a hardware adapter with ray queries: never on the CPU, never on
/// a software adapter (lavapipe has ray queries from Mesa 25, and runs them on the CPU's
/// cores), whether the caller opened the device first (frames: `backend::traced_on`) or
/// chooses before it opens one (ray batches: `Backend::traced_on`, on the process's probe).
#[test]
fn auto_picks_hwrt_only_on_hardware_with_ray_queries() {
    for work in [Work::Render, Work::Animate, Work::Rays] {
        assert_ne!(AccelChoice::Auto.resolve(TracedOn::Cpu, work).0, AccelKind::Hwrt);
        assert_eq!(Backend::Cpu.traced_on(), TracedOn::Cpu);
        let (k, note) = AccelChoice::Auto.resolve(Backend::Gpu.traced_on(), work);
        assert_eq!(
            k == AccelKind::Hwrt,
            gridtrace::backend::hardware_ray_queries_present(),
            "{note:?}"
        );
    }
    if let Ok(mut c) = GpuContext::new() {
        // As an adapter with ray queries, whatever this one has: a software one still never
        // decides.
        c.ray_query = true;
        let on = gridtrace::backend::traced_on(Some(&c));
        assert_eq!(
            on,
            TracedOn::Gpu {
                hardware_ray_queries: !c.is_software()
            },
            "{}",
            c.describe()
        );
        c.ray_query = false;
        let on = gridtrace::backend::traced_on(Some(&c));
        assert_eq!(
            on,
            TracedOn::Gpu {
                hardware_ray_queries: false
            },
            "{}",
            c.describe()
        );
        if c.is_software() {
            assert!(!gridtrace::backend::hardware_ray_queries_present(), "{}", c.describe());
        }
    }
}

/// The adapter line says whether ray queries are there; an adapter without them (Mesa 22.3's
/// lavapipe, the H100) refuses `hwrt` with an error naming the adapter and the feature, under
/// `gpu` and under `auto` alike (never a fall back to a CPU that cannot trace it either).
#[test]
fn an_adapter_without_ray_queries_refuses_hwrt() {
    if skip_gpu() {
        return;
    }
    let mut ctx = GpuContext::new().expect("a GPU adapter (lavapipe in CI)");
    let line = ctx.describe();
    eprintln!("adapter: {line}");
    assert!(line.contains(ctx.ray_queries_words()), "{line}");
    // As an adapter without them.
    ctx.ray_query = false;
    let name = ctx.info.name.clone();
    let ctx = Arc::new(ctx);
    assert!(ctx.describe().contains("no ray queries"));
    let e = GpuRenderer::new(ctx.clone(), &hwrt_scene(), &gridtrace::gpu::GpuVariants::default())
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains(&name) && e.contains("ray queries") && e.contains("'hwrt'"),
        "{e}"
    );
    for backend in [Backend::Gpu, Backend::Auto] {
        let e = Tracer::open(
            hwrt_scene(),
            &Placement::on_device(backend, ctx.clone()),
            &mut Vec::new(),
        )
        .err()
        .unwrap_or_else(|| panic!("{backend:?}: hwrt without ray queries must be refused"))
        .to_string();
        assert!(e.contains(&name) && e.contains("ray queries"), "{backend:?}: {e}");
    }
}

/// Closest hits name the triangle (the tracer's order) and its barycentrics (the weights of v1
/// and v2) as the CPU's do: for rays through triangles' interiors, away from edges, the
/// triangle is the CPU's and u, v, t agree to rounding. (tests/gpu.rs compares whole ray sets
/// within the tolerance every structure meets.)
#[test]
fn hits_name_the_cpus_triangle_and_barycentrics() {
    if skip_gpu() {
        return;
    }
    let ctx = Arc::new(GpuContext::new().expect("a GPU adapter (lavapipe in CI)"));
    if !gpu_runs(&ctx, AccelKind::Hwrt) {
        return;
    }
    let scene = hwrt_scene();
    let mut gpu = GpuRenderer::new(ctx, &scene, &gridtrace::gpu::GpuVariants::default()).unwrap();
    // Rays are drawn from a grid's cells over the same triangles.
    let grid = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let rays = ray_set(&grid.accel, 20_000, 11);
    let got = gpu.intersect(&rays).unwrap();
    let mut interior = 0;
    for (r, g) in rays.iter().zip(&got) {
        let c: Hit = scene.accel.intersect(r, &mut NoCounters);
        if !c.is_hit() || c.u.min(c.v).min(1.0 - c.u - c.v) < 1e-3 {
            continue;
        }
        interior += 1;
        assert_eq!(g.tri, c.tri, "{r:?}: {g:?} vs {c:?}");
        let close = |a: f32, b: f32, tol: f32| (a - b).abs() <= tol;
        assert!(close(g.t, c.t, 1e-4 * c.t.abs().max(1.0)), "{r:?}: {g:?} vs {c:?}");
        assert!(close(g.u, c.u, 1e-3) && close(g.v, c.v, 1e-3), "{r:?}: {g:?} vs {c:?}");
    }
    assert!(interior > 2_000, "{interior} interior hits");
}
