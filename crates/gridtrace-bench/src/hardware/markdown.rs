//! The suite's Markdown report: what ran where, then each part as a table, GPU beside CPU.

use std::fmt::Write as _;

use super::{FrameRow, HardwareReport, PointRow, RayRow};
use gridtrace::gpu::HostPhases;

pub fn markdown(r: &HardwareReport) -> String {
    let mut md = String::new();
    let a = &r.adapter;
    let _ = writeln!(md, "# gridtrace hardware suite\n");
    if a.software {
        let _ = writeln!(
            md,
            "**WARNING: SOFTWARE ADAPTER ({}). Its shaders ran on the CPU: no figure here is a GPU figure.**\n",
            a.name
        );
    }
    let _ = writeln!(
        md,
        "- gridtrace {}; command: `{}`",
        r.gridtrace_version,
        r.command_line.join(" ")
    );
    let _ = writeln!(
        md,
        "- adapter: {} ({}, {}, vendor {:#x} device {:#x}), driver {} {}; timestamps: {}; subgroups: {}",
        a.name, a.device_type, a.backend, a.vendor, a.device, a.driver, a.driver_info, a.timestamps, a.subgroups
    );
    if let Some(s) = &a.nvidia_smi {
        let _ = writeln!(md, "- nvidia-smi: `{}`", s.replace('\n', " / "));
    }
    let m = &r.machine;
    let _ = writeln!(md, "- CPU: {} ({} threads); OS: {}", m.cpu_model, m.threads, m.os);
    let p = &r.plan;
    let _ = writeln!(
        md,
        "- plan: {} frames {}x{}, big frame {}x{}, {} rays per batch, builds up to {} triangles, {} timed repetitions (median), warm-up {} ms; variants: {}",
        if p.quick { "quick" } else { "full" },
        p.frame_size.0,
        p.frame_size.1,
        p.big_frame.0,
        p.big_frame.1,
        p.rays,
        p.build_max_tris,
        p.reps,
        p.warmup_ms,
        r.variants.join(", ")
    );
    let _ = writeln!(md, "- ran {:.1} s of a {:.0} s budget\n", r.elapsed_s, p.budget_s);
    if r.mismatches.is_empty() {
        md.push_str("Every GPU image and hit agreed with the CPU's within the stated tolerances.\n\n");
    } else {
        md.push_str("## MISMATCHES (GPU results that differ from the CPU's)\n\n");
        for s in &r.mismatches {
            let _ = writeln!(md, "- {s}");
        }
        md.push('\n');
    }
    if !r.skipped.is_empty() {
        md.push_str("Skipped:\n\n");
        for s in &r.skipped {
            let _ = writeln!(md, "- {s}");
        }
        md.push('\n');
    }
    frames(&mut md, "Frames", &r.frames);
    frames(&mut md, "The big frame", &r.big_frame);
    rays(&mut md, &r.rays);
    points(&mut md, &r.points);
    builds(&mut md, r);
    md
}

/// GPU rows beside the CPU row of the same scene, structure, mode and size.
fn frames(md: &mut String, title: &str, rows: &[FrameRow]) {
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "## {title}\n\nWall: host clock, uploads to image in host memory (median). GPU: the stages' timestamps summed (median). x CPU: the CPU's median wall time over the GPU's. Host: the wall time's parts on the host's clock (medians): preparing and submitting / waiting for the device / reading the image out. Variants were timed in rounds across them. `image=device`: the default variant's frames left in a device image, as the viewer presents them (only counters and timestamps read back). `in-flight=2`: the default variant's frames read back with two in flight (frame N+1 submitted before frame N is read back); its wall time is a run of 6 frames' time over 6 (the throughput), its host phases the last frame's own.\n\n| scene | mode | accel | variant | size | rays | CPU ms | wall ms | GPU ms | host ms | Mrays/s (wall) | Mrays/s (GPU) | x CPU | round trips | bytes down | differing px |\n|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for g in rows.iter().filter(|g| g.backend == "gpu") {
        let cpu = rows.iter().find(|c| {
            c.backend == "cpu" && c.scene == g.scene && c.accel == g.accel && c.mode == g.mode && c.width == g.width
        });
        let cpu_ms = cpu.map(|c| c.wall.median_ms);
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {}x{} | {} | {} | {:.2} | {} | {} | {:.1} | {} | {} | {} | {} | {:.3}% |",
            g.scene,
            g.mode,
            g.accel,
            g.variant,
            g.width,
            g.height,
            g.rays,
            cpu_ms.map_or("-".into(), |v| format!("{v:.2}")),
            g.wall.median_ms,
            g.gpu_median_ms.map_or("-".into(), |v| format!("{v:.2}")),
            host_cell(g.host_ms.as_ref()),
            g.mrays_per_s,
            g.gpu_mrays_per_s.map_or("-".into(), |v| format!("{v:.1}")),
            cpu_ms.map_or("-".into(), |c| format!("{:.2}", c / g.wall.median_ms.max(1e-9))),
            g.round_trips,
            g.bytes_down,
            100.0 * g.differing_from_cpu
        );
    }
    md.push('\n');
}

fn rays(md: &mut String, rows: &[RayRow]) {
    if rows.is_empty() {
        return;
    }
    md.push_str("## Ray batches\n\nWall time of the whole query (upload, trace, readback; median); GPU: the stages' timestamps summed (median); host: the wall time's parts as in the frames; B/ray: bytes over the bus a ray, up / down (rays, answers, each chunk's constants and timestamps), in pipelined chunks. Variants were timed in rounds across them. The GPU rows answer hits with u, v as the CPU's; `answers=t,tri` the default variant asked for (t, triangle) only, `answers=occlusion` for occlusion bits (checked against the CPU's hits).\n\n| mesh | set | accel | backend | variant | rays | ms | GPU ms | host ms | B/ray | chunks | Mrays/s | x CPU | hit | differing hits |\n|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in rows {
        let cpu = rows.iter().find(|c| {
            r.backend == "gpu" && c.backend == "cpu" && c.mesh == r.mesh && c.set == r.set && c.accel == r.accel
        });
        let ratio = cpu.map_or("-".into(), |c| {
            format!("{:.2}", c.wall.median_ms / r.wall.median_ms.max(1e-9))
        });
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {:.2} | {} | {} | {} | {} | {:.2} | {ratio} | {:.1}% | {:.3}% |",
            r.mesh,
            r.set,
            r.accel,
            r.backend,
            r.variant,
            r.rays,
            r.wall.median_ms,
            r.gpu_median_ms.map_or("-".into(), |v| format!("{v:.2}")),
            host_cell(r.host_ms.as_ref()),
            match (r.bytes_up_per_ray, r.bytes_down_per_ray) {
                (Some(up), Some(down)) => format!("{up:.1} / {down:.2}"),
                _ => "-".into(),
            },
            r.chunks.map_or("-".into(), |c| c.to_string()),
            r.mrays_per_s,
            100.0 * r.hit_fraction,
            100.0 * r.differing_from_cpu
        );
    }
    md.push('\n');
}

fn points(md: &mut String, rows: &[PointRow]) {
    if rows.is_empty() {
        return;
    }
    md.push_str("## Point queries\n\nPoints uniform in the mesh's box grown by a tenth a side. `closest`: the nearest point through each structure's search; `winding`: generalised winding numbers over the fast winding tree at accuracy 2 (the sign of signed distance and occupancy), the tree built before the times. Wall: the whole query (median); GPU: the timestamps summed; B/pt: bytes over the bus a point, up / down; x CPU: the CPU's median over the GPU's; differing: answers apart from the CPU's by more than 1e-4 relative (distances) or 1e-3 (winding numbers).\n\n| mesh | query | accel | backend | points | ms | GPU ms | B/pt | Mpoints/s | x CPU | differing |\n|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in rows {
        let cpu = rows.iter().find(|c| {
            r.backend == "gpu" && c.backend == "cpu" && c.mesh == r.mesh && c.query == r.query && c.accel == r.accel
        });
        let ratio = cpu.map_or("-".into(), |c| {
            format!("{:.2}", c.wall.median_ms / r.wall.median_ms.max(1e-9))
        });
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {:.2} | {} | {} | {:.2} | {ratio} | {:.3}% |",
            r.mesh,
            r.query,
            r.accel,
            r.backend,
            r.points,
            r.wall.median_ms,
            r.gpu_median_ms.map_or("-".into(), |v| format!("{v:.2}")),
            match (r.bytes_up_per_point, r.bytes_down_per_point) {
                (Some(up), Some(down)) => format!("{up:.1} / {down:.1}"),
                _ => "-".into(),
            },
            r.mpoints_per_s,
            100.0 * r.differing_from_cpu
        );
    }
    md.push('\n');
}

/// `prepare / wait / readout` ms, or `-` on the CPU.
fn host_cell(h: Option<&HostPhases>) -> String {
    h.map_or("-".into(), |h| {
        format!("{:.1} / {:.1} / {:.1}", h.prepare_ms, h.wait_ms, h.readout_ms)
    })
}

fn builds(md: &mut String, r: &HardwareReport) {
    if r.builds.is_empty() {
        return;
    }
    md.push_str("## Grid builds (grid + proximity cloud, best ms)\n\n| mesh | triangles | CPU all threads | GPU | GPU from | x CPU | references CPU / GPU |\n|---|---:|---:|---:|---|---:|---|\n");
    for b in &r.builds {
        let from = b
            .gpu_fallback
            .clone()
            .unwrap_or_else(|| if b.gpu_from_timestamps { "timestamps" } else { "wall" }.to_string());
        let _ = writeln!(
            md,
            "| {} | {} | {:.1} | {} | {from} | {} | {} / {} |",
            b.mesh,
            b.triangles,
            b.cpu_ms,
            b.gpu_ms.map_or("-".into(), |v| format!("{v:.1}")),
            b.gpu_ms
                .map_or("-".into(), |g| format!("{:.2}", b.cpu_ms / g.max(1e-9))),
            b.cpu_references,
            b.gpu_references.map_or("-".into(), |n| n.to_string())
        );
    }
    md.push('\n');
}
