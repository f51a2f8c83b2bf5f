//! Camera-ray renders (512 x 512, best of 5 after one counted run) of the paper's scenes
//! through the irregular grid with each parameter set given, beside the BVH, with the work per
//! ray and the structure's bytes per triangle:
//! `cargo run --release -p gridtrace-bench --example irregular_render_params -- [cast|shadow|trace] [PARAMS ...]`
//! (each `PARAMS` as `--irregular` spells them, `""` for the defaults; the mesh folder found
//! as `gridtrace bench` finds it: `GRIDTRACE_DATA_DIR`, else `shared/data/meshes` beside the
//! checkout).
use gridtrace::accel::{AccelKind, IrregularParams};
use gridtrace::render::{Mode, RenderOptions};

fn main() -> gridtrace::Result<()> {
    let data = gridtrace_bench::scenes::find_data_dir(None);
    let mode = match std::env::args().nth(1).as_deref() {
        Some("shadow") => Mode::Shadow,
        Some("trace") => Mode::Trace,
        _ => Mode::Cast,
    };
    let mut sets: Vec<String> = std::env::args().skip(2).collect();
    if sets.is_empty() {
        sets.push(String::new());
    }
    for name in ["bunny", "knight", "torus-knot", "stanford-bunny"] {
        let scene = gridtrace_bench::scenes::build_paper_scene(name, data.as_deref())?.scene;
        let runs = std::iter::once((AccelKind::Bvh, String::new()))
            .chain(sets.iter().map(|s| (AccelKind::Irregular, s.clone())));
        for (kind, set) in runs {
            let params: IrregularParams = set.parse().map_err(gridtrace::Error::InvalidInput)?;
            let prepared = scene.prepare_for(kind, &params.to_params())?;
            let opts = RenderOptions {
                width: 512,
                height: 512,
                mode,
                ablation: Default::default(),
                rows: None,
                pixels: Default::default(),
            };
            let (_, stats) = gridtrace::cpu::render_with_counters(&prepared, &scene.camera, &scene.lights, &opts)?;
            let rays = stats.rays.total() as f64;
            let mut best = f64::INFINITY;
            for _ in 0..5 {
                let t0 = std::time::Instant::now();
                gridtrace::cpu::render_view(&prepared, &scene.camera, &scene.lights, &opts, None)?;
                best = best.min(t0.elapsed().as_secs_f64() * 1e3);
            }
            let extra = prepared.accel.irregular().map_or(String::new(), |g| {
                format!(
                    "{:6.1} B/tri, build {:.1} ms",
                    g.bytes() as f64 / g.stats.triangles as f64,
                    g.stats.build_ms()
                )
            });
            println!(
                "{name:<15} {:<10} {set:<24} {best:8.2} ms  steps {:6.2} tests {:6.2} per ray  {extra}",
                kind.name(),
                stats.counters.cells as f64 / rays,
                stats.counters.tri_tests as f64 / rays,
            );
        }
    }
    Ok(())
}
