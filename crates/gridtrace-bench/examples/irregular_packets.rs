//! Eye rays alone, no shading: each paper scene's 512 x 512 camera rays through the BVH one by
//! one, and through the irregular grid one by one, in packets of four (2x2 pixels, SSE; a
//! packet of eight as two of four, as CPUs without AVX2 run it) and of eight (4x2 pixels, AVX)
//! on one thread (best of 5, ms); every packet's hits are checked to equal the single rays': `cargo run --release -p gridtrace-bench --example irregular_packets`
//! (the mesh folder found as `gridtrace bench` finds it: `GRIDTRACE_DATA_DIR`, else
//! `shared/data/meshes` beside the checkout).
use gridtrace::accel::{AccelKind, Hit, NoCounters, PACKET, Ray, Structure};
use gridtrace::scene::CameraFrame;

/// The camera's rays block by block (`w` x `h` pixels, the renderer's order), and the pixel
/// each ray is for.
fn blocks(cam: &CameraFrame, size: u32, (w, h): (u32, u32)) -> (Vec<Ray>, Vec<usize>) {
    let (mut rays, mut pixel) = (Vec::new(), Vec::new());
    for by in (0..size).step_by(h as usize) {
        for bx in (0..size).step_by(w as usize) {
            for dy in 0..h {
                for dx in 0..w {
                    rays.push(cam.ray(bx + dx, by + dy));
                    pixel.push(((by + dy) * size + bx + dx) as usize);
                }
            }
        }
    }
    (rays, pixel)
}

/// The hits of packets, by pixel: eight rays in AVX registers, or (`fours`) as two packets of
/// four.
fn packets(
    g: &gridtrace::accel::IrregularGrid,
    tris: &[gridtrace::accel::TriAccel],
    (rays, pixel): &(Vec<Ray>, Vec<usize>),
    hits: &mut [Hit],
    fours: bool,
) {
    for (chunk, at) in rays.chunks(PACKET).zip(pixel.chunks(PACKET)) {
        let c = &mut [NoCounters; PACKET][..chunk.len()];
        let got = if fours {
            g.packet_in_fours::<false, _>(tris, chunk, c)
        } else {
            g.intersect_packet(tris, chunk, c)
        };
        for (k, &p) in at.iter().enumerate() {
            hits[p] = got[k];
        }
    }
}

fn main() -> gridtrace::Result<()> {
    let data = gridtrace_bench::scenes::find_data_dir(None);
    const SIZE: u32 = 512;
    for name in ["bunny", "knight", "torus-knot", "stanford-bunny"] {
        let scene = gridtrace_bench::scenes::build_paper_scene(name, data.as_deref())?.scene;
        let cam = scene.camera.frame(SIZE, SIZE);
        let eye = blocks(&cam, SIZE, (1, 1)).0;
        let (quads, octs) = (blocks(&cam, SIZE, (2, 2)), blocks(&cam, SIZE, (4, 2)));
        let n = eye.len();
        let bvh = scene.prepare_for(AccelKind::Bvh, &gridtrace::AccelParams::NONE)?;
        let mut want = vec![Hit::MISS; n];
        let bvh_ms = gridtrace_bench::best_of_ms(5, || {
            for (h, r) in want.iter_mut().zip(&eye) {
                *h = bvh.accel.intersect(r, &mut NoCounters);
            }
        });
        let prepared = scene.prepare_for(AccelKind::Irregular, &gridtrace::AccelParams::NONE)?;
        let accel = &prepared.accel;
        let Structure::Irregular(g) = &accel.structure else {
            unreachable!("an irregular grid was asked for")
        };
        let mut single = vec![Hit::MISS; n];
        let single_ms = gridtrace_bench::best_of_ms(5, || {
            for (h, r) in single.iter_mut().zip(&eye) {
                *h = accel.intersect(r, &mut NoCounters);
            }
        });
        let (mut four, mut eight) = (vec![Hit::MISS; n], vec![Hit::MISS; n]);
        let four_ms = gridtrace_bench::best_of_ms(5, || packets(g, &accel.tris, &quads, &mut four, true));
        let eight_ms = gridtrace_bench::best_of_ms(5, || packets(g, &accel.tris, &octs, &mut eight, false));
        assert_eq!(single, four, "{name}: packets of four differ from single rays");
        assert_eq!(single, eight, "{name}: packets of eight differ from single rays");
        println!(
            "{name:<15} bvh {bvh_ms:7.2} ms  irregular single {single_ms:7.2}  x4 {four_ms:7.2}  x8 {eight_ms:7.2} ms  \
             (x8/x4 {:.2}x, bvh/x8 {:.2}x)",
            four_ms / eight_ms,
            bvh_ms / eight_ms
        );
    }
    Ok(())
}
