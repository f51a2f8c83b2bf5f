//! The grid built on the GPU agrees with the grid built on the CPU, in terms that hold on any
//! GPU: the same lattice; per cell the same triangles in the same order, except triangles that
//! touch the cell's boundary within rounding (a GPU that fuses multiply-adds rounds the overlap
//! test differently from the CPU, and naga emits no `NoContraction`); starts that are the
//! prefix sums of the GPU's own counts; distances that are the proximity transform of the GPU's
//! own occupancy. On lavapipe (no fused multiply-adds) the two are the same bit for bit, and
//! the tests say how many boundary triangles differed. On the built-in scenes, on the awkward inputs (a flat scene, a
//! strip a million times longer than wide, one triangle, many copies of one triangle, grids of
//! one cell and of over a million cells, which takes the scan three levels deep), and on random
//! meshes (a proptest). Also: a rebuild into the same buffers after the mesh moved, and a grid
//! over the device's limits is an error naming the limit.
//!
//! Fails, not skips, without an adapter (lavapipe in CI); GRIDTRACE_SKIP_GPU=1 skips knowingly.

use std::sync::{Arc, Mutex, OnceLock};

use glam::Vec3;
use gridtrace::accel::grid::proximity::chebyshev_distance_transform;
use gridtrace::accel::tri_box::triangle_overlaps_box;
use gridtrace::accel::{Grid, GridLattice, Resolution, TriAccel};
use gridtrace::gpu::walks::grid::build::{MAX_CELLS_PER_TRI, SORT_MAX_REFS};
use gridtrace::gpu::{GpuContext, GpuGrid};
use gridtrace::scene::builtin;
use gridtrace::testing::{flat_scene, long_strip, skip_gpu, triangle_soup};
use proptest::prelude::*;

/// One context for the whole file; GPU tests run one at a time (lavapipe shares the two cores).
fn ctx() -> Arc<GpuContext> {
    static CTX: OnceLock<Arc<GpuContext>> = OnceLock::new();
    CTX.get_or_init(|| Arc::new(GpuContext::new().expect("a GPU adapter (lavapipe in CI)")))
        .clone()
}
static GPU_LOCK: Mutex<()> = Mutex::new(());

/// Builds on both and compares everything the traversal reads.
fn assert_same_grid(tris: &[TriAccel], resolution: Resolution, what: &str) {
    let cpu = Grid::build(tris, resolution).unwrap();
    let (gpu, stats) = GpuGrid::build_from(ctx(), tris, resolution).unwrap();
    let references = compare(&cpu, &gpu, tris, what);
    assert_eq!(stats.dims, cpu.dims.to_array(), "{what}");
    assert_eq!(stats.references, references as u64, "{what}");
    assert!(stats.cpu_fallback.is_none(), "{what}: {:?}", stats.cpu_fallback);
}

/// How far (relative to the cell's half size) from a cell's boundary a triangle the two builds
/// disagree on may lie: rounding moves the overlap test's answer only for triangles that touch
/// the boundary (the test's own margin is far smaller than this).
const BOUNDARY_REL: f32 = 1e-3;

/// Whether `t` touches the boundary of the cell box (`center`, `half`) within `BOUNDARY_REL`:
/// it overlaps the box grown by it, and not the box shrunk by it.
fn on_boundary(t: &TriAccel, center: Vec3, half: Vec3) -> bool {
    let [a, b, c] = t.vertices();
    let grown = triangle_overlaps_box(center, half * (1.0 + BOUNDARY_REL), a, b, c);
    let shrunk = triangle_overlaps_box(center, half * (1.0 - BOUNDARY_REL), a, b, c);
    grown && !shrunk
}

/// The GPU's grid against the CPU's (see the file's docs), read back once; returns the GPU
/// grid's reference count.
fn compare(cpu: &Grid, gpu: &GpuGrid, tris: &[TriAccel], what: &str) -> usize {
    let lattice = gpu.lattice().expect("built");
    assert_eq!(lattice.dims, cpu.dims, "{what}: dims");
    assert_eq!(lattice.bounds, cpu.bounds, "{what}: bounds");
    let (cells, refs) = gpu.read_back().unwrap();
    assert_eq!(cells.len(), cpu.cells.len(), "{what}: cell count");
    let dims = lattice.dims;
    let mut start = 0u32;
    let mut differing = 0;
    for (i, (g, c)) in cells.iter().zip(&cpu.cells).enumerate() {
        if g.count > 0 {
            assert_eq!(
                g.start, start,
                "{what}: cell {i} start is not the prefix sum of the counts"
            );
        }
        start += g.count;
        let mut got = refs[g.start as usize..][..g.count as usize].to_vec();
        let want = &cpu.refs[c.start as usize..][..c.count as usize];
        // Cells over SORT_MAX_REFS keep the GPU's placing order: compare as sets.
        if g.count > SORT_MAX_REFS {
            got.sort_unstable();
        } else {
            assert!(
                got.windows(2).all(|w| w[0] < w[1]),
                "{what}: cell {i} not in triangle order"
            );
        }
        if got == want {
            continue;
        }
        let idx = glam::UVec3::new(
            i as u32 % dims.x,
            (i as u32 / dims.x) % dims.y,
            i as u32 / (dims.x * dims.y),
        );
        let half = lattice.cell_size * 0.5;
        let center = lattice.bounds.min + (idx.as_vec3() + 0.5) * lattice.cell_size;
        for t in symmetric_difference(&got, want) {
            assert!(
                on_boundary(&tris[t as usize], center, half),
                "{what}: cell {i}: triangle {t} is in one build's cell and not the other's, and not on its boundary"
            );
            differing += 1;
        }
    }
    assert_eq!(start as usize, refs.len(), "{what}: counts and references");
    // Rounding may move a few boundary triangles, never a real share of them.
    assert!(
        differing <= 8 + cpu.refs.len() / 1000,
        "{what}: {differing} boundary pairs differ"
    );
    let occupied: Vec<bool> = cells.iter().map(|c| c.count > 0).collect();
    let want_dist = chebyshev_distance_transform(dims.to_array(), &occupied);
    for (i, (g, d)) in cells.iter().zip(&want_dist).enumerate() {
        assert_eq!(
            g.dist, *d,
            "{what}: cell {i} distance is not the transform of the GPU's occupancy"
        );
    }
    if differing > 0 {
        eprintln!("{what}: {differing} boundary (cell, triangle) pairs differ from the CPU's");
    }
    refs.len()
}

/// The elements of two ascending lists that only one of them has.
fn symmetric_difference(a: &[u32], b: &[u32]) -> Vec<u32> {
    let mut out: Vec<u32> = a.iter().filter(|x| b.binary_search(x).is_err()).copied().collect();
    out.extend(b.iter().filter(|x| a.binary_search(x).is_err()));
    out
}

#[test]
fn builtin_scenes() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    for name in ["knot-box", "mirror-spheres", "sparse-room"] {
        let scene = builtin::scene(name).unwrap().prepare(Resolution::default()).unwrap();
        let tris = &scene.accel.tris;
        assert_same_grid(tris, Resolution::default(), name);
        assert_same_grid(tris, Resolution::Auto { lambda: 0.5 }, name);
        assert_same_grid(tris, Resolution::Fixed([7, 1, 13]), name);
    }
}

#[test]
fn awkward_inputs() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let soup = triangle_soup(3000, 5);
    assert_same_grid(&soup, Resolution::default(), "soup");
    assert_same_grid(&soup, Resolution::Fixed([1, 1, 1]), "soup in one cell");
    // Over a million cells: three scan levels, and long lines for the distance passes (small
    // triangles, each in a few of them).
    let mut rng = gridtrace::util::Rng::new(8);
    let small: Vec<TriAccel> = (0..4000)
        .map(|_| {
            let mut p = || Vec3::new(rng.range(0.0, 1.0), rng.range(0.0, 1.0), rng.range(0.0, 1.0));
            let c = p();
            TriAccel::new(c, c + p() * 0.02, c + p() * 0.02)
        })
        .collect();
    assert_same_grid(&small, Resolution::Fixed([160, 90, 80]), "small triangles, 1.15M cells");
    assert_same_grid(&flat_scene(2), Resolution::default(), "flat");
    let (v, f) = long_strip(2000);
    let strip: Vec<TriAccel> = f
        .iter()
        .map(|t| {
            TriAccel::new(
                Vec3::from(v[t[0] as usize]),
                Vec3::from(v[t[1] as usize]),
                Vec3::from(v[t[2] as usize]),
            )
        })
        .collect();
    assert_same_grid(&strip, Resolution::default(), "long strip");
    let one = TriAccel::new(Vec3::ZERO, Vec3::X, Vec3::Y);
    assert_same_grid(&[one], Resolution::default(), "one triangle");
    assert_same_grid(
        &vec![one; 500],
        Resolution::Fixed([4, 4, 4]),
        "500 copies of one triangle",
    );
    // A big triangle across a fine grid: one triangle in thousands of cells (under
    // MAX_CELLS_PER_TRI), and over it: that grid is built on the CPU, and says so.
    let big = TriAccel::new(Vec3::ZERO, Vec3::new(10.0, 0.5, 3.0), Vec3::new(2.0, 9.0, 7.0));
    assert_same_grid(&[big, one], Resolution::Fixed([25, 25, 25]), "big triangle");
    let res = Resolution::Fixed([40, 40, 40]);
    const { assert!(40 * 40 * 40 > MAX_CELLS_PER_TRI) };
    let (gpu, stats) = GpuGrid::build_from(ctx(), &[big, one], res).unwrap();
    let why = stats.cpu_fallback.expect("built on the CPU");
    assert!(why.contains("cells"), "{why}");
    compare(
        &Grid::build(&[big, one], res).unwrap(),
        &gpu,
        &[big, one],
        "big triangle, CPU fallback",
    );
}

/// The same `GpuGrid` rebuilt after every vertex moved: the buffers are reused (or grown) and
/// the result is again the CPU's grid of the moved mesh.
#[test]
fn rebuild_after_the_mesh_moves() {
    if skip_gpu() {
        return;
    }
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let ctx = ctx();
    let mut tris = triangle_soup(2000, 9);
    let mut gpu = GpuGrid::new(ctx.clone()).unwrap();
    for frame in 0..4 {
        let lattice = GridLattice::new(&tris, Resolution::default()).unwrap();
        let buf = wgpu::util::DeviceExt::create_buffer_init(
            &ctx.device,
            &wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytemuck::cast_slice(&gridtrace::gpu::layout::GpuTri::all(&tris)),
                usage: wgpu::BufferUsages::STORAGE,
            },
        );
        let stats = gpu.build(&buf, &tris, &lattice).unwrap();
        let cpu = Grid::build(&tris, Resolution::default()).unwrap();
        let references = compare(&cpu, &gpu, &tris, &format!("frame {frame}"));
        assert_eq!(stats.references, references as u64);
        // Stretch and twist: the grid's bounds, dimensions and references all change.
        let s = 1.0 + 0.4 * frame as f32;
        for t in &mut tris {
            let [a, b, c] = t.vertices().map(|p| {
                let (sn, cs) = (p.y * 0.3).sin_cos();
                Vec3::new(s * (p.x * cs - p.z * sn), p.y, p.x * sn + p.z * cs)
            });
            *t = TriAccel::new(a, b, c);
        }
    }
}

fn vec3() -> impl Strategy<Value = Vec3> {
    (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
    /// Random meshes over a shared vertex pool (shared edges and vertices, cell faces hit
    /// exactly), at the automatic resolution or a random fixed one.
    #[test]
    fn random_meshes(
        pool in prop::collection::vec(vec3(), 3..40),
        idx in prop::collection::vec((0usize..64, 0usize..64, 0usize..64), 1..200),
        scale in prop_oneof![Just(1.0f32), Just(1e-3), Just(1e4)],
        fixed in prop::option::of((1u32..20, 1u32..20, 1u32..20)),
    ) {
        if skip_gpu() {
            return Ok(());
        }
        let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
        let n = pool.len();
        let tris: Vec<TriAccel> = idx
            .iter()
            .map(|&(a, b, c)| TriAccel::new(pool[a % n] * scale, pool[b % n] * scale, pool[c % n] * scale))
            .collect();
        let res = fixed.map_or(Resolution::default(), |(a, b, c)| Resolution::Fixed([a, b, c]));
        assert_same_grid(&tris, res, "random mesh");
    }
}
