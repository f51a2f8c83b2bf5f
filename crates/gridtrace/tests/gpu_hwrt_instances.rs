//! `hwrt` over a `QueryScene`'s instances (the driver's: a BLAS a mesh, a TLAS instance a
//! scene instance, `gpu/walks/hwrt/instances.rs`) against the CPU's two levels over the same
//! instances (the BVH's: `hwrt`'s CPU reference), on an adapter with ray queries (lavapipe in
//! CI): random rotations, uneven scales, mirrors, masks and per-ray intervals and masks; masks
//! few enough for the driver's 8 bits (its opaque path) and too many (folded, each candidate
//! checked on its 32 bits). Then moves: no BLAS built again, the bytes written the TLAS's
//! instances (and the instance table where a mask changed), answers a fresh scene's.

use glam::{Mat4, Vec3};
use gridtrace::accel::{AccelKind, Ray};
use gridtrace::query::{Backend, QueryOptions};
use gridtrace::query_scene::{InstanceOf, PerRay, QueryScene, RayOptions};
use gridtrace::testing::{compare_hits, move_step, rebuilt, skip_gpu};
use gridtrace::util::Rng;

/// Instances placed, and the bytes of the instance table for them: 16 header words and two an
/// instance, in 64-byte records.
const INSTANCES: u32 = 100;
fn table_bytes(n: u64) -> u64 {
    (16 + 2 * n).div_ceil(16) * 64
}

/// `INSTANCES` instances of two meshes, each with `mask(rng)` (`testing::instanced_scene`).
fn instanced(opts: QueryOptions, seed: u64, mask: impl Fn(&mut Rng) -> u32) -> QueryScene {
    gridtrace::testing::instanced_scene(opts, seed, INSTANCES, mask)
}

/// `n` random rays towards the instances' region, each with its interval (a quarter from 0, a
/// fifth to infinity, a fifth empty).
fn rays_with_intervals(rng: &mut Rng, n: usize) -> (Vec<[f32; 6]>, Vec<f32>, Vec<f32>) {
    let rays: Vec<[f32; 6]> = (0..n)
        .map(|_| {
            let o = Vec3::new(rng.range(-14.0, 14.0), rng.range(-14.0, 14.0), rng.range(-14.0, 14.0));
            let target = Vec3::new(rng.range(-8.0, 8.0), rng.range(-8.0, 8.0), rng.range(-8.0, 8.0));
            let d = (target - o) * rng.range(0.05, 2.0);
            [o.x, o.y, o.z, d.x, d.y, d.z]
        })
        .collect();
    let t_near: Vec<f32> = (0..n)
        .map(|i| if i % 4 == 0 { 0.0 } else { rng.range(0.0, 0.5) })
        .collect();
    let t_far: Vec<f32> = (0..n)
        .map(|i| match i % 5 {
            0 => f32::INFINITY,
            1 => t_near[i] * 0.5,
            _ => t_near[i] + rng.range(0.0, 3.0),
        })
        .collect();
    (rays, t_near, t_far)
}

fn opts(accel: AccelKind, backend: Backend) -> QueryOptions {
    QueryOptions {
        accel: accel.into(),
        backend,
        ..Default::default()
    }
}

/// Whether this machine's adapter traces `hwrt` (`testing::gpu_runs`: under `CI=1` one without
/// ray queries fails).
fn hwrt_runs() -> bool {
    if skip_gpu() {
        return false;
    }
    let ctx = gridtrace::gpu::GpuContext::new().unwrap_or_else(|e| panic!("GPU tests need an adapter: {e}"));
    gridtrace::testing::gpu_runs(&ctx, AccelKind::Hwrt)
}

/// The driver's instances answer as the CPU's two levels: masks on the driver's opaque path
/// (four distinct, exact in its 8 bits) and on its folded one (two random bits of 32 each:
/// candidates checked on their 32 bits), rays with their own intervals and masks, and rays
/// sharing one.
#[test]
fn driver_instances_equal_cpu_two_levels() {
    if !hwrt_runs() {
        return;
    }
    let mut rng = Rng::new(33);
    let n = 1500;
    let (rays, t_near, t_far) = rays_with_intervals(&mut rng, n);
    let ray_list: Vec<Ray> = rays
        .iter()
        .map(|q| Ray::new(Vec3::new(q[0], q[1], q[2]), Vec3::new(q[3], q[4], q[5])))
        .collect();
    let few = |rng: &mut Rng| 1u32 << rng.below(4);
    let many = |rng: &mut Rng| (1u32 << rng.below(32)) | (1u32 << rng.below(32));
    for (name, masks, seed, least) in [
        ("few masks", &few as &dyn Fn(&mut Rng) -> u32, 3, 600),
        // Two bits of 32 see fewer instances: fewer hits to compare.
        ("many masks", &many, 4, 300),
    ] {
        let ray_masks: Vec<u32> = (0..n)
            .map(|i| match i % 4 {
                0 => u32::MAX,
                1 => masks(&mut rng),
                2 => masks(&mut rng) | masks(&mut rng),
                _ => 1 << rng.below(32),
            })
            .collect();
        let each = RayOptions {
            t_near: PerRay::Each(&t_near),
            t_far: PerRay::Each(&t_far),
            mask: PerRay::Each(&ray_masks),
        };
        let shared = RayOptions {
            mask: PerRay::All(2 | 4 | (1 << 20)),
            ..Default::default()
        };
        let on_cpu = instanced(opts(AccelKind::Bvh, Backend::Cpu), seed, masks);
        let on_gpu = instanced(opts(AccelKind::Hwrt, Backend::Gpu), seed, masks);
        let mut total = [0; 4];
        for (o, which) in [(&each, "each"), (&shared, "shared")] {
            let (c, g) = (
                on_cpu.cast_rays_with(&rays, o).unwrap(),
                on_gpu.cast_rays_with(&rays, o).unwrap(),
            );
            let occ = on_gpu.test_occlusions_with(&rays, o).unwrap();
            let counts = compare_hits(&format!("{name}, {which}"), &ray_list, &c, &g, &occ);
            for (t, k) in total.iter_mut().zip(counts) {
                *t += k;
            }
        }
        let [hits, rounding, boundary, excused] = total;
        eprintln!(
            "hwrt, {name}: {hits} hits compared, {rounding} t beyond 1e-5 within rounding, {boundary} other \
             faces on a boundary, {excused} hit-or-miss on a boundary"
        );
        assert!(hits > least, "{name}: only {hits} hits");
        assert!(
            rounding * 100 <= hits && boundary * 100 <= hits && excused * 100 <= 2 * n,
            "{name}: {rounding} rounding, {boundary} boundary, {excused} excused"
        );
        let up = on_gpu.gpu_uploads().expect("the driver's instances answered");
        assert_eq!(
            (up.blas_builds, up.top_records, up.top_nodes),
            (2, INSTANCES, 0),
            "{name}"
        );
    }
}

/// Moves: every instance moved and one masked out, twice, then an instance added. No BLAS is
/// built again and no mesh uploaded again; a move writes the TLAS's instances (64 bytes each)
/// and the instance table only where a mask changed; the answers are a fresh scene's.
#[test]
fn a_move_rebuilds_the_tlas_alone() {
    if !hwrt_runs() {
        return;
    }
    let mut rng = Rng::new(8);
    let n = 1000;
    let (rays, t_near, t_far) = rays_with_intervals(&mut rng, n);
    let ray_masks: Vec<u32> = (0..n).map(|i| [1, 2, 4 | 8, u32::MAX][i % 4]).collect();
    let each = RayOptions {
        t_near: PerRay::Each(&t_near),
        t_far: PerRay::Each(&t_far),
        mask: PerRay::Each(&ray_masks),
    };
    let gpu = opts(AccelKind::Hwrt, Backend::Gpu);
    let mut on_gpu = instanced(gpu.clone(), 5, |rng| 1 << rng.below(4));
    on_gpu.cast_rays_with(&rays, &each).unwrap();
    let first = on_gpu.gpu_uploads().expect("the driver's instances answered");
    assert_eq!((first.mesh_uploads, first.blas_builds, first.tlas_builds), (1, 2, 1));
    let builds = on_gpu.structure_builds();
    let ids: Vec<u32> = on_gpu.ids().collect();
    for step in 1..=2u32 {
        let before = on_gpu.gpu_uploads().unwrap();
        move_step(&mut on_gpu, &ids, step);
        let g = on_gpu.cast_rays_with(&rays, &each).unwrap();
        let occ = on_gpu.test_occlusions_with(&rays, &each).unwrap();
        let after = on_gpu.gpu_uploads().unwrap();
        assert_eq!(
            (after.mesh_uploads, after.blas_builds),
            (1, 2),
            "step {step}: a BLAS built again"
        );
        assert_eq!(after.tlas_builds, before.tlas_builds + 1, "step {step}");
        assert_eq!(after.mesh_bytes, before.mesh_bytes);
        assert_eq!(
            on_gpu.structure_builds(),
            builds,
            "step {step}: a move built a structure"
        );
        // The mask changes at the first step only.
        let table = if step == 1 { table_bytes(INSTANCES as u64) } else { 0 };
        let written = after.written_bytes - before.written_bytes;
        assert_eq!(written, 64 * INSTANCES as u64 + table, "step {step}");
        let fresh = rebuilt(&on_gpu, gpu.clone());
        assert_eq!(g, fresh.cast_rays_with(&rays, &each).unwrap(), "step {step}");
        assert_eq!(occ, fresh.test_occlusions_with(&rays, &each).unwrap(), "step {step}");
        assert!(g.geometry_ids.iter().all(|&id| id != ids[3]), "masked out");
        eprintln!(
            "hwrt step {step}: a move wrote {written} bytes ({} TLAS instances); the meshes' {} bytes stay",
            after.top_records, after.mesh_bytes
        );
    }
    // An instance more of a mesh already there: a TLAS of 101 (a new one), the table grown.
    let before = on_gpu.gpu_uploads().unwrap();
    on_gpu
        .add_instance(
            InstanceOf::Geometry(ids[0]),
            Some(Mat4::from_translation(Vec3::splat(0.5))),
            1,
        )
        .unwrap();
    let g = on_gpu.cast_rays_with(&rays, &each).unwrap();
    let after = on_gpu.gpu_uploads().unwrap();
    assert_eq!(
        (after.mesh_uploads, after.blas_builds, after.top_records),
        (1, 2, INSTANCES + 1)
    );
    assert_eq!(
        after.written_bytes - before.written_bytes,
        64 * (INSTANCES as u64 + 1) + table_bytes(INSTANCES as u64 + 1)
    );
    assert_eq!(g, rebuilt(&on_gpu, gpu.clone()).cast_rays_with(&rays, &each).unwrap());
}

/// Counts and lists of hits of a scene of driver instances are the CPU's two levels' (by
/// `intersect_tri`, as `hwrt` lists them on one level). With the default masks (all-ones: the
/// opaque path) a move writes the TLAS's instances alone, the table unchanged.
#[test]
fn driver_instances_count_as_the_cpu() {
    if !hwrt_runs() {
        return;
    }
    let mut rng = Rng::new(9);
    let (rays, _, _) = rays_with_intervals(&mut rng, 500);
    let on_cpu = instanced(opts(AccelKind::Bvh, Backend::Cpu), 6, |_| u32::MAX);
    let mut on_gpu = instanced(opts(AccelKind::Hwrt, Backend::Gpu), 6, |_| u32::MAX);
    assert_eq!(
        on_gpu.count_intersections(&rays).unwrap(),
        on_cpu.count_intersections(&rays).unwrap()
    );
    on_gpu.cast_rays(&rays).unwrap();
    let before = on_gpu.gpu_uploads().expect("the driver's instances answered");
    let ids: Vec<u32> = on_gpu.ids().collect();
    let moved: Vec<Mat4> = ids
        .iter()
        .map(|&id| Mat4::from_translation(Vec3::X) * on_gpu.geometry(id).unwrap().transform())
        .collect();
    on_gpu.set_transforms(&ids, &moved).unwrap();
    on_gpu.cast_rays(&rays).unwrap();
    let after = on_gpu.gpu_uploads().unwrap();
    assert_eq!(after.written_bytes - before.written_bytes, 64 * INSTANCES as u64);
    assert_eq!((after.blas_builds, after.tlas_builds), (2, before.tlas_builds + 1));
}
