//! Studies beside the paper's matrix (CPU): grid-resolution sweeps, scaling with triangle and
//! pixel count, and the proximity-cloud study with traversal counters. The ray-query study has
//! a file of its own (`query_study.rs`, re-exported here).

use gridtrace::AccelParams;
use std::path::Path;

use glam::{Mat4, Vec3};
use serde::Serialize;

pub use super::query_study::{QueryStudyRow, incoherent_rays, query_study};
use super::scenes::{self, BenchScene, ScalingMesh};
use super::{GridInfo, Summary, loglog_fit, time_cpu, time_gpu};
use gridtrace::Result;
use gridtrace::accel::DEFAULT_LAMBDA;
use gridtrace::accel::{AccelKind, Resolution};
use gridtrace::render::{Mode, RenderOptions};
use gridtrace::scene::procedural::box_mesh;
use gridtrace::scene::{Camera, Material, PointLight, Scene, builtin};

/// The cells-per-triangle values of a sweep.
pub const SWEEP_LAMBDAS: [f32; 7] = [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0];

#[derive(Debug, Clone, Serialize)]
pub struct SweepPoint {
    /// `auto:LAMBDA` or `paper`.
    pub choice: String,
    pub lambda: Option<f32>,
    pub grid: GridInfo,
    pub cells_per_triangle: f64,
    #[serde(flatten)]
    pub summary: Summary,
}

/// Time against grid resolution for one scene.
#[derive(Debug, Clone, Serialize)]
pub struct Sweep {
    pub scene: String,
    pub mode: String,
    pub accel: String,
    pub width: u32,
    pub height: u32,
    pub points: Vec<SweepPoint>,
    /// The fastest point (by best time).
    pub best: String,
    pub best_dims: [u32; 3],
    pub best_ms: f64,
    /// The automatic choice (default lambda).
    pub auto_dims: [u32; 3],
    pub auto_ms: f64,
}

/// Renders `bs` with each grid of the sweep (lambda 0.5..32 and the paper's dims if known).
/// `accel` is the grid's traversal to time (`grid` or `pc`).
pub fn grid_sweep(
    bs: &BenchScene,
    accel: AccelKind,
    opts: &RenderOptions,
    warmup: u32,
    reps: u32,
    log: &mut dyn FnMut(&str),
) -> Result<Sweep> {
    let mut choices: Vec<(String, Option<f32>, Resolution)> = SWEEP_LAMBDAS
        .iter()
        .map(|&l| (format!("auto:{l}"), Some(l), Resolution::Auto { lambda: l }))
        .collect();
    if let Some(d) = bs.paper_grid {
        choices.push(("paper".into(), None, Resolution::Fixed(d)));
    }
    let mut points = Vec::new();
    for (choice, lambda, res) in choices {
        let prepared = bs.scene.prepare_for(accel, &res.into())?;
        let (_, summary, _) = time_cpu(&prepared, opts, warmup, reps)?;
        let grid = GridInfo::of(&prepared, choice.clone());
        let p = SweepPoint {
            cells_per_triangle: grid.cells as f64 / prepared.accel.tris.len().max(1) as f64,
            choice,
            lambda,
            grid,
            summary,
        };
        log(&format!(
            "  sweep {:<14} {:<9} {:>4}x{:<4}x{:<4} {:>7.2} cells/tri  best {:>9.2} ms",
            bs.name, p.choice, p.grid.dims[0], p.grid.dims[1], p.grid.dims[2], p.cells_per_triangle, summary.best_ms
        ));
        points.push(p);
    }
    let best = points
        .iter()
        .min_by(|a, b| a.summary.best_ms.total_cmp(&b.summary.best_ms))
        .expect("at least one sweep point");
    let auto_name = format!("auto:{DEFAULT_LAMBDA}");
    let auto = points.iter().find(|p| p.choice == auto_name).unwrap_or(best);
    Ok(Sweep {
        scene: bs.name.clone(),
        mode: opts.mode.name().into(),
        accel: accel.name().into(),
        width: opts.width,
        height: opts.height,
        best: best.choice.clone(),
        best_dims: best.grid.dims,
        best_ms: best.summary.best_ms,
        auto_dims: auto.grid.dims,
        auto_ms: auto.summary.best_ms,
        points,
    })
}

#[derive(Debug, Clone, Serialize)]
pub struct ScalingPoint {
    pub mesh: String,
    pub family: String,
    pub source: String,
    pub triangles: usize,
    pub grid_dims: [u32; 3],
    pub build_ms: f64,
    pub width: u32,
    pub height: u32,
    pub rays: u64,
    #[serde(flatten)]
    pub summary: Summary,
    /// Best time per ray in nanoseconds.
    pub ns_per_ray: f64,
}

/// Growth of time per ray: `ns_per_ray ~ x^exponent`.
#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    pub series: String,
    pub exponent: f64,
    pub intercept_ln: f64,
    pub points: usize,
}

#[derive(Debug, Clone, Serialize)]
pub struct Scaling {
    /// cpu or gpu.
    pub backend: String,
    pub mode: String,
    pub accel: String,
    pub by_triangles: Vec<ScalingPoint>,
    pub by_pixels: Vec<ScalingPoint>,
    /// Exponents of time per ray against triangle count, per family and over all meshes; and of
    /// total time against pixel count.
    pub fits: Vec<Fit>,
}

fn family(name: &str) -> String {
    let f = name.split(['_', '-']).next().unwrap_or(name);
    if f == "bun" { "bunny" } else { f }.to_string()
}

/// The meshes of the scaling series found in `data_dir`, plus procedural ones; at most
/// `max_tris` triangles each.
pub fn scaling_meshes(data_dir: Option<&Path>, max_tris: usize, log: &mut dyn FnMut(&str)) -> Vec<ScalingMesh> {
    let mut v = Vec::new();
    for f in scenes::SCALING_FILES {
        let Some(dir) = data_dir else {
            log(&format!("  scaling: skipping {f}: no mesh data folder"));
            continue;
        };
        let p = dir.join(f);
        match gridtrace::io::load_mesh(&p) {
            Ok(m) if m.triangles.len() <= max_tris => v.push(ScalingMesh {
                name: Path::new(f).file_stem().unwrap().to_string_lossy().into(),
                source: f.into(),
                mesh: m,
            }),
            Ok(_) => log(&format!("  scaling: leaving out {f} (over {max_tris} triangles)")),
            Err(e) => log(&format!("  scaling: skipping {f}: {e}")),
        }
    }
    let top = if max_tris >= 1_310_720 { 8 } else { 6 };
    v.extend(scenes::procedural_scaling(3..=top, false));
    v
}

/// The meshes of the build-time series, smallest first: icospheres of 1,280 to 5.2 M
/// triangles and torus knots up to 10.2 M (procedural, the same on every machine), and the
/// scaling series' files where present; at most `max_tris` triangles each.
pub fn build_scaling_meshes(data_dir: Option<&Path>, max_tris: usize, log: &mut dyn FnMut(&str)) -> Vec<ScalingMesh> {
    let mut v = scaling_meshes(data_dir, max_tris, log);
    v.retain(|m| !m.name.starts_with("icosphere"));
    v.extend(scenes::procedural_scaling(3..=9, false));
    for (rings, sides) in [(2_000u32, 32u32), (40_000, 128)] {
        v.push(ScalingMesh {
            name: format!("torus-knot-{}", 2 * rings * sides),
            source: "procedural".into(),
            mesh: gridtrace::scene::procedural::torus_knot(2, 3, 0.16, rings, sides),
        });
    }
    v.retain(|m| m.mesh.triangles.len() <= max_tris);
    v.sort_by_key(|m| m.mesh.triangles.len());
    v
}

/// Time per ray against triangle count (each mesh alone, auto-framed) and against pixel count,
/// on the CPU, or on the GPU when `gpu` is given (each mesh uploaded once, then timed).
#[allow(clippy::too_many_arguments)]
pub fn scaling(
    meshes: Vec<ScalingMesh>,
    gpu: Option<&std::sync::Arc<gridtrace::gpu::GpuContext>>,
    res: (u32, u32),
    pixel_sides: &[u32],
    mode: Mode,
    accel: AccelKind,
    warmup: u32,
    reps: u32,
    log: &mut dyn FnMut(&str),
) -> Result<Scaling> {
    let mut by_triangles = Vec::new();
    let mut pixel_mesh = None;
    // On the GPU each mesh is uploaded once and timed at every size asked of it.
    let upload = |prepared: &gridtrace::scene::PreparedScene| {
        gpu.map(|ctx| gridtrace::gpu::GpuRenderer::new(ctx.clone(), prepared, &gridtrace::gpu::GpuVariants::default()))
            .transpose()
    };
    let time = |prepared: &gridtrace::scene::PreparedScene,
                on_gpu: &mut Option<gridtrace::gpu::GpuRenderer>,
                opts: &RenderOptions| match on_gpu {
        None => time_cpu(prepared, opts, warmup, reps).map(|(_, s, r)| (s, r)),
        Some(r) => time_gpu(r, prepared, opts, warmup, reps).map(|(_, s, out)| (s, out.render.rays)),
    };
    for m in meshes {
        let scene = builtin::mesh_scene(m.mesh, false);
        let prepared = scene.prepare_for(accel, &AccelParams::NONE)?;
        let mut on_gpu = upload(&prepared)?;
        let opts = RenderOptions::new(res.0, res.1, mode);
        let (summary, rays) = time(&prepared, &mut on_gpu, &opts)?;
        let p = ScalingPoint {
            family: family(&m.name),
            triangles: prepared.accel.tris.len(),
            grid_dims: grid_dims_of(&prepared),
            build_ms: grid_build_ms_of(&prepared),
            width: res.0,
            height: res.1,
            rays: rays.total(),
            ns_per_ray: summary.best_ms * 1e6 / rays.total().max(1) as f64,
            summary,
            mesh: m.name,
            source: m.source,
        };
        log(&format!(
            "  scaling {:<22} {:>9} tris  grid {:>4}x{:<4}x{:<4} build {:>8.1} ms  best {:>8.2} ms  {:>7.1} ns/ray",
            p.mesh,
            p.triangles,
            p.grid_dims[0],
            p.grid_dims[1],
            p.grid_dims[2],
            p.build_ms,
            summary.best_ms,
            p.ns_per_ray
        ));
        // The pixel series uses the Stanford bunny if present, else the first mesh.
        if pixel_mesh.is_none() || p.mesh == "bun_zipper" {
            pixel_mesh = Some((p.mesh.clone(), p.family.clone(), p.source.clone(), prepared, on_gpu));
        }
        by_triangles.push(p);
    }
    let mut by_pixels = Vec::new();
    if let Some((name, fam, source, prepared, mut on_gpu)) = pixel_mesh {
        for &side in pixel_sides {
            let opts = RenderOptions::new(side, side, mode);
            let (summary, rays) = time(&prepared, &mut on_gpu, &opts)?;
            log(&format!(
                "  pixels  {:<22} {:>5}x{:<5} best {:>8.2} ms",
                name, side, side, summary.best_ms
            ));
            by_pixels.push(ScalingPoint {
                mesh: name.clone(),
                family: fam.clone(),
                source: source.clone(),
                triangles: prepared.accel.tris.len(),
                grid_dims: grid_dims_of(&prepared),
                build_ms: grid_build_ms_of(&prepared),
                width: side,
                height: side,
                rays: rays.total(),
                ns_per_ray: summary.best_ms * 1e6 / rays.total().max(1) as f64,
                summary,
            });
        }
    }
    let mut fits = Vec::new();
    let mut families: Vec<String> = by_triangles.iter().map(|p| p.family.clone()).collect();
    families.dedup();
    let mut push_fit = |series: String, pts: Vec<(f64, f64)>| {
        if let Some((exponent, intercept_ln)) = loglog_fit(&pts) {
            fits.push(Fit {
                series,
                exponent,
                intercept_ln,
                points: pts.len(),
            });
        }
    };
    for f in &families {
        let pts = by_triangles
            .iter()
            .filter(|p| &p.family == f)
            .map(|p| (p.triangles as f64, p.ns_per_ray))
            .collect();
        push_fit(format!("ns/ray vs triangles: {f}"), pts);
    }
    push_fit(
        "ns/ray vs triangles: all".into(),
        by_triangles
            .iter()
            .map(|p| (p.triangles as f64, p.ns_per_ray))
            .collect(),
    );
    push_fit(
        "ms vs pixels".into(),
        by_pixels
            .iter()
            .map(|p| ((p.width * p.height) as f64, p.summary.best_ms))
            .collect(),
    );
    Ok(Scaling {
        backend: if gpu.is_some() { "gpu" } else { "cpu" }.into(),
        mode: mode.name().into(),
        accel: accel.name().into(),
        by_triangles,
        by_pixels,
        fits,
    })
}

/// The grid's dims and build time, zero for a scene prepared with a BVH.
/// The grid's dimensions (the irregular grid's top level); zero for a BVH.
fn grid_dims_of(p: &gridtrace::scene::PreparedScene) -> [u32; 3] {
    match (p.accel.grid(), p.accel.irregular()) {
        (Some(g), _) => g.stats.dims,
        (_, Some(g)) => g.stats.top_dims,
        _ => [0; 3],
    }
}

/// The grid's build time (either grid's); zero for a BVH.
fn grid_build_ms_of(p: &gridtrace::scene::PreparedScene) -> f64 {
    match (p.accel.grid(), p.accel.irregular()) {
        (Some(g), _) => g.stats.build_ms,
        (_, Some(g)) => g.stats.build_ms(),
        _ => 0.0,
    }
}

/// Traversal work per ray and time, grid against proximity clouds, for one scene and mode.
#[derive(Debug, Clone, Serialize)]
pub struct PcStudyRow {
    pub scene: String,
    pub mode: String,
    pub accel: String,
    pub width: u32,
    pub height: u32,
    pub grid_dims: [u32; 3],
    pub empty_fraction: f64,
    pub rays: u64,
    pub cells_per_ray: f64,
    pub jumps_per_ray: f64,
    pub tri_tests_per_ray: f64,
    #[serde(flatten)]
    pub summary: Summary,
}

/// A mesh seen from far away: the mesh (a low-poly one if `mesh` is given, else a torus knot)
/// about one unit across at one end of a closed 40-unit room, the camera at the other end.
pub fn far_mesh_scene(mesh: Option<gridtrace::Mesh>) -> Scene {
    let mut s = Scene::default();
    s.add_mesh(
        box_mesh(Vec3::splat(-20.0), Vec3::splat(20.0), 1, true),
        Mat4::IDENTITY,
        Some(Material {
            name: "room".into(),
            diffuse: Vec3::splat(0.7),
            reflectivity: 0.0,
        }),
    );
    let mesh = mesh.unwrap_or_else(|| gridtrace::scene::procedural::torus_knot(2, 3, 0.16, 84, 6));
    let b = gridtrace::accel::Aabb::from_points(&mesh.positions);
    let scale = 1.5 / b.diagonal().max(1e-12);
    let target = Vec3::new(0.0, -10.0, -15.0);
    let xf =
        Mat4::from_translation(target) * Mat4::from_scale(Vec3::splat(scale)) * Mat4::from_translation(-b.center());
    s.add_mesh(mesh, xf, None);
    s.camera = Camera {
        eye: Vec3::new(0.0, 5.0, 18.0),
        target,
        up: Vec3::Y,
        vfov_deg: 12.0,
    };
    s.lights = vec![PointLight::new(Vec3::new(0.0, 15.0, 10.0), Vec3::splat(600.0))];
    s
}

/// Counters and times of each scene, mode and acceleration.
pub fn pc_study(
    scenes: &[(String, Scene)],
    modes: &[Mode],
    res: (u32, u32),
    warmup: u32,
    reps: u32,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<PcStudyRow>> {
    let mut rows = Vec::new();
    for (name, scene) in scenes {
        let prepared = scene.prepare(Resolution::default())?;
        for &mode in modes {
            for accel in [AccelKind::Grid, AccelKind::ProximityCloud] {
                let opts = RenderOptions::new(res.0, res.1, mode);
                let (_, stats) =
                    gridtrace::cpu::render_with_counters(&prepared, &prepared.camera, &prepared.lights, &opts)?;
                let (_, summary, _) = time_cpu(&prepared, &opts, warmup, reps)?;
                let n = stats.rays.total().max(1) as f64;
                let c = stats.counters;
                let row = PcStudyRow {
                    scene: name.clone(),
                    mode: mode.name().into(),
                    accel: accel.name().into(),
                    width: res.0,
                    height: res.1,
                    grid_dims: prepared.grid().stats.dims,
                    empty_fraction: prepared.grid().stats.empty_fraction(),
                    rays: stats.rays.total(),
                    cells_per_ray: c.cells as f64 / n,
                    jumps_per_ray: c.jumps as f64 / n,
                    tri_tests_per_ray: c.tri_tests as f64 / n,
                    summary,
                };
                log(&format!(
                    "  pc-study {:<16} {:<6} {:<4} {:>7.2} cells  {:>6.2} jumps  {:>7.2} tri tests per ray  best {:>8.2} ms",
                    row.scene,
                    row.mode,
                    row.accel,
                    row.cells_per_ray,
                    row.jumps_per_ray,
                    row.tri_tests_per_ray,
                    summary.best_ms
                ));
                rows.push(row);
            }
        }
    }
    Ok(rows)
}

/// What `--export-rays` / `--export-hits` wrote.
#[derive(Debug, Clone, Serialize)]
pub struct RayExport {
    pub scene: String,
    pub mode: String,
    pub accel: String,
    pub width: u32,
    pub height: u32,
    pub rays_file: Option<String>,
    pub hits_file: Option<String>,
    pub eye: u64,
    pub shadow: u64,
    pub reflection: u64,
    pub hits: u64,
}
