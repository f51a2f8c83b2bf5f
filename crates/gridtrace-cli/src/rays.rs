//! `gridtrace rays`: cast rays from a file at a mesh, write hits to a file.
//!
//! Rays: little-endian float32 records `ox oy oz dx dy dz` (24 bytes; the format of hagrid and of
//! `gridtrace bench --export-rays`). Hits: little-endian records `t: f32, tri: u32, u: f32,
//! v: f32` (16 bytes; a miss is `t = inf`, `tri = 0xFFFFFFFF`), with `--no-uv` `t: f32, tri:
//! u32` (8 bytes: a GPU then brings back 8 bytes a ray instead of 16); with `--occluded`, one
//! byte per ray (1 = occluded; the GPU brings back one bit). Both files are streamed in
//! chunks, so memory stays bounded. On the GPU the rays go up as they are in the file, 24
//! bytes each; the bytes each way are printed, also per ray. `--make camera|random` writes a
//! ray file for a mesh instead (the auto-framed view's eye rays, or incoherent ones).
//! `--counts` counts every hit along each ray instead (`rays_counts.rs`, chosen in main.rs).
//! After the queries a `query` line says which query ran, the device that answered it (the
//! library's `last_query`: under `auto` the CPU once a GPU fault sent the work there) and, for
//! GPU work, the bytes up and down.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use gridtrace::query::{CHUNK, QueryOptions, TraceMesh};
use gridtrace::{Error, Ray};
use rayon::prelude::*;

use crate::common::{AccelArgs, Backend, GpuFigures, GpuVariantArgs, backend_parser, parse_output, print_gpu_figures};

#[derive(Args)]
pub struct RaysArgs {
    /// The mesh (OBJ, PLY, glTF/GLB, STL, OFF).
    pub(crate) mesh: PathBuf,
    /// Ray file: little-endian float32 records ox oy oz dx dy dz (24 bytes a ray); --make
    /// writes one.
    #[arg(long)]
    pub(crate) rays: PathBuf,
    /// Hits count only for t > TMIN (t in units of each ray's direction length).
    // Hyphen values: clap would otherwise take `--tmin -1` for a flag `-1`.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub(crate) tmin: f32,
    /// Hits count only for t < TMAX.
    #[arg(long, default_value_t = f32::INFINITY, allow_hyphen_values = true)]
    pub(crate) tmax: f32,
    /// Any-hit occlusion instead of closest hits (one byte per ray).
    #[arg(long)]
    occluded: bool,
    /// Closest hits without barycentrics: 8-byte records (t, tri) instead of 16.
    #[arg(long, conflicts_with = "occluded")]
    no_uv: bool,
    /// Count every hit along each ray instead (a scene's `count_intersections`, Open3D's
    /// rule: a face hit twice at one t counts once) within [TMIN, TMAX): one little-endian
    /// u32 per ray. Prints the total of hits and how many rays hit anything.
    #[arg(long, conflicts_with_all = ["occluded", "no_uv"])]
    pub(crate) counts: bool,
    /// Where to trace: auto (GPU if present, else CPU), gpu or cpu.
    #[arg(long, default_value = "auto", value_parser = backend_parser())]
    pub(crate) backend: Backend,
    #[command(flatten)]
    pub(crate) gpu: GpuVariantArgs,
    #[command(flatten)]
    pub(crate) accel_args: AccelArgs,
    /// Trace every chunk of rays this many times in a row (the answers of the last are
    /// written) and report the median pass: warm figures, as `embree_rays --reps` reports
    /// its own (a single pass of a small file also times the threads' start and the first
    /// touch of fresh memory).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100), allow_hyphen_values = true)]
    pub(crate) reps: u32,
    /// Output file (its folder must exist; checked before any work).
    #[arg(long, value_parser = parse_output, required_unless_present = "make")]
    hits_out: Option<PathBuf>,
    /// Write a ray file into --rays instead of tracing one: `camera`, the eye rays of the
    /// mesh's auto-framed view (as `render --mesh` frames it), row by row of a square image of
    /// at least --count pixels; or `random`, incoherent rays from a sphere of one bounding-box
    /// diagonal around the mesh aimed at random points of its box (the benchmarks' ray queries).
    #[arg(long, value_enum, value_name = "KIND")]
    pub(crate) make: Option<MakeRays>,
    /// With --make: how many rays.
    #[arg(long, default_value_t = 1_000_000, requires = "make", allow_hyphen_values = true,
          value_parser = clap::value_parser!(u32).range(1..=MAX_MADE_RAYS))]
    count: u32,
}

/// The ray sets `--make` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MakeRays {
    Camera,
    Random,
}

/// `--count`'s bound: the rays are made in memory (24 bytes each, 0.24 GB at the bound) before
/// they are written.
const MAX_MADE_RAYS: i64 = 10_000_000;

/// `--make`: a ray file of `--count` rays of the kind asked for, at `--rays`.
fn make_rays(a: &RaysArgs, kind: MakeRays) -> gridtrace::Result<()> {
    crate::common::check_output_path(&a.rays)
        .map_err(|e| Error::InvalidInput(format!("--rays {}: {e}", a.rays.display())))?;
    let mesh = gridtrace::io::load_mesh(&a.mesh)?;
    let n = a.count as usize;
    let rays: Vec<[f32; 6]> = match kind {
        MakeRays::Camera => gridtrace_bench::hardware::camera_rays(&mesh, n)
            .iter()
            .map(|r| [r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z])
            .collect(),
        MakeRays::Random => {
            let bounds = gridtrace::accel::Aabb::from_points(&mesh.positions);
            let (o, d) = gridtrace_bench::query_study::incoherent_rays(bounds, n, 7);
            o.iter()
                .zip(&d)
                .map(|(o, d)| [o[0], o[1], o[2], d[0], d[1], d[2]])
                .collect()
        }
    };
    let bytes: Vec<u8> = rays.iter().flatten().flat_map(|f| f.to_le_bytes()).collect();
    std::fs::write(&a.rays, bytes).map_err(|e| Error::io(&a.rays, e))?;
    let what = match kind {
        MakeRays::Camera => "camera",
        MakeRays::Random => "random",
    };
    println!(
        "wrote   {}: {n} {what} rays of {}, 24 bytes each (ox oy oz dx dy dz, little-endian float32)",
        a.rays.display(),
        a.mesh.display()
    );
    Ok(())
}

pub fn run(a: RaysArgs) -> gridtrace::Result<()> {
    if let Some(kind) = a.make {
        return make_rays(&a, kind);
    }
    let (n, hits_out) = checked_input(&a)?;
    let opts = QueryOptions {
        accel: a.accel_args.spec()?,
        backend: a.backend,
        gpu_variants: a.gpu.gpu_variant,
    };
    let t_build = Instant::now();
    let mesh = TraceMesh::load(&a.mesh, &opts)?;
    println!(
        "mesh    {}: {} triangles, built in {:.1} ms",
        a.mesh.display(),
        mesh.triangle_count(),
        t_build.elapsed().as_secs_f64() * 1e3
    );
    for n in mesh.notes() {
        eprintln!("note: {n}");
    }
    println!("accel   {}", mesh.accel().name());
    println!("backend {}", mesh.device());
    let mut input = BufReader::new(File::open(&a.rays).map_err(|e| Error::io(&a.rays, e))?);
    let mut output = BufWriter::new(File::create(&hits_out).map_err(|e| Error::io(&hits_out, e))?);
    let write_err = |e| Error::io(&hits_out, e);
    let mut buf = vec![0u8; CHUNK * 24];
    let (mut done, mut hits) = (0u64, 0u64);
    // Each pass's tracing time, summed over the file's chunks.
    let mut pass_s = vec![0.0; a.reps as usize];
    // The answers, one buffer kept over passes and chunks (`intersect_rays_into`): a caller
    // tracing batch after batch keeps its memory mapped.
    let (mut found, mut occ) = (Vec::new(), Vec::new());
    // The GPU batches' own figures, summed over the file's chunks.
    let mut gpu = gridtrace::gpu::GpuQueryStats::default();
    let mut line = QueryLine::default();
    while done < n {
        let count = (n - done).min(CHUNK as u64) as usize;
        let rays = read_rays(&mut input, &mut buf[..count * 24], (&a.rays, done), (a.tmin, a.tmax))?;
        if a.occluded {
            for s in pass_s.iter_mut() {
                let t0 = Instant::now();
                mesh.occluded_rays_into(mesh.backend(), &rays, &mut occ)?;
                *s += t0.elapsed().as_secs_f64();
            }
            hits += occ.par_iter().filter(|o| **o).count() as u64;
            let out: Vec<u8> = occ.par_iter().map(|&o| o as u8).collect();
            output.write_all(&out).map_err(write_err)?;
        } else {
            for s in pass_s.iter_mut() {
                let t0 = Instant::now();
                mesh.intersect_rays_into(mesh.backend(), &rays, !a.no_uv, &mut found)?;
                *s += t0.elapsed().as_secs_f64();
            }
            // Records written in parallel into a zeroed buffer (fresh pages, first touched by
            // the workers): 16 bytes, or 8 without u, v.
            let rec = if a.no_uv { 8 } else { 16 };
            let mut out = vec![0u8; found.len() * rec];
            hits += out
                .par_chunks_mut(rec)
                .zip(found.par_iter())
                .map(|(o, h)| {
                    let tri = if h.is_hit() {
                        mesh.original_index(h.tri)
                    } else {
                        u32::MAX
                    };
                    o[0..4].copy_from_slice(&h.t.to_le_bytes());
                    o[4..8].copy_from_slice(&tri.to_le_bytes());
                    if rec == 16 {
                        o[8..12].copy_from_slice(&h.u.to_le_bytes());
                        o[12..16].copy_from_slice(&h.v.to_le_bytes());
                    }
                    h.is_hit() as u64
                })
                .sum::<u64>();
            output.write_all(&out).map_err(write_err)?;
        }
        // This chunk's last pass: where it ran, and its GPU batch.
        let q = mesh.last_query();
        if let Some(s) = &q.gpu {
            gpu.add(s);
        }
        line.add(&q);
        done += count as u64;
    }
    output.flush().map_err(write_err)?;
    // The median pass (the slower of two middle ones), the rate from it.
    let first_s = pass_s[0];
    pass_s.sort_by(f64::total_cmp);
    let trace_s = pass_s[pass_s.len() / 2];
    let passes = match a.reps {
        1 => String::new(),
        r => format!(
            "median of {r} passes (first {:.2} Mrays/s), ",
            n as f64 / first_s.max(1e-9) / 1e6
        ),
    };
    println!(
        "rays    {n} ({}), {hits} hit, {passes}{:.1} ms, {:.2} Mrays/s",
        if a.occluded { "occlusion" } else { "closest hit" },
        trace_s * 1e3,
        n as f64 / trace_s.max(1e-9) / 1e6
    );
    print_tail(&gpu, &line, &hits_out);
    Ok(())
}

/// The ray file's record count and the hits file, after the checks every query of `rays`
/// makes before any work (the interval, the file: a whole number of 24-byte records).
pub(crate) fn checked_input(a: &RaysArgs) -> gridtrace::Result<(u64, std::path::PathBuf)> {
    let hits_out = a.hits_out.clone().expect("clap requires --hits-out without --make");
    // Checked here, before any work: the CPU query path does not check the interval itself, and
    // a negative --tmin would silently report hits behind the origins.
    if a.tmin.is_nan() || a.tmax.is_nan() || a.tmin < 0.0 || a.tmin > a.tmax {
        return Err(Error::InvalidInput(format!(
            "need 0 <= --tmin <= --tmax, got --tmin {} --tmax {}",
            a.tmin, a.tmax
        )));
    }
    let meta = std::fs::metadata(&a.rays).map_err(|e| Error::io(&a.rays, e))?;
    // As `render` says of a folder given for a mesh (a folder's size, 4096, means nothing here).
    if meta.is_dir() {
        return Err(Error::parse(
            &a.rays,
            gridtrace::Location::Whole,
            "is a directory, not a ray file (float32 records ox oy oz dx dy dz)",
        ));
    }
    let size = meta.len();
    if size % 24 != 0 {
        return Err(Error::parse(
            &a.rays,
            gridtrace::Location::Byte(size - size % 24),
            format!("ray file is {size} bytes, not a whole number of 24-byte records (6 float32 per ray)"),
        ));
    }
    let n = size / 24;
    Ok((n, hits_out))
}

/// What `rays` prints after a query's line: the GPU's batches (where it ran there), the query
/// line and the file written.
pub(crate) fn print_tail(gpu: &gridtrace::gpu::GpuQueryStats, line: &QueryLine, hits_out: &std::path::Path) {
    if gpu.round_trips > 0 {
        print_gpu_batches(gpu);
    }
    line.print();
    println!("wrote   {}", hits_out.display());
}

/// Reads the next `bytes.len() / 24` rays of the file `path` (ray `first` on) from `input`,
/// converted and checked in parallel (a serial pass here would be a part of the run that no
/// thread count speeds up); a ray that is not finite or has a zero direction is an error
/// naming its byte in the file.
pub(crate) fn read_rays(
    input: &mut impl Read,
    bytes: &mut [u8],
    (path, first): (&std::path::Path, u64),
    (t_min, t_max): (f32, f32),
) -> gridtrace::Result<Vec<Ray>> {
    input.read_exact(bytes).map_err(|e| Error::io(path, e))?;
    let mut rays = Vec::with_capacity(bytes.len() / 24);
    bytes
        .par_chunks_exact(24)
        .map(|r| {
            let f = |k: usize| f32::from_le_bytes([r[4 * k], r[4 * k + 1], r[4 * k + 2], r[4 * k + 3]]);
            Ray::new(glam::Vec3::new(f(0), f(1), f(2)), glam::Vec3::new(f(3), f(4), f(5))).within(t_min, t_max)
        })
        .collect_into_vec(&mut rays);
    let bad = |r: &Ray| !r.origin.is_finite() || !r.dir.is_finite() || r.dir == glam::Vec3::ZERO;
    if let Some(i) = rays.par_iter().position_first(bad) {
        let k = first + i as u64;
        let r = &rays[i];
        return Err(Error::parse(
            path,
            gridtrace::Location::Byte(k * 24),
            format!(
                "ray {k} is not finite or has a zero direction: {:?}",
                [r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z]
            ),
        ));
    }
    Ok(rays)
}

/// Where a run's queries were answered, from each chunk's `last_query`: the query's name, the
/// devices in the order they answered (under `auto`, "gpu, then cpu" after a GPU fault), and
/// the GPU's bytes each way, summed over the chunks. A fault's note goes to stderr as it
/// comes.
#[derive(Default)]
pub(crate) struct QueryLine {
    name: &'static str,
    devices: Vec<&'static str>,
    uploaded_bytes: u64,
    downloaded_bytes: u64,
}

impl QueryLine {
    pub(crate) fn add(&mut self, q: &gridtrace::query::LastQuery) {
        self.name = q.name;
        if self.devices.last() != Some(&q.device) {
            self.devices.push(q.device);
        }
        if let Some(s) = &q.gpu {
            self.uploaded_bytes += s.uploaded_bytes;
            self.downloaded_bytes += s.downloaded_bytes;
        }
        if let Some(n) = &q.note {
            eprintln!("note: {n}");
        }
    }

    /// `query   NAME on DEVICE[, B up, B down]` (nothing for an empty ray file).
    pub(crate) fn print(&self) {
        if self.devices.is_empty() {
            return;
        }
        let bytes = if self.devices.contains(&"gpu") {
            format!(", {} B up, {} B down", self.uploaded_bytes, self.downloaded_bytes)
        } else {
            String::new()
        };
        println!("query   {} on {}{bytes}", self.name, self.devices.join(", then "));
    }
}

/// The GPU's figures for the batches, with the frame's meanings (`render`'s `gpu` line), and
/// the rays' rate on the device.
pub(crate) fn print_gpu_batches(s: &gridtrace::gpu::GpuQueryStats) {
    let figures = GpuFigures {
        wall_ms: s.wall_ms,
        timings: &s.timings,
        parts: (s.chunks, "chunk"),
        round_trips: s.round_trips,
        uploaded_bytes: s.uploaded_bytes,
        downloaded_bytes: s.downloaded_bytes,
    };
    let per_ray = |bytes: u64| bytes as f64 / s.rays.max(1) as f64;
    println!(
        "bus     {:.2} B up, {:.2} B down a ray (rays, answers, each chunk's constants and timestamps)",
        per_ray(s.uploaded_bytes),
        per_ray(s.downloaded_bytes)
    );
    if let Some(ms) = print_gpu_figures("", &figures).filter(|ms| *ms > 0.0) {
        println!("rates   {:.2} Mrays/s on the device", s.rays as f64 / (ms * 1e3));
    }
}
