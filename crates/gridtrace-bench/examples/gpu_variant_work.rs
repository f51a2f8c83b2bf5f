//! Work per ray of the BVH's two GPU layouts (`--gpu-variant bvh=binary|wide8`), counted by the
//! CPU copies of their GPU walks (`gpu::bvh::walk`, `gpu::walks::bvh::wide8::walk`), which take
//! the same steps as the WGSL: nodes whose boxes are tested, whole-node fetches, group reads
//! (the wide walk reads 20 bytes of a node again when it pops a group of it), triangle tests,
//! and the bytes those read from each layout. What a hardware run's timings can be read against; no timing here.
//!
//!     cargo run --release -p gridtrace-bench --example gpu_variant_work -- [MESH] [RES] [RAYS]
//!
//! MESH defaults to the Stanford Bunny (../shared/data/meshes/bunny/bun_zipper.ply), RES (the
//! camera rays' image side) to 256, RAYS (incoherent rays, `query_study::incoherent_rays`) to
//! 65,536. The other variants (stack, order, appends, stats, checks) do the same work per ray.

use gridtrace::AccelParams;
use std::path::PathBuf;

use gridtrace::accel::{AccelKind, Hit, Ray, Structure, TraversalCounters};
use gridtrace::gpu::layout::GpuTri;
use gridtrace::gpu::walks::bvh::binary::GpuBvhNode;
use gridtrace::gpu::walks::bvh::wide8::GpuBvh8Node;
use gridtrace::gpu::walks::bvh::wide8::{self, Wide8, Wide8Work};
use rayon::prelude::*;

/// Bytes a triangle test reads: its 48-byte record (`GpuTri`), stored in leaf order (the
/// 4-byte reference is read only for a hit, left out here).
const TRI_BYTES: u64 = std::mem::size_of::<GpuTri>() as u64;

#[derive(Default, Clone, Copy)]
struct Work {
    counters: TraversalCounters,
    /// Whole-node reads.
    fetches: u64,
    /// Popped groups' partial reads (wide8: `GROUP_READ_BYTES` each; the binary walk has none).
    group_reads: u64,
}

fn sum(a: Work, b: Work) -> Work {
    Work {
        counters: TraversalCounters {
            cells: a.counters.cells + b.counters.cells,
            jumps: 0,
            tri_tests: a.counters.tri_tests + b.counters.tri_tests,
        },
        fetches: a.fetches + b.fetches,
        group_reads: a.group_reads + b.group_reads,
    }
}

fn row(label: &str, rays: usize, node_bytes: u64, w: Work) {
    let per = |x: u64| x as f64 / rays as f64;
    let node_b = per(w.fetches * node_bytes + w.group_reads * wide8::GROUP_READ_BYTES);
    let tri_b = per(w.counters.tri_tests * TRI_BYTES);
    println!(
        "| {label} | {:.1} | {:.1} | {:.1} | {:.1} | {:.0} | {:.0} | {:.0} |",
        per(w.counters.cells),
        per(w.fetches),
        per(w.group_reads),
        per(w.counters.tri_tests),
        node_b,
        tri_b,
        node_b + tri_b
    );
}

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let mesh = args
        .get(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("../shared/data/meshes/bunny/bun_zipper.ply"));
    let res: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(256);
    let n_incoherent: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(65_536);
    let scene = gridtrace::scene::builtin::mesh_scene(gridtrace::io::load_mesh(&mesh)?, false);
    let prepared = scene.prepare_for(AccelKind::Bvh, &AccelParams::NONE)?;
    let Structure::Bvh(b) = &prepared.accel.structure else {
        unreachable!("prepared for the BVH")
    };
    let tris = &prepared.accel.tris;
    let binary = gridtrace::gpu::bvh::gpu_nodes(&b.bvh)?;
    let wide = Wide8::build(b)?;
    println!(
        "mesh {}: {} triangles; binary {} nodes x {} B = {:.2} MB, wide8 {} nodes x {} B = {:.2} MB",
        mesh.display(),
        tris.len(),
        binary.len(),
        size_of::<GpuBvhNode>(),
        (binary.len() * size_of::<GpuBvhNode>()) as f64 / 1e6,
        wide.nodes.len(),
        size_of::<GpuBvh8Node>(),
        (wide.nodes.len() * size_of::<GpuBvh8Node>()) as f64 / 1e6
    );
    let frame = prepared.camera.frame(res, res);
    let camera: Vec<Ray> = (0..res * res).map(|i| frame.ray(i % res, i / res)).collect();
    let (o, d) = gridtrace_bench::query_study::incoherent_rays(prepared.accel.bounds(), n_incoherent, 7);
    let incoherent: Vec<Ray> = o
        .iter()
        .zip(&d)
        .map(|(o, d)| Ray::new((*o).into(), (*d).into()))
        .collect();
    println!(
        "\n| rays, layout | nodes tested / ray | node fetches / ray | group reads / ray | triangle tests / ray | node bytes / ray | triangle bytes / ray | bytes / ray |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    for (name, rays) in [
        (format!("camera {res}x{res}"), &camera),
        (format!("incoherent {n_incoherent}"), &incoherent),
    ] {
        let walk_binary = |r: &Ray, any: bool| {
            let mut c = TraversalCounters::default();
            let h = if any {
                gridtrace::gpu::bvh::walk::<true, _>(&binary, &b.bvh.prims, tris, r, 0.0, f32::INFINITY, &mut c)
            } else {
                gridtrace::gpu::bvh::walk::<false, _>(&binary, &b.bvh.prims, tris, r, 0.0, f32::INFINITY, &mut c)
            };
            // Every node the binary walk tests it fetches once (a pop hands over the child's entry).
            (
                h,
                Work {
                    counters: c,
                    fetches: c.cells,
                    group_reads: 0,
                },
            )
        };
        let walk_wide = |r: &Ray, any: bool| {
            let (mut c, mut w) = (TraversalCounters::default(), Wide8Work::default());
            let h = if any {
                wide8::walk::<true, _>(&wide, tris, r, 0.0, f32::INFINITY, &mut c, &mut w)
            } else {
                wide8::walk::<false, _>(&wide, tris, r, 0.0, f32::INFINITY, &mut c, &mut w)
            };
            (
                h,
                Work {
                    counters: c,
                    fetches: w.node_fetches,
                    group_reads: w.group_reads,
                },
            )
        };
        for any in [false, true] {
            let results: Vec<((Hit, Work), (Hit, Work))> = rays
                .par_iter()
                .map(|r| (walk_binary(r, any), walk_wide(r, any)))
                .collect();
            // Any hit keeps the first hit found, which the visiting order decides: compare
            // hit or miss only there.
            let differ = results
                .iter()
                .filter(|(a, b)| a.0.is_hit() != b.0.is_hit() || (!any && a.0.t != b.0.t))
                .count();
            let hits = results.iter().filter(|(a, _)| a.0.is_hit()).count();
            let (wb, ww) = results
                .iter()
                .fold((Work::default(), Work::default()), |(x, y), (a, b)| {
                    (sum(x, a.1), sum(y, b.1))
                });
            let q = if any { "any hit" } else { "closest" };
            row(
                &format!("{name} {q}, binary"),
                rays.len(),
                size_of::<GpuBvhNode>() as u64,
                wb,
            );
            row(
                &format!("{name} {q}, wide8"),
                rays.len(),
                size_of::<GpuBvh8Node>() as u64,
                ww,
            );
            eprintln!(
                "{name} {q}: {hits} of {} rays hit; {differ} differ in hit or t between the layouts",
                rays.len()
            );
        }
    }
    Ok(())
}
