//! Batch queries of coherent rays (what Python's `Mesh.intersect` and `Mesh.occluded` run on
//! each thread's chunk), one thread, best of 5, ms: each paper scene's 512 x 512 camera rays in
//! row order through `Accel::intersect_batch`, then the shadow rays from their hits towards
//! the scene's first light through `Accel::occluded_batch`; the BVH and the irregular grid,
//! their answers checked to agree:
//! `cargo run --release -p gridtrace-bench --example irregular_batches`
//! (the mesh folder found as `gridtrace bench` finds it: `GRIDTRACE_DATA_DIR`, else
//! `shared/data/meshes` beside the checkout).
use gridtrace::accel::{AccelKind, Hit, Ray};

fn main() -> gridtrace::Result<()> {
    let data = gridtrace_bench::scenes::find_data_dir(None);
    const SIZE: u32 = 512;
    for name in ["bunny", "knight", "torus-knot", "stanford-bunny"] {
        let scene = gridtrace_bench::scenes::build_paper_scene(name, data.as_deref())?.scene;
        let cam = scene.camera.frame(SIZE, SIZE);
        let eye: Vec<Ray> = (0..SIZE * SIZE).map(|p| cam.ray(p % SIZE, p / SIZE)).collect();
        let light = glam::Vec3::from(scene.lights[0].position);
        let mut line = format!("{name:<15}");
        let mut answers = Vec::new();
        for kind in [AccelKind::Bvh, AccelKind::Irregular] {
            let prepared = scene.prepare_for(kind, &gridtrace::AccelParams::NONE)?;
            let accel = &prepared.accel;
            let mut hits = vec![Hit::MISS; eye.len()];
            let eye_ms = gridtrace_bench::best_of_ms(5, || accel.intersect_batch(&eye, &mut hits));
            // From just off each hit towards the light, in image order.
            let shadow: Vec<Ray> = eye
                .iter()
                .zip(&hits)
                .filter(|(_, h)| h.is_hit())
                .map(|(r, h)| {
                    let p = r.at(h.t * 0.999);
                    Ray::new(p, (light - p).normalize()).within(0.0, 1e30)
                })
                .collect();
            let mut occluded = vec![false; shadow.len()];
            let shadow_ms = gridtrace_bench::best_of_ms(5, || accel.occluded_batch(&shadow, &mut occluded));
            line += &format!("  {:<9} camera {eye_ms:7.2} ms  shadow {shadow_ms:7.2} ms", kind.name());
            answers.push((hits.iter().map(|h| h.t).collect::<Vec<_>>(), occluded));
        }
        let (bvh, irr) = (&answers[0], &answers[1]);
        let far = bvh
            .0
            .iter()
            .zip(&irr.0)
            .filter(|(a, b)| (*a - *b).abs() > 1e-5 * a.abs())
            .count();
        assert_eq!(far, 0, "{name}: the structures' camera hits are at other distances");
        println!("{line}");
    }
    Ok(())
}
