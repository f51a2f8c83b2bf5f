//! Eye rays alone, no shading: each paper scene's 512 x 512 camera rays traced one by one and in
//! 2x2 packets (`Accel::intersect_packet`), through the BVH and the irregular grid, on one
//! thread (best of 5, ms); the packets' hits are checked to equal the single rays':
//! `cargo run --release -p gridtrace-bench --example irregular_packets`
//! (the mesh folder from `GRIDTRACE_DATA_DIR` or `../shared/data/meshes`).
use gridtrace::accel::{AccelKind, Hit, IrregularParams, NoCounters, PACKET, Resolution};

fn main() -> gridtrace::Result<()> {
    let data = std::env::var_os("GRIDTRACE_DATA_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| "../shared/data/meshes".into());
    for name in ["bunny", "knight", "torus-knot", "stanford-bunny"] {
        let scene = gridtrace_bench::scenes::build_paper_scene(name, Some(&data))?.scene;
        let cam = scene.camera.frame(512, 512);
        // In the renderer's order: 2x2 blocks, each block's four rays together.
        let mut eye = Vec::new();
        for by in (0..512).step_by(2) {
            for bx in (0..512).step_by(2) {
                for (dy, dx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                    eye.push(cam.ray(bx + dx, by + dy));
                }
            }
        }
        let mut line = format!("{name:<15}");
        for kind in [AccelKind::Bvh, AccelKind::Irregular] {
            let prepared = scene.prepare_with(kind, Resolution::default(), IrregularParams::default())?;
            let accel = &prepared.accel;
            let (mut single_ms, mut packet_ms) = (f64::INFINITY, f64::INFINITY);
            let mut single = vec![Hit::MISS; eye.len()];
            let mut packets = vec![Hit::MISS; eye.len()];
            for _ in 0..5 {
                let t0 = std::time::Instant::now();
                for (h, r) in single.iter_mut().zip(&eye) {
                    *h = accel.intersect(r, 0.0, f32::INFINITY, kind, &mut NoCounters);
                }
                single_ms = single_ms.min(t0.elapsed().as_secs_f64() * 1e3);
                let t0 = std::time::Instant::now();
                for (hits, rays) in packets.chunks_mut(PACKET).zip(eye.chunks(PACKET)) {
                    let mut c = [NoCounters; PACKET];
                    let got = accel.intersect_packet(rays, 0.0, f32::INFINITY, kind, &mut c[..rays.len()]);
                    hits.copy_from_slice(&got[..rays.len()]);
                }
                packet_ms = packet_ms.min(t0.elapsed().as_secs_f64() * 1e3);
            }
            assert_eq!(
                single,
                packets,
                "{name} {}: packets differ from single rays",
                kind.name()
            );
            line += &format!(
                "  {:<9} single {single_ms:7.2} ms  packets {packet_ms:7.2} ms ({:.2}x)",
                kind.name(),
                single_ms / packet_ms
            );
        }
        println!("{line}");
    }
    Ok(())
}
