//! The GPU BVH against brute force on the CPU, closest and any hit, on a random soup and on
//! degenerate inputs: one triangle, one plane, a million copies of one triangle, a mesh a
//! million times longer than wide. (The built-in scenes' GPU BVH is checked against the CPU
//! BVH and its images against the CPU's in tests/gpu.rs; its edge leaks in tests/edges.rs.)
//!
//! Fails, not skips, without an adapter (lavapipe in CI); GRIDTRACE_SKIP_GPU=1 skips knowingly.

use std::sync::Mutex;

use glam::Vec3;
use gridtrace::Backend;
use gridtrace::accel::{Accel, AccelKind, Hit, Ray, TriAccel, brute_force_intersect, brute_force_occluded};
use gridtrace::query::TraceMesh;
use gridtrace::testing::{
    flat_scene, gpu_disagreements, gpu_mesh, long_strip, ray_set, skip_gpu, soup_arrays, triangle_soup,
};
use rayon::prelude::*;

static GPU_LOCK: Mutex<()> = Mutex::new(());

/// `testing::ray_set`'s adversarial rays (drawn from a grid over the mesh's triangles).
fn rays_for(mesh: &TraceMesh, n: usize, seed: u64) -> Vec<Ray> {
    let grid = Accel::build(
        mesh.prepared().accel.tris.clone(),
        AccelKind::Grid,
        &gridtrace::AccelParams::NONE,
    )
    .unwrap();
    ray_set(&grid, n, seed)
}

/// GPU closest and any hits equal brute force over the mesh's own (kept) triangles: same hit
/// or miss, t within a relative 1e-4 (`testing::gpu_disagreements`, which also excuses a
/// hit-or-miss disagreement on a triangle's own boundary, at most 1% of the rays here). Any
/// hit is asked twice: unbounded, and with t_max halfway to the closest hit (must be false).
/// At most `rays / 10,000` rays may disagree otherwise (as in tests/gpu.rs).
fn check(name: &str, mesh: &TraceMesh, rays: &[Ray]) {
    let tris = &mesh.prepared().accel.tris;
    let want: Vec<Hit> = rays.par_iter().map(|r| brute_force_intersect(tris, r)).collect();
    let got = mesh.intersect_rays_with(Backend::Gpu, rays).unwrap();
    let occ = mesh.occluded_rays_with(Backend::Gpu, rays).unwrap();
    let (bad, excused) = gpu_disagreements(rays, &want, &got, &occ);
    // The excuse must stay an exception (a GPU test that misses every edge would pass it).
    assert!(
        excused <= rays.len() / 100,
        "{name}: {excused} of {} rays disagree on a triangle's boundary",
        rays.len()
    );
    let allowed = rays.len() / 10_000;
    assert!(
        bad.len() <= allowed,
        "{name}: {} of {} rays disagree with brute force; first: {:?}",
        bad.len(),
        rays.len(),
        bad.iter()
            .take(3)
            .map(|&i| (rays[i], want[i], got[i]))
            .collect::<Vec<_>>()
    );
    // Bounded any hit: nothing lies before half the closest hit (brute force agrees).
    let hit_rays: Vec<(Ray, f32)> = rays
        .iter()
        .zip(&want)
        .filter(|(_, h)| h.is_hit() && h.t > 1e-3)
        .map(|(r, h)| (*r, h.t * 0.5))
        .collect();
    for chunk in hit_rays.chunk_by(|a, b| a.1 == b.1) {
        let rs: Vec<Ray> = chunk.iter().map(|c| c.0).collect();
        let t_max = chunk[0].1;
        let o = mesh
            .occluded_rays_with(Backend::Gpu, &gridtrace::testing::within(&rs, 0.0, t_max))
            .unwrap();
        let wrong = rs
            .iter()
            .zip(&o)
            .filter(|(r, o)| **o != brute_force_occluded(tris, &gridtrace::testing::within(r, 0.0, t_max)))
            .count();
        assert!(wrong <= allowed, "{name}: {wrong} bounded any-hit results disagree");
    }
    let hits = want.iter().filter(|h| h.is_hit()).count();
    eprintln!(
        "{name}: {} rays, {hits} hits, {} disagree, {excused} on a boundary",
        rays.len(),
        bad.len()
    );
    assert!(hits > 0, "{name}: the ray set must hit something");
}

#[test]
fn soup_100k_rays() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let (v, f) = soup_arrays(&triangle_soup(3000, 0xB7));
    let mesh = gpu_mesh(&v, &f, AccelKind::Bvh);
    let rays = rays_for(&mesh, 100_000, 0xB8);
    check("soup", &mesh, &rays);
}

#[test]
fn one_triangle_and_one_plane() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let mesh = gpu_mesh(
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        &[[0, 1, 2]],
        AccelKind::Bvh,
    );
    let rays = rays_for(&mesh, 20_000, 1);
    check("one triangle", &mesh, &rays);
    let (v, f) = soup_arrays(&flat_scene(5));
    let mesh = gpu_mesh(&v, &f, AccelKind::Bvh);
    let rays = rays_for(&mesh, 20_000, 2);
    check("one plane", &mesh, &rays);
}

/// A strip a million units long and one wide: boxes of every aspect, rays at every angle.
#[test]
fn aspect_ratio_one_million() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let (v, f) = long_strip(1000);
    let mesh = gpu_mesh(&v, &f, AccelKind::Bvh);
    let rays = rays_for(&mesh, 20_000, 3);
    check("1e6:1 strip", &mesh, &rays);
}

/// A million copies of one triangle: the SAH cannot split them (one centre), the builder splits
/// by count, and a ray through the triangle must visit every leaf. No hang, no stack overflow,
/// and the hit is the triangle's.
#[test]
fn a_million_copies_of_one_triangle() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let f = vec![[0u32, 1, 2]; 1_000_000];
    let mesh = gpu_mesh(&v, &f, AccelKind::Bvh);
    assert_eq!(mesh.triangle_count(), 1_000_000);
    // 16 rays through the triangle (every one visits every leaf), 16 beside it, 16 along it.
    let mut rays = Vec::new();
    for i in 0..16 {
        let s = i as f32 / 16.0;
        rays.push(Ray::new(
            Vec3::new(0.1 + 0.4 * s, 0.3 - 0.2 * s, 2.0),
            Vec3::new(0.01, 0.02, -1.0),
        ));
        rays.push(Ray::new(Vec3::new(1.0 + s, 1.0, 2.0), Vec3::new(0.0, 0.0, -1.0)));
        rays.push(Ray::new(Vec3::new(-1.0, 0.2 + s * 0.01, 0.0), Vec3::new(1.0, 0.0, 0.0)));
    }
    let got = mesh.intersect_rays_with(Backend::Gpu, &rays).unwrap();
    let occ = mesh.occluded_rays_with(Backend::Gpu, &rays).unwrap();
    let tri = TriAccel::new(Vec3::ZERO, Vec3::X, Vec3::Y);
    for (i, r) in rays.iter().enumerate() {
        let want = tri.intersect(r.origin, r.dir, 0.0, f32::INFINITY);
        assert_eq!(got[i].is_hit(), want.is_some(), "ray {i}: {r:?} -> {:?}", got[i]);
        assert_eq!(occ[i], want.is_some(), "ray {i}");
        if let Some(w) = want {
            assert!(
                (got[i].t - w.t).abs() <= 1e-4 * w.t,
                "ray {i}: t {} vs {}",
                got[i].t,
                w.t
            );
            assert!((got[i].tri as usize) < 1_000_000);
        }
    }
    assert_eq!(got.iter().filter(|h| h.is_hit()).count(), 16);
}
