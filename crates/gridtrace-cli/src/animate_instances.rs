//! `gridtrace render --animate --scene tumbling-bunnies`: many rigid instances of one mesh
//! (`gridtrace::scene::tumbling`) played frame by frame through a `QueryScene`'s two levels.
//! Each frame is timed as `animate.rs` times a rebuild: the move (the instances' matrices and
//! `set_transforms`, which rebuilds the top level and nothing else), the trace (the eye rays
//! through `cast_rays`, and under --mode shadow or trace the shadow rays through
//! `test_occlusions`, on the CPU or the GPU as --backend says; on the GPU this includes
//! uploading the new top level) and the shade; and the structures built over triangles so far,
//! which stays 1 (the one mesh's) after the first frame. The camera options and --light apply
//! as in a still frame (`view`).

use std::path::PathBuf;
use std::time::Instant;

use gridtrace::query::QueryOptions;
use gridtrace::scene::PointLight;
use gridtrace::scene::tumbling::{self, Tumbling};
use gridtrace::{AccelChoice, AccelKind, AccelSpec, Error, Mode};

use crate::render::RenderArgs;

/// The mesh placed by default, below the mesh folder.
const BUNNY: &str = "bunny/bun_zipper.ply";

pub fn run(a: &RenderArgs) -> gridtrace::Result<()> {
    if !(a.fps.is_finite() && a.fps > 0.0) {
        return Err(Error::InvalidInput(format!("--fps must be positive, got {}", a.fps)));
    }
    if a.scene.file.is_some() || a.scene.mesh.is_some() {
        return Err(Error::InvalidInput(format!(
            "--scene {} places --instance-mesh PATH, not a scene file or --mesh",
            tumbling::NAME
        )));
    }
    let path = mesh_path(a)?;
    let mesh = gridtrace::io::load_mesh(&path)?;
    let vertices = mesh.positions.iter().map(|p| p.to_array()).collect();
    let instances = a.instances.unwrap_or(tumbling::DEFAULT_INSTANCES);
    let what = path.display().to_string();
    let mut scene_def = Tumbling::new(vertices, mesh.triangles, instances, &what)?;
    let (placement, mut notes) = gridtrace::Placement::open(a.backend, a.gpu.gpu_variant)?;
    let accel = accel_spec(a, &mut notes)?;
    let opts = QueryOptions {
        accel: accel.clone(),
        backend: a.backend,
        gpu_variants: a.gpu.gpu_variant,
    };
    let view = view(a, &mut scene_def, &mut notes)?;
    let t0 = Instant::now();
    let (mut scene, ids) = scene_def.query_scene(opts, 0.0)?;
    if let Some(ctx) = &placement.device {
        // The device `--backend` opened, and described below: the scene's GPU work goes there
        // rather than to a second device the scene would open itself.
        scene.adopt_device(ctx.clone());
    }
    // One ray builds the two levels (the mesh's structure, the top level, and on the GPU their
    // upload), so that the first frame's move is a move like the others.
    scene.cast_rays(&[scene_def.primary_rays(1, 1)[0]])?;
    let first_build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let tris = scene_def.faces.len();
    println!(
        "scene {} (animated): {instances} instances of {what} ({tris} triangles each, {} placed), {}; \
         first build {first_build_ms:.1} ms; mode {}, {}",
        tumbling::NAME,
        tris * instances as usize,
        accel_name(&accel),
        view.mode.name(),
        view.lighting(),
    );
    crate::common::print_backend(&placement);
    for n in notes {
        eprintln!("note: {n}");
    }
    if let Some(dir) = &a.sequence {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let (w, h) = a.res;
    let rays = scene_def.primary_rays(w, h);
    println!("frame  time_s  move_ms  trace_ms  shade_ms  total_ms  builds  on");
    let mut rows = Vec::with_capacity(a.frames as usize);
    for i in 0..a.frames {
        let time = i as f32 / a.fps;
        let t_frame = Instant::now();
        let transforms = scene_def.transforms_at(time);
        scene.set_transforms(&ids, &transforms)?;
        let move_ms = t_frame.elapsed().as_secs_f64() * 1e3;
        let t_trace = Instant::now();
        let hits = scene.cast_rays(&rays)?;
        // The shadow rays' walk is tracing too (the query's note, if any, is the last's).
        let occluded = match view.mode {
            Mode::Cast => None,
            _ => Some(scene.test_occlusions(&scene_def.shadow_rays(&rays, &hits, &view.lights), 0.0, 1.0)?),
        };
        let trace_ms = t_trace.elapsed().as_secs_f64() * 1e3;
        let t_shade = Instant::now();
        let image = if view.lights.is_empty() {
            scene_def.shade(&rays, &hits, w, h)
        } else {
            scene_def.shade_lit(&rays, &hits, &view.lights, occluded.as_deref(), w, h)
        };
        let shade_ms = t_shade.elapsed().as_secs_f64() * 1e3;
        let total_ms = t_frame.elapsed().as_secs_f64() * 1e3;
        let builds = scene.structure_builds();
        let on = scene.last_query();
        println!(
            "{i:5}  {time:6.3}  {move_ms:7.2}  {trace_ms:8.2}  {shade_ms:8.2}  {total_ms:8.2}  {builds:6}  {}",
            on.device
        );
        if let Some(n) = on.note {
            println!("note: {n}");
        }
        rows.push([move_ms, trace_ms, shade_ms]);
        crate::common::save_frame(&image, i, a.sequence.as_deref(), &a.output)?;
    }
    if rows.len() > 1 {
        let median = |k: usize| crate::common::median_after_first(&rows, k);
        println!(
            "median of frames 1-{}: move {:.2} ms, trace {:.2} ms, shade {:.2} ms; structure builds {} \
             [{instances} instances {} {w}x{h}]",
            rows.len() - 1,
            median(0),
            median(1),
            median(2),
            scene.structure_builds(),
            accel_name(&accel)
        );
    }
    if let Some(up) = scene.gpu_uploads() {
        println!(
            "gpu     meshes uploaded {} time(s) ({} B); a move uploads the top level alone: {} nodes, {} \
             instance records",
            up.mesh_uploads, up.mesh_bytes, up.top_nodes, up.top_records
        );
    }
    if scene.structure_builds() > 1 {
        // The GPU walks some structures only merged flat: each move rebuilds that mesh.
        println!(
            "note: {} structures were built: --accel {} is not walked under a top level here (each move \
             rebuilt the merged mesh); bvh, grid, pc and brute are",
            scene.structure_builds(),
            accel_name(&accel)
        );
    }
    println!("wrote   {}", a.output.display());
    Ok(())
}

/// How the frames are seen and lit: `--mode` (cast where none is given), the lights of
/// `--light` (none: the headlight, a light at the eye).
struct View {
    mode: Mode,
    lights: Vec<PointLight>,
}

impl View {
    /// The lighting, in words for the scene's line.
    fn lighting(&self) -> String {
        match self.lights.len() {
            0 => "lit by a headlight".into(),
            n => format!(
                "{n} light(s){}",
                if self.mode == Mode::Cast { "" } else { " with shadows" }
            ),
        }
    }
}

/// The camera `--eye`, `--target`, `--up` and `--vfov` set on `scene`, and the mode and lights
/// the frames are shaded with. What cannot apply is refused naming the option: heat (the two
/// levels' queries count no traversal work) and shadows without `--light` (the headlight's
/// fall behind what it lights, out of sight); trace is shadow here, as nothing reflects.
fn view(a: &RenderArgs, scene: &mut Tumbling, notes: &mut Vec<String>) -> gridtrace::Result<View> {
    let center = scene.center();
    scene.camera = a.camera_over(scene.camera);
    scene
        .camera
        .validate()
        .map_err(|e| Error::InvalidInput(format!("{}: {e}", a.camera_args())))?;
    let lights = a.lights(center);
    let mode = a.mode_given().unwrap_or(Mode::Cast);
    match mode {
        Mode::Heat => {
            return Err(Error::InvalidInput(format!(
                "--mode heat: {} traces through a QueryScene's two levels, which count no traversal work; \
                 use --mode cast, shadow or trace",
                tumbling::NAME
            )));
        }
        Mode::Shadow | Mode::Trace if lights.is_empty() => {
            return Err(Error::InvalidInput(format!(
                "--mode {}: {} is lit by a headlight (a light at the eye), whose shadows fall behind what \
                 it lights; give the lights to cast shadows with --light X,Y,Z",
                mode.name(),
                tumbling::NAME
            )));
        }
        Mode::Trace => notes.push(format!(
            "--mode trace: nothing in {} reflects, so its frames are --mode shadow's",
            tumbling::NAME
        )),
        Mode::Cast | Mode::Shadow => {}
    }
    Ok(View { mode, lights })
}

/// `--instance-mesh`, else the Bunny in the mesh folder; a missing file is an error naming it
/// and how to give another.
fn mesh_path(a: &RenderArgs) -> gridtrace::Result<PathBuf> {
    if let Some(p) = &a.instance_mesh {
        return Ok(p.clone());
    }
    let Some(dir) = gridtrace_bench::scenes::find_data_dir(None) else {
        return Err(Error::InvalidInput(format!(
            "{}: no mesh folder holding {BUNNY} (set GRIDTRACE_DATA_DIR to it, or give --instance-mesh PATH)",
            tumbling::NAME
        )));
    };
    let path = dir.join(BUNNY);
    if !path.is_file() {
        return Err(Error::InvalidInput(format!(
            "{}: {}: no such file (the Stanford Bunny; set GRIDTRACE_DATA_DIR to a folder holding {BUNNY}, \
             or give --instance-mesh PATH)",
            tumbling::NAME,
            path.display()
        )));
    }
    Ok(path)
}

/// `--accel` with `--accel-params`; `auto` is the BVH here (the scene's queries' structure
/// under a top level, on the CPU and on the GPU).
fn accel_spec(a: &RenderArgs, notes: &mut Vec<String>) -> gridtrace::Result<AccelSpec> {
    let spec = a.accel_args.spec()?;
    Ok(match spec.choice {
        AccelChoice::Auto => {
            notes.push(format!("--accel auto: bvh for {}'s mesh", tumbling::NAME));
            AccelSpec::from(AccelKind::Bvh)
        }
        AccelChoice::Kind(_) => spec,
    })
}

fn accel_name(spec: &AccelSpec) -> &'static str {
    match spec.choice {
        AccelChoice::Kind(k) => k.name(),
        AccelChoice::Auto => "auto",
    }
}
