//! The irregular grid on the GPU against brute force on the CPU, closest and any hit, and
//! against the CPU's walk of the same grid ray by ray (same t, same triangle up to ties): on a
//! random soup, on degenerate inputs (one triangle, one plane, a strip a million times longer
//! than wide, many copies of one triangle), on a dense cluster in a large empty room (the case
//! the structure is for: merging and expansion make boxes of every size), and with other build
//! parameters (no merging or expansion; fine cells merged aggressively). The ray sets add, to
//! `testing::ray_set`'s adversarial rays, rays that lie in the virtual voxels' planes and run
//! along and through the corners of the cells' grown boxes: where the walk's exit point lies
//! exactly on a face. (The built-in scenes' images are checked against the CPU in tests/gpu.rs,
//! edge leaks in tests/edges.rs.)
//!
//! Fails, not skips, without an adapter (lavapipe in CI); GRIDTRACE_SKIP_GPU=1 skips knowingly.

use gridtrace::AccelParams;
use std::sync::{Arc, Mutex};

use glam::Vec3;
use gridtrace::Backend;
use gridtrace::accel::{
    Accel, AccelKind, Hit, IrregularGrid, IrregularParams, NoCounters, Ray, TriAccel, brute_force_intersect,
    brute_force_occluded,
};
use gridtrace::gpu::{GpuContext, GpuRenderer};
use gridtrace::query::{QueryOptions, TraceMesh};
use gridtrace::scene::PreparedScene;
use gridtrace::testing::{
    flat_scene, gpu_disagreements, gpu_mesh, long_strip, on_triangle_boundary, ray_set, skip_gpu, soup_arrays, t_close,
    triangle_soup,
};
use gridtrace::util::Rng;
use rayon::prelude::*;

static GPU_LOCK: Mutex<()> = Mutex::new(());

/// `n` rays where the irregular grid's walk is on a knife edge, in turn: in a voxel plane that
/// is a face of some cell's grown box (origin on the plane, direction within it); through a
/// corner of a grown box from anywhere around the grid; along an edge of a grown box
/// (axis-parallel, from outside the grid); from a point on a grown box's face, inward or out.
fn voxel_rays(g: &IrregularGrid, n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed);
    let b = g.bounds;
    let ext = b.extent();
    let voxel = |v: [u32; 3]| b.min + Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32) * g.voxel_size;
    let around = |rng: &mut Rng| {
        Vec3::new(
            rng.range(b.min.x - ext.x * 0.5, b.max.x + ext.x * 0.5),
            rng.range(b.min.y - ext.y * 0.5, b.max.y + ext.y * 0.5),
            rng.range(b.min.z - ext.z * 0.5, b.max.z + ext.z * 0.5),
        )
    };
    let dir = |rng: &mut Rng| {
        Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize_or(Vec3::X)
    };
    let mut rays = Vec::with_capacity(n);
    while rays.len() < n {
        let cell = g.cell(rng.below(g.cell_count() as u32));
        // A corner of the cell's grown box.
        let corner = [0, 1, 2].map(|a| if rng.below(2) == 0 { cell.min[a] } else { cell.max[a] });
        let axis = rng.below(3) as usize;
        let ray = match rays.len() % 4 {
            0 => {
                let mut o = around(&mut rng);
                o[axis] = voxel(corner)[axis];
                let mut d = dir(&mut rng);
                d[axis] = 0.0;
                Ray::new(o, d)
            }
            1 => {
                let o = around(&mut rng);
                Ray::new(o, voxel(corner) - o)
            }
            2 => {
                let mut d = Vec3::ZERO;
                d[axis] = if rng.below(2) == 0 { 1.0 } else { -1.0 };
                Ray::new(voxel(corner) - d * ext[axis] * rng.range(0.6, 2.0), d)
            }
            _ => {
                let lo = voxel(cell.min);
                let hi = voxel(cell.max);
                let mut o = Vec3::new(rng.range(lo.x, hi.x), rng.range(lo.y, hi.y), rng.range(lo.z, hi.z));
                o[axis] = voxel(corner)[axis];
                Ray::new(o, dir(&mut rng))
            }
        };
        if ray.dir.length_squared() > 0.0 && ray.dir.is_finite() {
            rays.push(ray);
        }
    }
    rays
}

/// `testing::ray_set`'s adversarial rays (drawn from a uniform grid over the same triangles),
/// then as many of `voxel_rays`.
fn rays_for(accel: &Accel, n: usize, seed: u64) -> Vec<Ray> {
    let grid = Accel::build(accel.tris.clone(), AccelKind::Grid, &AccelParams::NONE).unwrap();
    let mut rays = ray_set(&grid, n / 2, seed);
    rays.extend(voxel_rays(accel.irregular().unwrap(), n - n / 2, seed ^ 0x1EE6));
    rays
}

/// The GPU's ray queries under test: through `TraceMesh` (the query API) or a renderer.
trait GpuQueries {
    fn closest(&mut self, rays: &[Ray]) -> Vec<Hit>;
    fn any(&mut self, rays: &[Ray], t_max: f32) -> Vec<bool>;
}

impl GpuQueries for &TraceMesh {
    fn closest(&mut self, rays: &[Ray]) -> Vec<Hit> {
        self.intersect_rays_with(Backend::Gpu, rays).unwrap()
    }
    fn any(&mut self, rays: &[Ray], t_max: f32) -> Vec<bool> {
        self.occluded_rays_with(Backend::Gpu, &gridtrace::testing::within(rays, 0.0, t_max))
            .unwrap()
    }
}

impl GpuQueries for GpuRenderer {
    fn closest(&mut self, rays: &[Ray]) -> Vec<Hit> {
        self.intersect(rays).unwrap()
    }
    fn any(&mut self, rays: &[Ray], t_max: f32) -> Vec<bool> {
        self.occluded(&gridtrace::testing::within(rays, 0.0, t_max)).unwrap()
    }
}

/// Checks, on `rays`:
/// - the CPU's walk of the irregular grid equals brute force exactly (same hit or miss, same t:
///   both run the same triangle test, so the closest triangle gives the same t bit for bit),
///   closest and any hit;
/// - the GPU's closest and any hits equal brute force: same hit or miss, t within a relative
///   1e-4 (the GPU compiler may fuse multiply-adds); any hit also bounded at half the closest
///   hit (must be false);
/// - the GPU's walk equals the CPU's per ray: same t and the same triangle, or a tie (the CPU
///   hits the GPU's triangle at the same t, or hit an edge or vertex that neighbours share).
///
/// For the GPU, at most `rays / 10,000` rays through exact edges may round either way (as in
/// tests/gpu.rs and tests/gpu_bvh.rs).
fn check(name: &str, accel: &Accel, gpu: &mut impl GpuQueries, rays: &[Ray]) {
    assert!(accel.irregular().is_some(), "{name}: not an irregular grid");
    let tris = &accel.tris;
    let want: Vec<Hit> = rays.par_iter().map(|r| brute_force_intersect(tris, r)).collect();
    let cpu: Vec<Hit> = rays.par_iter().map(|r| accel.intersect(r, &mut NoCounters)).collect();
    let cpu_occ: Vec<bool> = rays.par_iter().map(|r| accel.occluded(r, &mut NoCounters)).collect();
    let cpu_bad: Vec<usize> = (0..rays.len())
        .filter(|&i| {
            let (w, c) = (&want[i], &cpu[i]);
            w.is_hit() != c.is_hit() || (w.is_hit() && w.t != c.t) || cpu_occ[i] != w.is_hit()
        })
        .collect();
    assert!(
        cpu_bad.is_empty(),
        "{name}: the CPU walk disagrees with brute force on {} of {} rays; first: {:?}",
        cpu_bad.len(),
        rays.len(),
        cpu_bad
            .iter()
            .take(3)
            .map(|&i| (rays[i], want[i], cpu[i], cpu_occ[i]))
            .collect::<Vec<_>>()
    );

    let got = gpu.closest(rays);
    let occ = gpu.any(rays, f32::INFINITY);
    assert_eq!((got.len(), occ.len()), (rays.len(), rays.len()));
    let allowed = rays.len() / 10_000;
    // Hit-or-miss on a triangle's own boundary excused, at most 1% (`gpu_disagreements`).
    let (bad, excused) = gpu_disagreements(rays, &want, &got, &occ);
    assert!(
        excused <= rays.len() / 100,
        "{name}: {excused} of {} GPU rays disagree on a triangle's boundary",
        rays.len()
    );
    assert!(
        bad.len() <= allowed,
        "{name}: {} of {} GPU rays disagree with brute force; first: {:?}",
        bad.len(),
        rays.len(),
        bad.iter()
            .take(3)
            .map(|&i| (rays[i], want[i], got[i], occ[i]))
            .collect::<Vec<_>>()
    );
    // The two walks, ray by ray.
    let same_walk = |i: usize| {
        let (c, g) = (&cpu[i], &got[i]);
        if c.is_hit() != g.is_hit() {
            // On a triangle's own boundary: counted in `excused` above (the CPU's walk answers
            // as brute force).
            return on_triangle_boundary(c) || on_triangle_boundary(g);
        }
        if !c.is_hit() {
            return true;
        }
        // Coplanar or neighbouring faces: either walk may name one the other's test puts on
        // its boundary.
        let on_edge = on_triangle_boundary(c) || on_triangle_boundary(g);
        t_close(&rays[i], c.t, g.t)
            && (c.tri == g.tri
                || on_edge
                || tris[g.tri as usize]
                    .intersect(rays[i].origin, rays[i].dir, 0.0, f32::INFINITY)
                    .is_some_and(|h| t_close(&rays[i], h.t, c.t)))
    };
    let differ: Vec<usize> = (0..rays.len()).filter(|&i| !same_walk(i)).collect();
    assert!(
        differ.len() <= allowed,
        "{name}: the GPU and CPU walks differ on {} of {} rays; first: {:?}",
        differ.len(),
        rays.len(),
        differ
            .iter()
            .take(3)
            .map(|&i| (rays[i], cpu[i], got[i]))
            .collect::<Vec<_>>()
    );
    // Bounded any hit: nothing lies before half the closest hit (brute force agrees).
    let hit_rays: Vec<(Ray, f32)> = rays
        .iter()
        .zip(&want)
        .filter(|(_, h)| h.is_hit() && h.t > 1e-3)
        .map(|(r, h)| (*r, h.t * 0.5))
        .collect();
    let mut wrong = 0;
    for chunk in hit_rays.chunk_by(|a, b| a.1 == b.1) {
        let rs: Vec<Ray> = chunk.iter().map(|c| c.0).collect();
        let t_max = chunk[0].1;
        let o = gpu.any(&rs, t_max);
        wrong += rs
            .iter()
            .zip(&o)
            .filter(|(r, o)| **o != brute_force_occluded(tris, &gridtrace::testing::within(r, 0.0, t_max)))
            .count();
    }
    assert!(wrong <= allowed, "{name}: {wrong} bounded any-hit results disagree");
    let hits = want.iter().filter(|h| h.is_hit()).count();
    let g = accel.irregular().unwrap();
    eprintln!(
        "{name}: {} cells over {:?} voxels; {} rays, {hits} hits, {} disagree with brute force, {} with the CPU walk",
        g.cell_count(),
        g.voxel_dims(),
        rays.len(),
        bad.len(),
        differ.len()
    );
    assert!(hits > 0, "{name}: the ray set must hit something");
}

/// Checks the mesh through the query API (`TraceMesh` with the GPU backend).
fn check_mesh(name: &str, vertices: &[[f32; 3]], faces: &[[u32; 3]], n: usize, seed: u64) {
    let mesh = gpu_mesh(vertices, faces, AccelKind::Irregular);
    let accel = &mesh.prepared().accel;
    let rays = rays_for(accel, n, seed);
    check(name, accel, &mut &mesh, &rays);
}

#[test]
fn soup_100k_rays() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let (v, f) = soup_arrays(&triangle_soup(3000, 0x1B7));
    check_mesh("soup", &v, &f, 100_000, 0x1B8);
}

#[test]
fn one_triangle_and_one_plane() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    check_mesh(
        "one triangle",
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        &[[0, 1, 2]],
        20_000,
        1,
    );
    let (v, f) = soup_arrays(&flat_scene(5));
    check_mesh("one plane", &v, &f, 20_000, 2);
}

/// A strip a million units long and one wide: voxels and boxes of every aspect, rays at every
/// angle.
#[test]
fn aspect_ratio_one_million() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let (v, f) = long_strip(1000);
    check_mesh("1e6:1 strip", &v, &f, 20_000, 3);
}

/// Many copies of one triangle: every cell it touches holds all of them, so a ray through it
/// tests them all. (Not a million, as for the BVH: the build pairs every copy with every top
/// cell the triangle overlaps, by design.) The hit is the triangle's.
#[test]
fn many_copies_of_one_triangle() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let f = vec![[0u32, 1, 2]; 300];
    let mesh = gpu_mesh(&v, &f, AccelKind::Irregular);
    assert_eq!(mesh.triangle_count(), 300);
    let rays = rays_for(&mesh.prepared().accel, 20_000, 4);
    check("300 copies", &mesh.prepared().accel, &mut &mesh, &rays);
}

/// A dense cluster (3,000 triangles in a box of side about 1.4) in a room of side 20 (its walls
/// two triangles each): the case the irregular grid is for. Empty space becomes a few large
/// boxes, the cluster many small ones (the top cells are split by at most 16 per axis, so a
/// much smaller cluster would sit in one voxel), and rays from inside the room at the cluster
/// cross boxes of very different sizes.
#[test]
fn teapot_in_a_stadium() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let mut tris: Vec<TriAccel> = triangle_soup(3000, 0x7EA)
        .into_iter()
        .map(|t| {
            let [a, b, c] = t.vertices().map(|p| p * 0.5 + Vec3::new(3.0, -2.0, 1.0));
            TriAccel::new(a, b, c)
        })
        .collect();
    let s = 10.0;
    for axis in 0..3 {
        for side in [-s, s] {
            let corner = |u: f32, v: f32| {
                let mut p = Vec3::ZERO;
                p[axis] = side;
                p[(axis + 1) % 3] = u;
                p[(axis + 2) % 3] = v;
                p
            };
            tris.push(TriAccel::new(corner(-s, -s), corner(s, -s), corner(s, s)));
            tris.push(TriAccel::new(corner(-s, -s), corner(s, s), corner(-s, s)));
        }
    }
    let (v, f) = soup_arrays(&tris);
    let mesh = gpu_mesh(&v, &f, AccelKind::Irregular);
    let accel = &mesh.prepared().accel;
    let g = accel.irregular().unwrap();
    // The build really made boxes of very different sizes.
    let volume = |c: u32| {
        let c = g.cell(c);
        (0..3).map(|a| (c.max[a] - c.min[a]) as u64).product::<u64>()
    };
    let largest = (0..g.cell_count() as u32).map(volume).max().unwrap();
    let smallest = (0..g.cell_count() as u32).map(volume).min().unwrap();
    assert!(largest >= 1000 * smallest, "{largest} vs {smallest} voxels");
    let mut rays = rays_for(accel, 40_000, 5);
    // And rays from inside the room at the cluster, where the small boxes are.
    let mut rng = Rng::new(6);
    for _ in 0..10_000 {
        let o = Vec3::new(rng.range(-9.0, 9.0), rng.range(-9.0, 9.0), rng.range(-9.0, 9.0));
        let target =
            Vec3::new(3.0, -2.0, 1.0) + Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), rng.range(-0.5, 0.5));
        rays.push(Ray::new(o, target - o));
    }
    check("teapot in a stadium", accel, &mut &mesh, &rays);
}

/// Other build parameters give other grids, which the GPU must walk as well: the plain
/// two-level grid (no merging, no expansion: many small boxes, every one of them its own cell)
/// and fine cells merged aggressively (cells that share few triangles merge too).
#[test]
fn other_build_parameters() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let (v, f) = soup_arrays(&triangle_soup(2000, 0xA1));
    let mesh = TraceMesh::from_arrays(&v, &f, &QueryOptions::default()).unwrap();
    let d = IrregularParams::default();
    let variants = [
        (
            "two-level grid",
            IrregularParams {
                merge_passes: 0,
                expand_passes: 0,
                ..d
            },
        ),
        (
            "fine cells, aggressive merging",
            IrregularParams {
                top_density: 0.5,
                cell_density: 8.0,
                merge_alpha: 1.5,
                ..d
            },
        ),
    ];
    let ctx = Arc::new(
        GpuContext::new().unwrap_or_else(|e| panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}")),
    );
    for (i, (name, params)) in variants.into_iter().enumerate() {
        let scene = PreparedScene {
            accel: Accel::build(
                mesh.prepared().accel.tris.clone(),
                AccelKind::Irregular,
                &params.to_params(),
            )
            .unwrap(),
            ..mesh.prepared().clone()
        };
        let mut gpu = GpuRenderer::new(ctx.clone(), &scene, &gridtrace::gpu::GpuVariants::default()).unwrap();
        let rays = rays_for(&scene.accel, 30_000, 7 + i as u64);
        check(name, &scene.accel, &mut gpu, &rays);
    }
}
