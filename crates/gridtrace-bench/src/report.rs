//! Writing a benchmark report: `bench.json` (everything), `bench.csv` (one line per matrix row)
//! and `bench.md` (tables laid out like the paper's Tables 1-3, then the studies).

use gridtrace::accel::dims_str;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::{BenchBackend, BenchReport, Row, SceneInfo};
use gridtrace::{Error, Result};

const MODES: [(&str, &str); 3] = [
    ("cast", "Table 1: ray casting (eye rays only)"),
    ("shadow", "Table 2: shadow casting (eye and shadow rays)"),
    ("trace", "Table 3: ray tracing (eye, shadow and reflection rays)"),
];

fn write(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).map_err(|e| Error::io(path, e))
}

/// Writes `bench.json`, `bench.csv` and `bench.md` into `dir`; returns their paths.
pub fn write_reports(report: &BenchReport, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let json = serde_json::to_string_pretty(report).map_err(|e| Error::InvalidInput(format!("JSON: {e}")))?;
    let paths = [dir.join("bench.json"), dir.join("bench.csv"), dir.join("bench.md")];
    write(&paths[0], &json)?;
    write(&paths[1], &csv(&report.matrix.rows))?;
    write(&paths[2], &markdown(report))?;
    Ok(paths.to_vec())
}

pub const CSV_HEADER: &str = "scene,backend,mode,accel,width,height,grid,reps,best_ms,median_ms,mean_ms,eye_rays,shadow_rays,reflection_rays,total_rays,mrays_per_s,paper_ms,speedup,gpu_wall_ms,gpu_ms,gpu_round_trips,gpu_bytes_up,gpu_bytes_down,raygen_ms,indirect_ms,traverse_ms,shade_ms,occlusion_ms,resolve_ms,host_prepare_ms,host_wait_ms,host_readout_ms";

/// The GPU stages that get a CSV column each (`*_ms`), in kernel order.
const CSV_STAGES: [&str; 6] = ["raygen", "indirect", "traverse", "shade", "occlusion", "resolve"];

pub fn csv(rows: &[Row]) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{:.4},{:.4},{:.4},{},{},{},{},{:.4},{},{},{},{},{},{},{},{},{},{},{}",
            r.scene,
            r.backend.name(),
            r.mode,
            r.accel,
            r.width,
            r.height,
            dims_str(r.grid_dims),
            r.times_ms.len(),
            r.summary.best_ms,
            r.summary.median_ms,
            r.summary.mean_ms,
            r.rays.eye,
            r.rays.shadow,
            r.rays.reflection,
            r.rays.total,
            r.mrays_per_s,
            opt(r.paper_ms),
            opt(r.speedup),
            opt(r.gpu_wall_ms),
            opt(r.gpu_ms),
            r.gpu_round_trips.map_or(String::new(), |n| n.to_string()),
            r.gpu_bytes_up.map_or(String::new(), |n| n.to_string()),
            r.gpu_bytes_down.map_or(String::new(), |n| n.to_string()),
            CSV_STAGES
                .iter()
                .map(|k| opt(r.gpu_stages_ms.as_ref().and_then(|m| m.get(*k).copied())))
                .collect::<Vec<_>>()
                .join(","),
            opt(r.gpu_host_prepare_ms),
            opt(r.gpu_host_wait_ms),
            opt(r.gpu_host_readout_ms),
        );
    }
    s
}

fn bytes(b: u64) -> String {
    if b >= 1 << 20 {
        format!("{:.2} MiB", b as f64 / (1u64 << 20) as f64)
    } else if b >= 1 << 10 {
        format!("{:.1} KiB", b as f64 / 1024.0)
    } else {
        format!("{b} B")
    }
}

fn scene_header(s: &SceneInfo) -> String {
    match s.paper_triangles {
        Some(p) => format!("{} n = {} (paper {})", s.title, s.triangles_traced, p),
        None => format!("{} n = {}", s.title, s.triangles_traced),
    }
}

/// The paper-style tables: one per mode and backend, rows the resolutions, for each scene a g
/// and a pc column; each cell `ours / paper (speed-up)` in ms, speed-up = paper ms / our ms.
fn paper_tables(md: &mut String, report: &BenchReport) {
    let rows = &report.matrix.rows;
    let scenes = &report.matrix.scenes;
    let accels = &report.config.accels;
    for backend in [BenchBackend::Cpu, BenchBackend::Gpu] {
        if !rows.iter().any(|r| r.backend == backend) {
            continue;
        }
        for (mode, title) in MODES {
            if !rows.iter().any(|r| r.backend == backend && r.mode == mode) {
                continue;
            }
            let _ = writeln!(md, "### {title}, {} backend\n", backend.name());
            md.push_str("| rendering resolution |");
            for s in scenes {
                for a in accels {
                    let _ = write!(md, " {} {} |", scene_header(s), if a == "grid" { "g" } else { a });
                }
            }
            md.push_str("\n|---|");
            for _ in 0..scenes.len() * accels.len() {
                md.push_str("---:|");
            }
            md.push('\n');
            for &[w, h] in &report.config.resolutions {
                let _ = write!(md, "| {w} x {h} |");
                for s in scenes {
                    for a in accels {
                        let r = rows.iter().find(|r| {
                            r.backend == backend
                                && r.mode == mode
                                && &r.accel == a
                                && r.scene == s.name
                                && r.width == w
                                && r.height == h
                        });
                        let cell = match r {
                            None => "-".to_string(),
                            Some(r) => match (r.paper_ms, r.speedup) {
                                (Some(p), Some(x)) => format!("{:.1} / {p:.0} ({x:.1}x)", r.summary.best_ms),
                                _ => format!("{:.1} / -", r.summary.best_ms),
                            },
                        };
                        let _ = write!(md, " {cell} |");
                    }
                }
                md.push('\n');
            }
            md.push('\n');
        }
    }
}

pub fn markdown(report: &BenchReport) -> String {
    let mut md = String::new();
    let m = &report.machine;
    let _ = writeln!(md, "# gridtrace bench\n");
    let _ = writeln!(md, "- gridtrace {}", report.gridtrace_version);
    let _ = writeln!(md, "- command: `{}`", report.command_line.join(" "));
    let _ = writeln!(
        md,
        "- CPU: {} ({} logical cores, {} threads)",
        m.cpu_model, m.logical_cores, m.threads
    );
    let _ = writeln!(md, "- OS: {}", m.os);
    match &m.adapter {
        Some(a) => {
            let sw = if m.adapter_is_software == Some(true) {
                " (software adapter: CPU speed)"
            } else {
                ""
            };
            let _ = writeln!(md, "- GPU adapter: {a}{sw}");
        }
        None => {
            let _ = writeln!(md, "- GPU adapter: none used");
        }
    }
    let c = &report.config;
    let _ = writeln!(
        md,
        "- {} warm-up run(s), {} timed repetition(s) per cell; grid: {}",
        c.warmup,
        c.reps,
        if c.paper_grids {
            "the paper's dims".to_string()
        } else {
            c.grid.clone()
        }
    );
    let _ = writeln!(md, "- mesh data: {}\n", c.data_dir.as_deref().unwrap_or("not found"));
    for s in &report.matrix.skipped {
        let _ = writeln!(md, "- **{s}**");
    }

    scenes_section(&mut md, report);
    md.push_str("\n## Times like the paper's Tables 1-3\n\n");
    md.push_str("Each cell: our best time / the paper's time in ms (speed-up = paper ms / our ms). The paper: GeForce 6800GT, best of several runs.\n\n");
    paper_tables(&mut md, report);

    memory_section(&mut md, report);
    gpu_frames_section(&mut md, report);
    grid_sweep_section(&mut md, report);
    scaling_section(&mut md, report);
    build_scaling_section(&mut md, report);
    pc_study_section(&mut md, report);
    query_study_section(&mut md, report);
    irregular_sweep_section(&mut md, report);
    ablation_section(&mut md, report);
    ray_export_section(&mut md, report);
    md
}

/// The scenes that ran: size, grid, build.
fn scenes_section(md: &mut String, report: &BenchReport) {
    md.push_str("## Scenes\n\n| scene | triangles | traced | paper | grid | cells | empty | refs/tri | build ms | made of |\n|---|---:|---:|---:|---|---:|---:|---:|---:|---|\n");
    for s in &report.matrix.scenes {
        let g = &s.grid;
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} ({}) | {} | {:.1}% | {:.2} | {:.1} | {} |",
            s.title,
            s.triangles,
            s.triangles_traced,
            s.paper_triangles.map_or("-".into(), |n| n.to_string()),
            dims_str(g.dims),
            g.choice,
            g.cells,
            100.0 * g.empty_cells as f64 / g.cells.max(1) as f64,
            g.refs_per_triangle,
            g.build_ms,
            s.description
        );
    }
}

/// Every array's bytes beside the paper's memory model.
fn memory_section(md: &mut String, report: &BenchReport) {
    md.push_str("## Memory\n\nBytes of every array, beside the paper's model M = n*96 + cells*16.\n\n");
    md.push_str(
        "| scene | CPU arrays | CPU total | GPU buffers | GPU total | paper model |\n|---|---|---:|---|---:|---:|\n",
    );
    for s in &report.matrix.scenes {
        let list = |m: &std::collections::BTreeMap<String, u64>| {
            m.iter()
                .map(|(k, v)| format!("{k} {}", bytes(*v)))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} |",
            s.title,
            list(&s.memory_cpu),
            bytes(s.memory_cpu_total),
            s.memory_gpu.as_ref().map_or("-".into(), list),
            s.memory_gpu_total.map_or("-".into(), bytes),
            bytes(s.memory_paper_model)
        );
    }
}

/// The GPU rows' best frames: wall time beside GPU time, round trips and bytes each way.
fn gpu_frames_section(md: &mut String, report: &BenchReport) {
    let rows: Vec<_> = report.matrix.rows.iter().filter(|r| r.gpu_wall_ms.is_some()).collect();
    if rows.is_empty() {
        return;
    }
    md.push_str("\n## GPU frames (best repetition)\n\nWall: the host's clock from the first upload to the image in host memory (the tables' times). GPU: the stages' timestamps summed. Their difference is submission, readback and host work.\n\n| scene | mode | accel | size | wall ms | GPU ms | round trips | bytes up | bytes down |\n|---|---|---|---|---:|---:|---:|---:|---:|\n");
    let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {}x{} | {} | {} | {} | {} | {} |",
            r.scene,
            r.mode,
            r.accel,
            r.width,
            r.height,
            opt(r.gpu_wall_ms),
            opt(r.gpu_ms),
            r.gpu_round_trips.unwrap_or(0),
            r.gpu_bytes_up.map_or("-".into(), bytes),
            r.gpu_bytes_down.map_or("-".into(), bytes)
        );
    }
}

/// `--sweep-grid`.
fn grid_sweep_section(md: &mut String, report: &BenchReport) {
    if !report.grid_sweep.is_empty() {
        md.push_str("\n## Grid resolution sweep\n\n| scene | mode | accel | grid | dims | cells/tri | best ms | median ms |\n|---|---|---|---|---|---:|---:|---:|\n");
        for sw in &report.grid_sweep {
            for p in &sw.points {
                let mark = if p.choice == sw.best { " **best**" } else { "" };
                let _ = writeln!(
                    md,
                    "| {} | {} | {} | {}{mark} | {} | {:.2} | {:.2} | {:.2} |",
                    sw.scene,
                    sw.mode,
                    sw.accel,
                    p.choice,
                    dims_str(p.grid.dims),
                    p.cells_per_triangle,
                    p.summary.best_ms,
                    p.summary.median_ms
                );
            }
        }
        md.push_str("\n| scene | best grid | best ms | automatic grid | automatic ms |\n|---|---|---:|---|---:|\n");
        for sw in &report.grid_sweep {
            let _ = writeln!(
                md,
                "| {} | {} {} | {:.2} | {} | {:.2} |",
                sw.scene,
                sw.best,
                dims_str(sw.best_dims),
                sw.best_ms,
                dims_str(sw.auto_dims),
                sw.auto_ms
            );
        }
    }
}

/// `--scaling`.
fn scaling_section(md: &mut String, report: &BenchReport) {
    for sc in &report.scaling {
        let _ = writeln!(
            md,
            "\n## Scaling ({}, {} mode, {})\n\n| mesh | triangles | grid | build ms | resolution | best ms | ns/ray |\n|---|---:|---|---:|---|---:|---:|",
            sc.backend, sc.mode, sc.accel
        );
        for p in sc.by_triangles.iter().chain(&sc.by_pixels) {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.1} | {}x{} | {:.2} | {:.1} |",
                p.mesh,
                p.triangles,
                dims_str(p.grid_dims),
                p.build_ms,
                p.width,
                p.height,
                p.summary.best_ms,
                p.ns_per_ray
            );
        }
        md.push_str("\nFitted growth exponents (least-squares slope in log-log):\n\n| series | exponent | points |\n|---|---:|---:|\n");
        for f in &sc.fits {
            let _ = writeln!(md, "| {} | {:.3} | {} |", f.series, f.exponent, f.points);
        }
    }
}

/// `--build-scaling`.
fn build_scaling_section(md: &mut String, report: &BenchReport) {
    if !report.build_scaling.is_empty() {
        md.push_str(
            "\n## Build time against triangle count (best, ms)\n\n| mesh | triangles | grid | refs | grid+pc cpu 1 thread | grid+pc cpu all threads | grid+pc gpu | bvh cpu | embree | grid cpu / embree |\n|---|---:|---|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        for p in &report.build_scaling {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {:.2} | {:.2} ({} threads) | {}{} | {:.2} | {} | {} |",
                p.mesh,
                p.triangles,
                dims_str(p.grid_dims),
                p.references,
                p.cpu_1t_ms,
                p.cpu_ms,
                p.cpu_threads,
                ms(p.gpu_ms),
                p.gpu_fallback.as_ref().map_or(String::new(), |w| format!(" ({w})")),
                p.bvh_ms,
                ms(p.embree_ms),
                p.embree_ms.map_or("-".to_string(), |e| format!("{:.2}", p.cpu_ms / e))
            );
        }
    }
}

/// `--pc-study`.
fn pc_study_section(md: &mut String, report: &BenchReport) {
    if !report.pc_study.is_empty() {
        md.push_str("\n## Proximity-cloud study\n\n| scene | mode | accel | grid | empty | cells/ray | jumps/ray | tri tests/ray | best ms |\n|---|---|---|---|---:|---:|---:|---:|---:|\n");
        for r in &report.pc_study {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {:.1}% | {:.2} | {:.2} | {:.2} | {:.2} |",
                r.scene,
                r.mode,
                r.accel,
                dims_str(r.grid_dims),
                r.empty_fraction * 100.0,
                r.cells_per_ray,
                r.jumps_per_ray,
                r.tri_tests_per_ray,
                r.summary.best_ms
            );
        }
    }
}

/// `--query-study`.
fn query_study_section(md: &mut String, report: &BenchReport) {
    if !report.query_study.is_empty() {
        md.push_str("\n## Ray-query study (incoherent rays; CPU: `TraceMesh::intersect`, GPU: `GpuRenderer::intersect`)\n\n| scene | triangles | accel | backend | build ms | threads | hits | cells or nodes/ray | tri tests/ray | best ms | Mrays/s |\n|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
        for r in &report.query_study {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {:.1} | {} | {:.1}% | {:.2} | {:.2} | {:.2} | {:.2} |",
                r.scene,
                r.triangles,
                r.accel,
                r.backend,
                r.build_ms,
                r.threads,
                r.hit_fraction * 100.0,
                r.cells_per_ray,
                r.tri_tests_per_ray,
                r.summary.best_ms,
                r.mrays_per_s
            );
        }
    }
}

/// `--irregular-sweep`.
fn irregular_sweep_section(md: &mut String, report: &BenchReport) {
    if !report.irregular_sweep.is_empty() {
        md.push_str("\n## Irregular grid parameters (incoherent rays, closest hit, all threads; pc and bvh on the same rays)\n\n| scene | accel | params | build ms | cells/nodes | refs/tri | bytes/tri | steps/ray | tri tests/ray | best ms | Mrays/s |\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
        for r in &report.irregular_sweep {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.1} | {} | {:.2} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} |",
                r.scene,
                r.accel,
                r.params,
                r.build_ms,
                r.cells,
                r.refs_per_triangle,
                r.bytes_per_triangle,
                r.steps_per_ray,
                r.tri_tests_per_ray,
                r.summary.best_ms,
                r.mrays_per_s
            );
        }
    }
}

/// `--ablate`.
fn ablation_section(md: &mut String, report: &BenchReport) {
    if !report.ablation.is_empty() {
        md.push_str("\n## Ablations (median ms per frame with the optimisation and without it; the two alternate run by run)\n\n| scene | backend | accel | mode | without | size | with ms | without ms | slowdown | shadow rays |\n|---|---|---|---|---|---|---:|---:|---:|---:|\n");
        for r in &report.ablation {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {}x{} | {:.2} | {:.2} | {:.3} | {} |",
                r.scene,
                r.backend,
                r.accel,
                r.mode,
                r.ablation,
                r.width,
                r.height,
                r.with_ms,
                r.without_ms,
                r.slowdown,
                r.shadow_rays
            );
        }
    }
}

/// `--export-rays` / `--export-hits`.
fn ray_export_section(md: &mut String, report: &BenchReport) {
    if let Some(e) = &report.ray_export {
        let _ = writeln!(
            md,
            "\n## Exported rays\n\n{} {} {} {}x{}: {} eye, {} shadow, {} reflection rays, {} hits; rays: {}, hits: {}",
            e.scene,
            e.mode,
            e.accel,
            e.width,
            e.height,
            e.eye,
            e.shadow,
            e.reflection,
            e.hits,
            e.rays_file.as_deref().unwrap_or("-"),
            e.hits_file.as_deref().unwrap_or("-")
        );
    }
}
