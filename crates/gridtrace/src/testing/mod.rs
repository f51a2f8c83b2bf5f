//! Test support shared by the unit tests, the integration tests (CPU and GPU), the benchmarks and
//! the fuzzers: scenes and adversarial ray sets. Public so every consumer draws the same rays.

use glam::Vec3;

use crate::accel::{Aabb, Accel, AccelKind, AccelParams, Grid, Ray, Resolution, TriAccel};
use crate::scene::procedural;
use crate::util::Rng;

mod bad_input;
mod instances;
mod intervals;
mod shapes;
pub use bad_input::{BadFile, bad_input_corpus};
pub use instances::{compare_hits, instanced_scene, move_step, ray_hit, rebuilt};
pub use intervals::{WithInterval, within, within_each};
pub use shapes::{cuboid, open3d_cube};

/// A random triangle soup: `n` triangles with sizes from slivers to large, in a unit-ish cube.
pub fn triangle_soup(n: usize, seed: u64) -> Vec<TriAccel> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|i| {
            let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            let size = [0.02, 0.1, 0.4][i % 3];
            let mut p = || c + Vec3::new(rng.range(-size, size), rng.range(-size, size), rng.range(-size, size));
            let (a, b, mut cc) = (p(), p(), p());
            if i % 17 == 0 {
                // Long thin sliver.
                cc = a + (b - a) * 0.5 + Vec3::new(1e-3, -1e-3, 2e-3);
            }
            TriAccel::new(a, b, cc)
        })
        .filter(|t| t.normal().length_squared() > 0.0)
        .collect()
}

/// A flat scene: a tessellated square in the z = 0.25 plane plus a flat random soup in it.
pub fn flat_scene(seed: u64) -> Vec<TriAccel> {
    let mut tris: Vec<TriAccel> = Vec::new();
    let m = procedural::plane(2.0, 12);
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| {
            let p = m.positions[i as usize];
            Vec3::new(p.x, p.z, 0.25)
        });
        tris.push(TriAccel::new(a, b, c));
    }
    let mut rng = Rng::new(seed);
    for _ in 0..400 {
        let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.25);
        let mut p = || c + Vec3::new(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2), 0.0);
        let t = TriAccel::new(p(), p(), p());
        if t.normal().length_squared() > 0.0 {
            tris.push(t);
        }
    }
    tris
}

fn unit_dir(rng: &mut Rng) -> Vec3 {
    loop {
        let v = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let l = v.length_squared();
        if l > 1e-4 && l <= 1.0 {
            return v / l.sqrt();
        }
    }
}

/// Adversarial ray set over `accel`: random rays from outside and inside the grid, rays aimed
/// exactly at vertices and at points on edges, axis-parallel rays (also through vertices), rays
/// in cell-boundary planes and through grid corners, and rays that miss the grid. Directions are
/// not all normalised.
pub fn ray_set(accel: &Accel, n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed);
    let g = accel
        .grid()
        .expect("ray sets are drawn from a grid's cells (use AllAccels)");
    let b = g.bounds;
    let ext = b.extent();
    let big = Aabb {
        min: b.min - ext * 0.5,
        max: b.max + ext * 0.5,
    };
    let point_in = |bb: &Aabb, rng: &mut Rng| {
        Vec3::new(
            rng.range(bb.min.x, bb.max.x),
            rng.range(bb.min.y, bb.max.y),
            rng.range(bb.min.z, bb.max.z),
        )
    };
    let axes = [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z];
    let mut rays = Vec::with_capacity(n);
    while rays.len() < n {
        let kind = rays.len() % 9;
        let tri = &accel.tris[rng.below(accel.tris.len() as u32) as usize];
        let [v0, v1, v2] = tri.vertices();
        let ray = match kind {
            // Random origin around the grid (often outside it), random direction.
            0 => Ray::new(point_in(&big, &mut rng), unit_dir(&mut rng)),
            // Origin inside the grid.
            1 => Ray::new(point_in(&b, &mut rng), unit_dir(&mut rng) * rng.range(0.1, 10.0)),
            // Aimed exactly at a vertex.
            2 => {
                let o = point_in(&big, &mut rng);
                Ray::new(o, [v0, v1, v2][rng.below(3) as usize] - o)
            }
            // Aimed at a point on an edge.
            3 => {
                let o = point_in(&big, &mut rng);
                let (a, c) = [(v0, v1), (v1, v2), (v2, v0)][rng.below(3) as usize];
                let f = [0.5, 0.25, rng.next_f32()][rng.below(3) as usize];
                Ray::new(o, a + (c - a) * f - o)
            }
            // Axis-parallel, random origin.
            4 => Ray::new(point_in(&big, &mut rng), axes[rng.below(6) as usize]),
            // Axis-parallel through a vertex or an edge midpoint.
            5 => {
                let d = axes[rng.below(6) as usize];
                let target = [v0, v1, v2, (v0 + v1) * 0.5][rng.below(4) as usize];
                Ray::new(target - d * ext.max_element() * rng.range(0.1, 2.0), d)
            }
            // In a cell-boundary plane (origin on a boundary, direction within the plane).
            6 => {
                let axis = rng.below(3) as usize;
                let k = rng.below(g.dims[axis] + 1) as f32;
                let mut o = point_in(&big, &mut rng);
                o[axis] = b.min[axis] + k * g.cell_size[axis];
                let mut d = unit_dir(&mut rng);
                d[axis] = 0.0;
                if d.length_squared() == 0.0 {
                    d[(axis + 1) % 3] = 1.0;
                }
                Ray::new(o, d)
            }
            // Through a grid corner (a lattice point of cell corners).
            7 => {
                let corner = b.min
                    + Vec3::new(
                        rng.below(g.dims.x + 1) as f32,
                        rng.below(g.dims.y + 1) as f32,
                        rng.below(g.dims.z + 1) as f32,
                    ) * g.cell_size;
                let o = point_in(&big, &mut rng);
                Ray::new(o, corner - o)
            }
            // Misses: from outside, pointing away from the grid.
            _ => {
                let o = point_in(&big, &mut rng);
                let away = (o - b.center()).normalize_or(Vec3::X);
                let mut d = unit_dir(&mut rng);
                if d.dot(away) < 0.0 {
                    d = -d;
                }
                Ray::new(
                    b.center() + (o - b.center()).normalize_or(Vec3::X) * b.diagonal() * 2.0,
                    d,
                )
            }
        };
        if ray.dir.length_squared() > 0.0 && ray.dir.is_finite() {
            rays.push(ray);
        }
    }
    rays
}

/// A ray aimed exactly at a point of a mesh surface: a vertex, or a point on an edge shared by
/// two triangles. Whatever the origin (off the surface), the ray must hit something at
/// `t <= t_aim` (up to rounding): a miss, or a first hit beyond the aim point, is a ray that
/// slipped through the surface.
#[derive(Debug, Clone, Copy)]
pub struct AimedRay {
    pub ray: Ray,
    /// Ray parameter of the aim point.
    pub t_aim: f32,
}

/// Rays aimed at the shared edges and interior vertices of a mesh (`positions`, `triangles`:
/// the triangles the accel was built from), for watertightness tests. Only edges shared by
/// exactly two triangles are used, and only vertices all of whose edges are such (so open
/// meshes such as the Stanford Bunny are aimed at away from their holes). Ray kinds, in turn:
/// random origins around the grid; axis-parallel rays; rays lying in a cell-boundary plane
/// through the point where an edge crosses that plane; rays that start at a grid corner; rays
/// that pass through a grid corner. Only rays that cross the surface there are kept (the same
/// side of every face at the aim point, by more than 1e-4 in cosine): a ray that merely touches
/// a silhouette vertex or ridge edge is a graze, not a crossing.
pub fn edge_aimed_rays(
    accel: &Accel,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    n: usize,
    seed: u64,
) -> Vec<AimedRay> {
    use std::collections::HashMap;
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default().push(t as u32);
        }
    }
    let face_normal = |t: u32| {
        let [a, b, c] = triangles[t as usize].map(|i| positions[i as usize]);
        (b - a).cross(c - a).normalize_or_zero()
    };
    let mut vertex_ok = vec![true; positions.len()];
    let mut vertex_faces: Vec<Vec<u32>> = vec![Vec::new(); positions.len()];
    for (t, tri) in triangles.iter().enumerate() {
        for &i in tri {
            vertex_faces[i as usize].push(t as u32);
        }
    }
    let mut shared: Vec<((u32, u32), [u32; 2])> = Vec::new();
    for (&(a, b), faces) in &edges {
        if faces.len() == 2 {
            shared.push(((a, b), [faces[0], faces[1]]));
        } else {
            vertex_ok[a as usize] = false;
            vertex_ok[b as usize] = false;
        }
    }
    shared.sort_unstable();
    let vertices: Vec<u32> = (0..positions.len() as u32)
        .filter(|&i| vertex_ok[i as usize] && !vertex_faces[i as usize].is_empty())
        .collect();
    assert!(!shared.is_empty(), "mesh has no edge shared by two triangles");

    let mut rng = Rng::new(seed);
    let g = accel
        .grid()
        .expect("ray sets are drawn from a grid's cells (use AllAccels)");
    let b = g.bounds;
    let far = b.diagonal();
    let axes = [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z];
    let corner = |rng: &mut Rng| {
        b.min
            + Vec3::new(
                rng.below(g.dims.x + 1) as f32,
                rng.below(g.dims.y + 1) as f32,
                rng.below(g.dims.z + 1) as f32,
            ) * g.cell_size
    };
    let mut out = Vec::with_capacity(n);
    let mut i = 0usize;
    while out.len() < n {
        i += 1;
        let kind = i % 6;
        // The aim point and the faces that meet there.
        let on_vertex = !vertices.is_empty() && rng.below(3) == 0 && kind != 3;
        let (mut p, mut faces): (Vec3, Vec<u32>) = if on_vertex {
            let v = vertices[rng.below(vertices.len() as u32) as usize];
            (positions[v as usize], vertex_faces[v as usize].clone())
        } else {
            let ((a, c), f) = shared[rng.below(shared.len() as u32) as usize];
            let (pa, pc) = (positions[a as usize], positions[c as usize]);
            let t = [0.5, 0.25, rng.next_f32()][rng.below(3) as usize];
            (pa + (pc - pa) * t, f.to_vec())
        };
        let dir = match kind {
            // Random direction from a random origin around the scene.
            0 | 1 => {
                let o = b.center() + unit_dir(&mut rng) * far * rng.range(0.6, 1.5);
                p - o
            }
            // Axis-parallel.
            2 => axes[rng.below(6) as usize] * far,
            // In a cell-boundary plane: aim at the point where a shared edge crosses a boundary
            // plane, with a direction inside that plane (the origin is on the plane exactly).
            3 => {
                let ((a, c), f) = shared[rng.below(shared.len() as u32) as usize];
                let (pa, pc) = (positions[a as usize], positions[c as usize]);
                let axis = rng.below(3) as usize;
                let (lo, hi) = (pa[axis].min(pc[axis]), pa[axis].max(pc[axis]));
                let k0 = ((lo - b.min[axis]) / g.cell_size[axis]).ceil();
                let plane = b.min[axis] + k0 * g.cell_size[axis];
                if !(plane > lo && plane < hi) {
                    continue;
                }
                let s = (plane - pa[axis]) / (pc[axis] - pa[axis]);
                p = pa + (pc - pa) * s;
                p[axis] = plane;
                faces = f.to_vec();
                let mut d = unit_dir(&mut rng);
                d[axis] = 0.0;
                if d.length_squared() < 1e-6 {
                    continue;
                }
                d * far
            }
            // From a grid corner (kind 4) or through one (kind 5).
            _ => p - corner(&mut rng),
        };
        if dir.length_squared() == 0.0 || !dir.is_finite() {
            continue;
        }
        let dn = dir.normalize();
        // Only rays that cross the surface at the aim point: the same side of every face there
        // (consistently wound meshes). A ray that merely touches (a silhouette vertex or ridge
        // edge seen from the side) is a graze that rounding may decide either way.
        let crossing = |sign: f32| faces.iter().all(|&f| face_normal(f).dot(dn) * sign > 1e-4);
        if !(crossing(1.0) || crossing(-1.0)) {
            continue;
        }
        let (origin, t_aim) = match kind {
            4 => (p - dir, 1.0),
            5 => (p - dir * 2.0, 2.0),
            _ => (p - dir, 1.0),
        };
        out.push(AimedRay {
            ray: Ray::new(origin, dir),
            t_aim,
        });
    }
    out
}

/// One structure per traversal kind over the same triangles, for tests that compare them all:
/// the grid (serving `grid` and `pc`) and every other structure of the registry.
pub struct AllAccels {
    /// The uniform grid, serving `grid` (ray sets are drawn from its bounds).
    pub grid: Accel,
    /// The same grid serving `pc` (`Accel::set_traversal`).
    pc: Accel,
    /// Every other structure of the registry (`accel::registry::ENTRIES`), in its order, over
    /// the same triangles.
    pub others: Vec<Accel>,
}

impl AllAccels {
    pub fn build(tris: Vec<TriAccel>, resolution: Resolution) -> crate::Result<AllAccels> {
        let grid = Accel::from_grid(Grid::build(&tris, resolution)?, tris.clone());
        let pc = grid.clone().with_traversal(AccelKind::ProximityCloud)?;
        let mut others: Vec<Accel> = Vec::new();
        for kind in AccelKind::ALL.into_iter().filter(|k| !k.uses_grid()) {
            if !others.iter().any(|a| a.structure_id() == kind.structure()) {
                others.push(Accel::build(tris.clone(), kind, &AccelParams::NONE)?);
            }
        }
        Ok(AllAccels { grid, pc, others })
    }

    /// Every structure once, the grid (serving `grid`) first.
    pub fn all(&self) -> impl Iterator<Item = &Accel> {
        std::iter::once(&self.grid).chain(&self.others)
    }

    /// The structure serving `kind` (`Accel::kind`).
    pub fn get(&self, kind: AccelKind) -> &Accel {
        self.all()
            .chain(std::iter::once(&self.pc))
            .find(|a| a.kind() == kind)
            .expect("every kind has a structure")
    }
}

/// The rays on which GPU closest hits (`got`) and any hits (`occ`) disagree with brute force
/// (`want`), as `(bad, excused)`: `bad` the indices that disagree (hit or miss, or `t` beyond
/// rounding: the GPU compiler may fuse multiply-adds), `excused` how many disagree only
/// in hit-or-miss on a triangle's own boundary.
///
/// Why the excuse: the adversarial ray sets aim at edges and vertices, and where no neighbour
/// shares the edge (a lone triangle, a plane's rim) the watertight test's answer there is the
/// rounding of its inputs. The CPU decides an exactly-zero edge function in f64; WGSL has no
/// f64, and its f32 edge function rounds either way (docs/robustness.md): 89 of 20,000
/// edge-aimed rays on one triangle on lavapipe. Excused: the answer that hit has a barycentric
/// coordinate within 1e-5 of 0. Hits inside triangles must agree; leaks between neighbours are
/// tests/edges.rs's. Callers bound `excused` so that a walk missing every edge still fails.
pub fn gpu_disagreements(
    rays: &[Ray],
    want: &[crate::accel::Hit],
    got: &[crate::accel::Hit],
    occ: &[bool],
) -> (Vec<usize>, usize) {
    let (mut bad, mut excused) = (Vec::new(), 0);
    for (i, ((w, g), &o)) in want.iter().zip(got).zip(occ).enumerate() {
        let hit_or_miss_differs = w.is_hit() != g.is_hit() || o != w.is_hit();
        let t_agrees = !(w.is_hit() && g.is_hit()) || t_close(&rays[i], w.t, g.t);
        if !hit_or_miss_differs && t_agrees {
            continue;
        }
        if hit_or_miss_differs && t_agrees && (on_triangle_boundary(w) || on_triangle_boundary(g)) {
            excused += 1;
        } else {
            bad.push(i);
        }
    }
    (bad, excused)
}

/// Whether two answers' `t` for ray `r` agree as the CPU's and the GPU's triangle tests can:
/// within 1e-4 relative (the GPU compiler may fuse multiply-adds), or within 16 ulps of the
/// coordinates over the direction's length. The watertight test's t is a difference of sheared
/// depths, whose absolute rounding follows the coordinates' size, not t's: a ray starting 1e-4
/// from a triangle at 0.4 gets t = 1.1366e-4 on the CPU and 1.1364e-4 on the GPU.
pub fn t_close(r: &Ray, a: f32, b: f32) -> bool {
    let size = r
        .origin
        .abs()
        .max_element()
        .max((r.origin + a * r.dir).abs().max_element());
    a == b || (a - b).abs() <= (1e-4 * a.abs().max(b.abs())).max(16.0 * f32::EPSILON * size / r.dir.length())
}

/// Whether `h` is a hit with a barycentric coordinate within 1e-5 of 0: on its triangle's own
/// boundary, where the CPU's and the GPU's watertight tests may round either way
/// (`gpu_disagreements`).
pub fn on_triangle_boundary(h: &crate::accel::Hit) -> bool {
    h.is_hit() && h.u.min(h.v).min(1.0 - h.u - h.v) <= 1e-5
}

/// Whether the GPU tests are skipped knowingly (`GRIDTRACE_SKIP_GPU` set); says so when they
/// are. Without it they fail, not skip, when there is no adapter: a test that silently skips
/// proves nothing.
pub fn skip_gpu() -> bool {
    let s = std::env::var_os("GRIDTRACE_SKIP_GPU").is_some();
    if s {
        eprintln!("GRIDTRACE_SKIP_GPU is set: skipping");
    }
    s
}

/// Whether a GPU test runs `kind` on `ctx`: every kind with a GPU walk, but one that traces by
/// ray query (`hwrt`) only where the adapter has ray queries. Where it has none the kind is
/// left out with a note on stderr, except under `CI=1`: CI's lavapipe (Mesa 25) has them, so
/// there their absence panics, naming the adapter, rather than skipping `hwrt`'s tests.
pub fn gpu_runs(ctx: &crate::gpu::GpuContext, kind: AccelKind) -> bool {
    if !kind.entry().gpu {
        return false;
    }
    if ctx.ray_query || !crate::gpu::walks::needs_ray_queries(kind.structure()) {
        return true;
    }
    let why = ctx.check_ray_queries(kind.name()).unwrap_err();
    if std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "0" && v != "false") {
        panic!("CI=1: {why} (CI installs Mesa 25's lavapipe from bookworm-backports: .ci/run)");
    }
    eprintln!("{why}: its GPU tests are left out on this adapter");
    false
}

/// The kinds a GPU test runs on `ctx` (`gpu_runs`), in registry order.
pub fn gpu_kinds(ctx: &crate::gpu::GpuContext) -> Vec<AccelKind> {
    AccelKind::ALL.into_iter().filter(|&k| gpu_runs(ctx, k)).collect()
}

/// The triangles as vertex and face arrays (three vertices of its own per triangle).
pub fn soup_arrays(tris: &[TriAccel]) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let vertices = tris.iter().flat_map(|t| t.vertices().map(|v| v.to_array())).collect();
    let faces = (0..tris.len() as u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    (vertices, faces)
}

/// A strip a million units long and one wide, in `2 n` triangles, with a gentle wave so that
/// it is not planar: cells and boxes of every aspect.
pub fn long_strip(n: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut v = Vec::new();
    let mut f = Vec::new();
    for i in 0..=n {
        let x = 1e6 * i as f32 / n as f32;
        let z = (i as f32 * 0.37).sin() * 0.3;
        v.push([x, 0.0, z]);
        v.push([x, 1.0, -z]);
    }
    for i in 0..n {
        let a = 2 * i;
        f.push([a, a + 2, a + 1]);
        f.push([a + 1, a + 2, a + 3]);
    }
    (v, f)
}

/// The mesh traced with `accel` on the GPU; panics, naming the fix, without an adapter.
pub fn gpu_mesh(vertices: &[[f32; 3]], faces: &[[u32; 3]], accel: AccelKind) -> crate::query::TraceMesh {
    let opts = crate::query::QueryOptions {
        accel: accel.into(),
        backend: crate::Backend::Gpu,
        ..Default::default()
    };
    crate::query::TraceMesh::from_arrays(vertices, faces, &opts)
        .unwrap_or_else(|e| panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}"))
}

/// The image tests' tolerance measure (`render::differing_pixels`).
pub use crate::render::differing_pixels;

/// A ray of `near_miss_rays` and what the triangle test must answer for it.
#[derive(Debug, Clone, Copy)]
pub struct NearMiss {
    pub ray: Ray,
    /// Whether it must hit the unit triangle (aimed inside) or miss it (aimed outside).
    pub hits: bool,
    /// Where it must hit, when it starts on the triangle (`t = 0`).
    pub t: Option<f32>,
}

/// The unit right triangle (0,0,0), (1,0,0), (0,1,0) that `near_miss_rays` are aimed at.
pub fn unit_triangle() -> TriAccel {
    TriAccel::new(Vec3::ZERO, Vec3::X, Vec3::Y)
}

/// Rays at `unit_triangle` that a watertight test without slack answers exactly (issue: no
/// false hits):
/// - head-on (along the normal, from either side, 1 and 1e4 units away), aimed at points 19
///   fractions along each edge, outside by 1e-6 to 1e-3 (must miss) or inside by as much
///   (must hit);
/// - grazing the plane at 1e-3 rad, running along an edge, from 1 and 100 units back, aimed
///   1e-5 to 1e-3 outside (miss) or inside (hit). (A grazing ray that crosses an edge's line
///   passes within `gap * 1e-3` of the triangle, below the rounding of unit coordinates, so the
///   gap is taken across the ray's way);
/// - rays starting on the triangle (inside, on an edge, at a vertex), leaving either side:
///   hit at `t = 0`.
pub fn near_miss_rays() -> Vec<NearMiss> {
    let h = std::f32::consts::FRAC_1_SQRT_2;
    // Each edge: a point at fraction 0, its direction, the in-plane normal pointing out.
    let edges = [
        (Vec3::ZERO, Vec3::X, -Vec3::Y),
        (Vec3::ZERO, Vec3::Y, -Vec3::X),
        (Vec3::X, Vec3::new(-1.0, 1.0, 0.0), Vec3::new(h, h, 0.0)),
    ];
    // Points `gap` outside the edges (inside where negative), not at their ends, where an
    // inside point would be outside the next edge.
    let beside = |gap: f32| {
        edges.iter().flat_map(move |&(start, along, normal)| {
            (1..20).map(move |i| (start + along * (i as f32 / 20.0) + normal * gap, along))
        })
    };
    let mut out = Vec::new();
    for gap in [1e-6f32, 3e-6, 1e-5, 1e-4, 1e-3] {
        for away in [1.0, 1e4] {
            for side in [1.0, -1.0] {
                for (sign, hits) in [(1.0, false), (-1.0, true)] {
                    for (target, _) in beside(sign * gap) {
                        let ray = Ray::new(target + Vec3::Z * (side * away), Vec3::Z * -side);
                        out.push(NearMiss { ray, hits, t: None });
                    }
                }
            }
        }
    }
    let angle: f32 = 1e-3;
    for gap in [1e-5f32, 1e-4, 1e-3] {
        for away in [1.0, 100.0] {
            for (sign, hits) in [(1.0, false), (-1.0, true)] {
                for (target, along) in beside(sign * gap) {
                    let dir = along.normalize() * angle.cos() - Vec3::Z * angle.sin();
                    out.push(NearMiss {
                        ray: Ray::new(target - dir * away, dir),
                        hits,
                        t: None,
                    });
                }
            }
        }
    }
    for origin in [Vec3::new(0.25, 0.25, 0.0), Vec3::new(0.5, 0.0, 0.0), Vec3::ZERO] {
        for dir in [Vec3::new(0.1, 0.2, -1.0), Vec3::new(-0.3, 0.1, 1.0), Vec3::Z] {
            out.push(NearMiss {
                ray: Ray::new(origin, dir),
                hits: true,
                t: Some(0.0),
            });
        }
    }
    out
}
