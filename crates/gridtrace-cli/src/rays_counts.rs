//! `gridtrace rays --counts`: every hit along each ray of a ray file, counted, as a scene's
//! `count_intersections` counts them (Open3D's rule: a face hit twice at one `t`, a ray through
//! an edge two faces share, counts once), within `[--tmin, --tmax)`. The mesh is the scene's
//! one geometry; the counts run where the scene traces its rays, on the GPU (the count pass,
//! a count a ray down) or the CPU's cores, with the same answers. Written as one
//! little-endian u32 a ray; printed: the total of hits, how many rays hit anything, and where
//! the query ran (`rays::QueryLine`).

use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::time::Instant;

use gridtrace::query::{CHUNK, QueryOptions};
use gridtrace::query_scene::{PerRay, RayOptions};
use gridtrace::{Error, QueryScene};
use rayon::prelude::*;

use crate::rays::{QueryLine, RaysArgs, checked_input, print_tail, read_rays};

/// Counts every hit of each ray of `a.rays` into `a.hits_out` (`rays --counts`; the input
/// checked as every `rays` query checks it, `rays::checked_input`).
pub fn run(a: RaysArgs) -> gridtrace::Result<()> {
    let (n, hits_out) = checked_input(&a)?;
    let hits_out = hits_out.as_path();
    let opts = QueryOptions {
        accel: a.accel_args.spec()?,
        backend: a.backend,
        gpu_variants: a.gpu.gpu_variant,
    };
    let t_build = Instant::now();
    let mut scene = QueryScene::new(opts);
    scene.add_file(&a.mesh, None)?;
    // The structure is built here, by the first query that needs it, so the build is timed
    // apart from the counts.
    let accel = scene.accel_name()?;
    println!(
        "mesh    {}: {} triangles, built in {:.1} ms",
        a.mesh.display(),
        scene.triangle_count(),
        t_build.elapsed().as_secs_f64() * 1e3
    );
    println!("accel   {accel}");
    println!("backend {}", scene.device()?);
    let interval = RayOptions {
        t_near: PerRay::All(a.tmin),
        t_far: PerRay::All(a.tmax),
        mask: PerRay::All(u32::MAX),
    };
    let mut input = BufReader::new(File::open(&a.rays).map_err(|e| Error::io(&a.rays, e))?);
    let mut output = BufWriter::new(File::create(hits_out).map_err(|e| Error::io(hits_out, e))?);
    let mut buf = vec![0u8; CHUNK * 24];
    let (mut done, mut total, mut with_hits) = (0u64, 0u64, 0u64);
    let mut pass_s = vec![0.0; a.reps as usize];
    let mut gpu = gridtrace::gpu::GpuQueryStats::default();
    let mut line = QueryLine::default();
    while done < n {
        let count = (n - done).min(CHUNK as u64) as usize;
        let rays = read_rays(&mut input, &mut buf[..count * 24], (&a.rays, done), (a.tmin, a.tmax))?;
        let rows: Vec<[f32; 6]> = rays.par_iter().map(gridtrace::accel::Ray::wire).collect();
        let mut counts = Vec::new();
        for s in pass_s.iter_mut() {
            let t0 = Instant::now();
            counts = scene.count_intersections_with(&rows, &interval)?;
            *s += t0.elapsed().as_secs_f64();
        }
        // The chunk's last pass: where it ran, and its GPU batch.
        let q = scene.last_query();
        if let Some(s) = &q.gpu {
            gpu.add(s);
        }
        line.add(&q);
        total += counts.par_iter().map(|&c| u64::from(c)).sum::<u64>();
        with_hits += counts.par_iter().filter(|&&c| c > 0).count() as u64;
        let out: Vec<u8> = counts.iter().flat_map(|c| c.to_le_bytes()).collect();
        output.write_all(&out).map_err(|e| Error::io(hits_out, e))?;
        done += count as u64;
    }
    output.flush().map_err(|e| Error::io(hits_out, e))?;
    // The median pass, as `rays` reports closest hits.
    pass_s.sort_by(f64::total_cmp);
    let trace_s = pass_s[pass_s.len() / 2];
    let passes = match a.reps {
        1 => String::new(),
        r => format!("median of {r} passes, "),
    };
    println!(
        "rays    {n} (every hit), {total} hits, {with_hits} rays hit, {passes}{:.1} ms, {:.2} Mrays/s",
        trace_s * 1e3,
        n as f64 / trace_s.max(1e-9) / 1e6
    );
    print_tail(&gpu, &line, hits_out);
    Ok(())
}
