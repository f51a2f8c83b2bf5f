//! The CPU BVH's quality on a mesh and ray files, in figures that do not depend on the
//! machine's load: the build time (best of 5), the wide tree's SAH cost (the expected node
//! visits and block tests of a ray through the root, the builder's own cost model), and per ray
//! file the nodes visited and triangles tested per ray by the single-ray walk, with a hash of
//! every answer (to check that a build change leaves them all the same) and, as a rough guide,
//! the single-thread batch rate (best of 3):
//! `cargo run --release -p gridtrace --example bvh_quality -- MESH RAYS...`
//! With `BVH_QUALITY_BATCH_ONLY=1`: one build, one batch pass per file, nothing else (to
//! count its instructions under a simulator: `valgrind --tool=cachegrind`).
//! With `BVH_QUALITY_CPU_TIME=N`: one build, then per file N batch passes, each timed by the
//! thread's CPU time rather than the wall clock, the best reported (on a machine shared with
//! other work, a pass's wall time counts the time the thread waited for a core; its CPU time
//! does not, though caches shared with the other work still disturb it).
//! (ray files as `gridtrace rays` reads them: float32 records ox oy oz dx dy dz).
use std::time::Instant;

use glam::Vec3;
use gridtrace::accel::bvh::{ChildRef, WIDTH};
use gridtrace::accel::{BvhAccel, Hit, Ray, TraversalCounters, TriAccel};

/// The wide tree's SAH cost relative to the root's surface area: a node visit costs
/// `node_cost`, a leaf `blocks` block tests (as `build.rs` counts them).
fn wide_sah(accel: &BvhAccel, node_cost: f64) -> f64 {
    let n = &accel.nodes[0];
    let area = |node: &gridtrace::accel::bvh::WideNode, k: usize| {
        let e: [f64; 3] = std::array::from_fn(|a| (node.planes[1][a][k] - node.planes[0][a][k]).max(0.0) as f64);
        e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
    };
    let root_area = {
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for k in 0..WIDTH {
            if n.planes[0][0][k] <= n.planes[1][0][k] {
                for a in 0..3 {
                    lo[a] = lo[a].min(n.planes[0][a][k] as f64);
                    hi[a] = hi[a].max(n.planes[1][a][k] as f64);
                }
            }
        }
        let e: [f64; 3] = std::array::from_fn(|a| hi[a] - lo[a]);
        e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
    };
    let mut cost = node_cost * root_area;
    let mut work = vec![0usize];
    while let Some(i) = work.pop() {
        let node = &accel.nodes[i];
        for k in 0..WIDTH {
            if node.planes[0][0][k] > node.planes[1][0][k] {
                continue;
            }
            let c: ChildRef = node.child[k];
            if c.count() == 0 {
                cost += node_cost * area(node, k);
                work.push(c.index() as usize);
            } else {
                cost += area(node, k) * c.count().div_ceil(4) as f64;
            }
        }
    }
    cost / root_area
}

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: bvh_quality MESH RAYS...");
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    let tris: Vec<TriAccel> = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            TriAccel::new(a, b, c)
        })
        .collect();
    let cpu_passes: Option<usize> = std::env::var("BVH_QUALITY_CPU_TIME")
        .ok()
        .map(|n| n.parse().expect("a number of passes"));
    let batch_only = std::env::var_os("BVH_QUALITY_BATCH_ONLY").is_some() || cpu_passes.is_some();
    let mut build_ms = f64::INFINITY;
    let mut accel = None;
    for _ in 0..if batch_only { 1 } else { 5 } {
        let t0 = Instant::now();
        let a = BvhAccel::build(&tris);
        build_ms = build_ms.min(t0.elapsed().as_secs_f64() * 1e3);
        accel = Some(a);
    }
    let accel = accel.expect("built");
    println!(
        "{path}: {} triangles; build {build_ms:.1} ms (best of 5, {} threads); {} wide nodes, {} blocks, depth {}; wide SAH {:.2} (node 0.5) / {:.2} (node 1)",
        tris.len(),
        rayon::current_num_threads(),
        accel.nodes.len(),
        accel.blocks.len(),
        accel.bvh.depth,
        wide_sah(&accel, 0.5),
        wide_sah(&accel, 1.0),
    );
    for file in &args[2..] {
        let bytes = std::fs::read(file).expect("a ray file");
        let f = |r: &[u8], k: usize| f32::from_le_bytes(r[4 * k..4 * k + 4].try_into().expect("4 bytes"));
        let rays: Vec<Ray> = bytes
            .chunks_exact(24)
            .map(|r| {
                Ray::new(
                    Vec3::new(f(r, 0), f(r, 1), f(r, 2)),
                    Vec3::new(f(r, 3), f(r, 4), f(r, 5)),
                )
            })
            .collect();
        if let Some(passes) = cpu_passes {
            let mut out = vec![Hit::MISS; rays.len()];
            let mut best_s = f64::INFINITY;
            for _ in 0..passes {
                let t0 = thread_cpu_seconds();
                accel.intersect_batch(&rays, &mut out);
                best_s = best_s.min(thread_cpu_seconds() - t0);
            }
            println!(
                "  {file}: {} rays, batch 1 thread {:.3} Mrays/s of CPU time (best of {passes})",
                rays.len(),
                rays.len() as f64 / best_s / 1e6
            );
            continue;
        }
        if batch_only {
            let mut out = vec![Hit::MISS; rays.len()];
            accel.intersect_batch(&rays, &mut out);
            println!("  {file}: {} hits", out.iter().filter(|h| h.is_hit()).count());
            continue;
        }
        let mut c = TraversalCounters::default();
        let mut hash = 0xcbf2_9ce4_8422_2325u64;
        let mut mix = |x: u32| {
            hash ^= x as u64;
            hash = hash.wrapping_mul(0x100_0000_01b3);
        };
        let mut single = Vec::with_capacity(rays.len());
        for r in &rays {
            let h = accel.intersect(r, &mut c);
            for x in [h.t.to_bits(), h.tri, h.u.to_bits(), h.v.to_bits()] {
                mix(x);
            }
            single.push(h);
        }
        let mut out = vec![Hit::MISS; rays.len()];
        let mut best_s = f64::INFINITY;
        for _ in 0..3 {
            let t0 = Instant::now();
            accel.intersect_batch(&rays, &mut out);
            best_s = best_s.min(t0.elapsed().as_secs_f64());
        }
        assert!(out == single, "the batch's answers differ from the single walk's");
        let mut one_s = f64::INFINITY;
        for _ in 0..3 {
            let t0 = Instant::now();
            for (r, o) in rays.iter().zip(out.iter_mut()) {
                *o = accel.intersect(r, &mut gridtrace::accel::NoCounters);
            }
            one_s = one_s.min(t0.elapsed().as_secs_f64());
        }
        let n = rays.len() as f64;
        println!(
            "  {file}: {} rays, {:.2} nodes/ray, {:.2} tris/ray, answers {hash:016x}; batch 1 thread {:.2} Mrays/s, one by one {:.2}",
            rays.len(),
            c.cells as f64 / n,
            c.tri_tests as f64 / n,
            n / best_s / 1e6,
            n / one_s / 1e6
        );
    }
    Ok(())
}

/// The calling thread's CPU time in seconds (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`).
#[cfg(target_os = "linux")]
fn thread_cpu_seconds() -> f64 {
    #[repr(C)]
    struct Timespec {
        sec: i64,
        nsec: i64,
    }
    unsafe extern "C" {
        fn clock_gettime(clock: i32, ts: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut ts = Timespec { sec: 0, nsec: 0 };
    // SAFETY: `ts` is a valid `struct timespec` (two 64-bit fields on 64-bit Linux).
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "clock_gettime");
    ts.sec as f64 + ts.nsec as f64 * 1e-9
}

/// Wall time where the thread's CPU time is not at hand.
#[cfg(not(target_os = "linux"))]
fn thread_cpu_seconds() -> f64 {
    use std::sync::OnceLock;
    static START: OnceLock<Instant> = OnceLock::new();
    START.get_or_init(Instant::now).elapsed().as_secs_f64()
}
