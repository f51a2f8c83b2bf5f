//! Watertightness: rays aimed exactly at shared edges and vertices of closed meshes (and at the
//! interior edges of the open Stanford Bunny) must not slip through, on the CPU and the GPU, for
//! every structure (the plain grid, proximity clouds, the BVH and the irregular grid). A ray
//! "leaks" if it misses, or if its first hit lies beyond the aim point (relative 1e-4).

use gridtrace::AccelParams;
use std::path::Path;

use glam::{Mat4, Vec3};
use gridtrace::Ray;
use gridtrace::accel::{AccelKind, Hit, NoCounters, PACKET, Resolution, TriAccel};
use gridtrace::scene::{PreparedScene, Scene, procedural};
use gridtrace::testing::{AimedRay, edge_aimed_rays};
use rayon::prelude::*;

/// A ray leaks if it misses, or its first hit lies beyond the aim point by more than 1e-4 of the
/// aim distance, *and* the ray as given (its `f32` origin and direction, against the `f32`
/// vertices) really hits the mesh before: `exact_first_hit`, allowing for the ray's own
/// rounding. (A ray that really passed through would hit the far side of the mesh, much farther
/// away.) The second condition matters for rays that graze: the `f32` test sees the vertices
/// relative to the ray to a few ulps of their distance (`delta`), and a ray that much beside
/// the aimed edge enters a surface crossed at cosine `c` up to `delta / c` farther along; near
/// a vertex where the surface folds away from the ray (a silhouette), the rounded ray misses
/// the mesh. Seen with the watertight test: a hit 1.3e-4 (relative) past the aim point on a
/// triangle at cosine 1.4e-4, and a miss at a torus-knot vertex that the ray, computed in
/// `f64`, misses by 3e-8 on every side.
fn leaks(rays: &[AimedRay], hits: &[Hit], tris: &[TriAccel]) -> Vec<usize> {
    let cos = |k: usize, d: Vec3| {
        tris.get(k).map_or(1.0, |t: &TriAccel| {
            let (n, d) = (t.normal().as_dvec3(), d.as_dvec3());
            (n.dot(d) / (n.length() * d.length())).abs()
        })
    };
    (0..rays.len())
        .filter(|&i| !(hits[i].is_hit() && hits[i].t <= rays[i].t_aim * (1.0 + 1e-4)))
        .filter(|&i| {
            let (r, h) = (&rays[i].ray, &hits[i]);
            exact_first_hit(tris, r).is_some_and(|(t, k)| {
                let c = if h.is_hit() {
                    cos(k, r.dir).min(cos(h.tri as usize, r.dir))
                } else {
                    cos(k, r.dir)
                };
                let scale = f64::from(r.origin.abs().max_element() + r.at(rays[i].t_aim).abs().max_element());
                let delta = 16.0 * f64::from(f32::EPSILON) * scale;
                let allowed = t * (1.0 + 1e-4) + delta / (c * f64::from(r.dir.length()));
                !(h.is_hit() && f64::from(h.t) <= allowed)
            })
        })
        .collect()
}

/// The first hit (`t >= 0`) of `ray` on `tris` in `f64`, and its triangle: the watertight
/// test's steps on the `f32` inputs in `f64` (exact products), brute force over all.
fn exact_first_hit(tris: &[TriAccel], ray: &Ray) -> Option<(f64, usize)> {
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let a = d.abs();
    let kz = if a.x > a.y {
        if a.x > a.z { 0 } else { 2 }
    } else if a.y > a.z {
        1
    } else {
        2
    };
    let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
    let (sx, sy, sz) = (d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]);
    let mut best: Option<(f64, usize)> = None;
    for (k, t) in tris.iter().enumerate() {
        let p = t.vertices().map(|v| {
            let q = v.as_dvec3() - o;
            [q[kx] - sx * q[kz], q[ky] - sy * q[kz], q[kz] * sz]
        });
        let ef = |a: [f64; 3], b: [f64; 3]| a[0] * b[1] - a[1] * b[0];
        let e = [ef(p[1], p[2]), ef(p[2], p[0]), ef(p[0], p[1])];
        if (e.iter().any(|&x| x < 0.0) && e.iter().any(|&x| x > 0.0)) || e.iter().sum::<f64>() == 0.0 {
            continue;
        }
        let tt = (e[0] * p[0][2] + e[1] * p[1][2] + e[2] * p[2][2]) / e.iter().sum::<f64>();
        if tt >= 0.0 && best.is_none_or(|(b, _)| tt < b) {
            best = Some((tt, k));
        }
    }
    best
}

/// The meshes and how many rays each gets: 1,000,000 in all (bunny present) or 700,000.
pub fn meshes() -> Vec<(&'static str, gridtrace::Mesh, usize)> {
    let mut v = vec![
        (
            "icosphere",
            procedural::icosphere(Vec3::new(0.3, -0.2, 0.1), 1.0, 5),
            350_000,
        ),
        ("torus-knot", procedural::torus_knot(2, 3, 0.16, 96, 8), 350_000),
    ];
    let bunny = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/meshes/bunny/bun_zipper.ply"
    ));
    if bunny.exists() {
        v.push(("bunny", gridtrace::io::load_mesh(bunny).unwrap(), 300_000));
    } else {
        eprintln!("{} not present: bunny skipped", bunny.display());
    }
    v
}

/// The rays `kind` is tested with: all of them, or for a structure whose rays test every
/// triangle (brute force: a million rays at the Stanford Bunny would be 7e10 triangle tests)
/// every 200th; for one the driver traverses (`hwrt`) on a software adapter every 20th: on
/// lavapipe its ray queries took over the 120-second device wait for the Stanford Bunny's
/// 300,000 rays on two shared cores (2026-11-27).
fn rays_for(kind: AccelKind, rays: &[AimedRay], software: bool) -> Vec<AimedRay> {
    let step = if kind.entry().every_triangle {
        200
    } else if !kind.entry().cpu && software {
        20
    } else {
        1
    };
    rays.iter().step_by(step).copied().collect()
}

/// The mesh alone, prepared, and `n` rays aimed at its shared edges and vertices (seeded, so the
/// CPU and GPU tests see the same rays).
fn scene_and_rays(mesh: gridtrace::Mesh, n: usize) -> (PreparedScene, Vec<AimedRay>) {
    let mut s = Scene::default();
    s.add_mesh(mesh, Mat4::IDENTITY, None);
    s.camera.eye = Vec3::new(0.0, 0.0, 10.0);
    let scene = s.prepare(Resolution::default()).unwrap();
    // The scene's world-space positions, which `tri_vertices` index.
    let rays = edge_aimed_rays(&scene.accel, &s.mesh.positions, &scene.tri_vertices, n, 0xED6E);
    (scene, rays)
}

/// The scene prepared for every structure: the grid (serving `grid` and `pc`) and one per kind
/// with a structure of its own.
fn all_structures(scene: PreparedScene) -> Vec<PreparedScene> {
    let own: Vec<PreparedScene> = AccelKind::ALL
        .into_iter()
        .filter(|k| !k.uses_grid())
        .map(|k| scene.with_accel(k, &AccelParams::NONE).unwrap())
        .collect();
    std::iter::once(scene).chain(own).collect()
}

/// The share of rays a structure the driver intersects (`hwrt`, by ray query) may leak; none of
/// ours may. lavapipe (Mesa 25.0.7) leaked 355 of the icosphere's 350,000 rays and 318 of the
/// torus knot's (2026-11-27, all the rays; the test now gives a software adapter every 20th,
/// and prints its counts): its ray-query triangle test is not watertight at shared edges and
/// vertices. Five times that share is allowed.
const DRIVER_LEAKS: f64 = 0.005;

/// Leaking rays per mesh and accel kind, on the CPU.
/// With `packets`, every 8th ray is traced as one lane of a packet (`Accel::intersect_packet`,
/// nothing counted: the route of renders and coherent batches, the BVH's packet walk), its
/// lane moving with the ray's index and the other lanes coherent companions (its origin,
/// directions a little apart).
fn cpu_leaks(packets: bool) -> (usize, Vec<String>) {
    let mut total = 0;
    let mut report = Vec::new();
    for (name, mesh, n) in meshes() {
        let tris = TriAccel::from_mesh(&mesh);
        let (scene, rays) = scene_and_rays(mesh, n);
        total += rays.len();
        let scenes = all_structures(scene);
        // `hwrt`'s CPU side is the BVH's walk, tested as the BVH; its rays are the GPU's.
        for kind in AccelKind::ALL.into_iter().filter(|k| k.entry().cpu) {
            let scene = &scenes
                .iter()
                .find(|s| s.accel.structure_id() == kind.structure())
                .unwrap()
                .with_accel(kind, &gridtrace::AccelParams::NONE)
                .unwrap();
            let mut rays = rays_for(kind, &rays, false);
            if packets {
                rays = rays.into_iter().step_by(PACKET).collect();
            }
            let hits: Vec<Hit> = rays
                .par_iter()
                .enumerate()
                .map(|(i, r)| {
                    if !packets {
                        return scene.accel.intersect(&r.ray, &mut NoCounters);
                    }
                    let k = i % PACKET;
                    let side = r.ray.dir.any_orthonormal_vector() * r.ray.dir.length() * 1e-3;
                    let lanes: [Ray; PACKET] =
                        std::array::from_fn(|j| Ray::new(r.ray.origin, r.ray.dir + side * (j as f32 - k as f32)));
                    let mut none = [NoCounters; PACKET];
                    scene.accel.intersect_packet(&lanes, &mut none)[k]
                })
                .collect();
            let bad = leaks(&rays, &hits, &tris);
            eprintln!("{name} {}: {} of {} rays leak", kind.name(), bad.len(), rays.len());
            if !bad.is_empty() {
                report.push(format!(
                    "{name} {}: {} of {} rays leak; first: {:?}",
                    kind.name(),
                    bad.len(),
                    rays.len(),
                    bad.iter().take(3).map(|&i| (rays[i], hits[i])).collect::<Vec<_>>()
                ));
            }
        }
    }
    (total, report)
}

/// Möller-Trumbore with a fixed 1e-6 barycentric slack leaked about 1.8% of these rays: its
/// barycentric error grows with the distance of the ray origin relative to the triangle size.
/// The watertight test (`TriAccel::intersect`), on vertices shared bit for bit, leaks none.
#[test]
fn cpu_watertight_edges_and_vertices_do_not_leak() {
    let (total, report) = cpu_leaks(false);
    assert!(total >= 700_000);
    assert!(report.is_empty(), "{}", report.join("\n"));
}

/// The same rays (every 8th) as lanes of coherent packets: the BVH's packet walk (interval
/// culling, ties redone by the single walk) and the irregular grid's packets leak none either.
#[test]
fn cpu_packets_at_edges_and_vertices_do_not_leak() {
    let (_, report) = cpu_leaks(true);
    assert!(report.is_empty(), "{}", report.join("\n"));
}

/// The same rays through the GPU batch API (lavapipe in CI), whose watertight test decides
/// exact zeros without f64 (`edge_fn` in common.wgsl).
#[test]
fn gpu_edges_and_vertices_do_not_leak() {
    if std::env::var_os("GRIDTRACE_SKIP_GPU").is_some() {
        eprintln!("GRIDTRACE_SKIP_GPU is set: skipping");
        return;
    }
    let mut total = 0;
    for (name, mesh, n) in meshes() {
        let tris = TriAccel::from_mesh(&mesh);
        let (scene, rays) = scene_and_rays(mesh, n);
        total += rays.len();
        let ctx = std::sync::Arc::new(
            gridtrace::gpu::GpuContext::new()
                .unwrap_or_else(|e| panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}")),
        );
        let kinds = gridtrace::testing::gpu_kinds(&ctx);
        let mut gpus: Vec<(PreparedScene, gridtrace::gpu::GpuRenderer)> = all_structures(scene)
            .into_iter()
            .filter(|s| kinds.iter().any(|&k| s.accel.structure_id() == k.structure()))
            .map(|s| {
                let g =
                    gridtrace::gpu::GpuRenderer::new(ctx.clone(), &s, &gridtrace::gpu::GpuVariants::default()).unwrap();
                (s, g)
            })
            .collect();
        for &kind in &kinds {
            let (_, gpu) = gpus
                .iter_mut()
                .find(|(s, _)| s.accel.structure_id() == kind.structure())
                .unwrap();
            gpu.set_traversal(kind).unwrap();
            let rays = rays_for(kind, &rays, ctx.is_software());
            let plain: Vec<_> = rays.iter().map(|r| r.ray).collect();
            let hits = gpu.intersect(&plain).unwrap();
            let bad = leaks(&rays, &hits, &tris);
            eprintln!("GPU {name} {}: {} of {} rays leak", kind.name(), bad.len(), rays.len());
            // `hwrt` is the driver's triangle test, not ours: its leaks are measured and held
            // to `DRIVER_LEAKS` (lavapipe, Mesa 25.0.7, is not watertight at shared edges).
            let allowed = if kind.entry().cpu {
                0
            } else {
                (rays.len() as f64 * DRIVER_LEAKS) as usize
            };
            assert!(
                bad.len() <= allowed,
                "GPU {name} {}: {} of {} rays leak; first: {:?}",
                kind.name(),
                bad.len(),
                rays.len(),
                bad.iter().take(3).map(|&i| (rays[i], hits[i])).collect::<Vec<_>>()
            );
        }
        eprintln!("GPU {name}: {} rays, no leaks beyond the allowances", rays.len());
    }
    assert!(total >= 700_000);
}

/// The near-miss family (`testing::near_miss_rays`) on the GPU, every structure with our own
/// triangle test (`hwrt`'s is the driver's): no hit 1e-6 or more beside an edge head-on (1e-5
/// grazing), a hit as close inside, and `t = 0` for a ray starting on the triangle. WGSL has
/// no f64: this checks that its exact zeros (`edge_fn`) decide these as the CPU does.
#[test]
fn gpu_near_misses_miss_and_near_hits_hit() {
    if std::env::var_os("GRIDTRACE_SKIP_GPU").is_some() {
        eprintln!("GRIDTRACE_SKIP_GPU is set: skipping");
        return;
    }
    let (vertices, faces) = gridtrace::testing::soup_arrays(&[gridtrace::testing::unit_triangle()]);
    let rays = gridtrace::testing::near_miss_rays();
    let plain: Vec<Ray> = rays.iter().map(|m| m.ray).collect();
    let ctx = gridtrace::gpu::GpuContext::new()
        .unwrap_or_else(|e| panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}"));
    let kinds: Vec<AccelKind> = gridtrace::testing::gpu_kinds(&ctx)
        .into_iter()
        .filter(|k| k.name() != "hwrt")
        .collect();
    assert!(kinds.len() >= 4, "{kinds:?}");
    for kind in kinds {
        let mesh = gridtrace::testing::gpu_mesh(&vertices, &faces, kind);
        let hits = mesh.intersect_rays(&plain).unwrap();
        for (m, h) in rays.iter().zip(&hits) {
            assert_eq!(h.is_hit(), m.hits, "GPU {}: {m:?} got {h:?}", kind.name());
            if let Some(t) = m.t {
                assert_eq!(h.t, t, "GPU {}: {m:?}", kind.name());
            }
        }
    }
}
