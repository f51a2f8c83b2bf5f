//! `gridtrace render --animate`: an animated scene played frame by frame, each frame timed as
//! the structures' dynamic paths are compared: moving the vertices (geometry), updating the
//! structure (build: the grids rebuilt, on the GPU with the GPU backend; the BVH refitted),
//! and tracing.

use std::time::Instant;

use gridtrace::scene::animated::Animation;
use gridtrace::{PixelFormat, RenderOptions};

use crate::render::RenderArgs;

pub fn run(a: &RenderArgs) -> gridtrace::Result<()> {
    let name = a.scene.scene.as_deref().unwrap_or("animated");
    // Rigid instances move the top level of two, not the vertices: a loop of their own.
    if name == gridtrace::scene::tumbling::NAME {
        return crate::animate_instances::run(a);
    }
    if a.instances.is_some() || a.instance_mesh.is_some() {
        return Err(gridtrace::Error::InvalidInput(format!(
            "--instances and --instance-mesh are for --scene {}, not {name}",
            gridtrace::scene::tumbling::NAME
        )));
    }
    if a.scene.file.is_some() || a.scene.mesh.is_some() {
        return Err(gridtrace::Error::InvalidInput(
            "--animate plays a built-in animated scene (--scene NAME), not a file".into(),
        ));
    }
    let mut anim = Animation::by_name(name).ok_or_else(|| {
        gridtrace::Error::InvalidInput(format!(
            "unknown animated scene '{name}'; animated scenes: {}, {}",
            Animation::NAMES.join(", "),
            gridtrace::scene::tumbling::NAME
        ))
    })?;
    if !(a.fps.is_finite() && a.fps > 0.0) {
        return Err(gridtrace::Error::InvalidInput(format!(
            "--fps must be positive, got {}",
            a.fps
        )));
    }
    // --eye, --target, --up, --vfov and --light, as a still frame takes them: the frames
    // below trace with the prepared scene's camera and lights.
    crate::render::set_view(a, &mut anim.scene, name);
    // Opened as a still frame's scene is (`--gpu-variant` with the rest), for animation.
    let opened = crate::render::open_scene(a, &anim.scene, name, gridtrace::Work::Animate)?;
    let (mut tracer, accel) = (opened.tracer, opened.accel);
    println!(
        "scene {name} (animated): {} triangles, {}; first build {:.1} ms",
        tracer.scene.accel.tris.len(),
        crate::common::describe_structure(&tracer.scene.accel),
        opened.build_ms
    );
    crate::render::print_tracer(&tracer, &opened.notes);
    if let Some(dir) = &a.sequence {
        std::fs::create_dir_all(dir).map_err(|e| gridtrace::Error::io(dir, e))?;
    }
    let opts = RenderOptions::new(a.res.0, a.res.1, a.mode()).with_pixels(PixelFormat::Srgb8);
    println!("frame  time_s  move_ms  geometry_ms  build_ms  trace_ms  total_ms  structure");
    let mut rows = Vec::with_capacity(a.frames as usize);
    for i in 0..a.frames {
        let time = i as f32 / a.fps;
        let t_frame = Instant::now();
        let t_move = Instant::now();
        let positions = anim.positions_at(time);
        let move_ms = t_move.elapsed().as_secs_f64() * 1e3;
        let up = tracer.update_vertices(&positions)?;
        let (camera, lights) = (tracer.scene.camera, tracer.scene.lights.clone());
        let frame = tracer.render(&camera, &lights, &opts)?;
        for n in tracer.take_notes() {
            println!("note: {n}");
        }
        let (image, trace_ms, build_ms, how) = (
            frame.image,
            frame.gpu.as_ref().map_or(frame.stats.render_ms, |g| g.frame_ms()),
            up.build_ms,
            up.how,
        );
        let total_ms = t_frame.elapsed().as_secs_f64() * 1e3;
        println!(
            "{i:5}  {time:6.3}  {move_ms:7.2}  {:11.2}  {build_ms:8.2}  {trace_ms:8.2}  {total_ms:8.2}  {how}",
            up.geometry_ms
        );
        rows.push([up.geometry_ms, build_ms, trace_ms]);
        let image = if a.mode() == gridtrace::Mode::Heat {
            image.heat_to_color()
        } else {
            image
        };
        crate::common::save_frame(&image, i, a.sequence.as_deref(), &a.output)?;
    }
    if rows.len() > 1 {
        let median = |k: usize| crate::common::median_after_first(&rows, k);
        // Named as the table numbers the frames (from 0), the last included.
        println!(
            "median of frames 1-{}: geometry {:.2} ms, build {:.2} ms, trace {:.2} ms [{} {} {}x{}]",
            rows.len() - 1,
            median(0),
            median(1),
            median(2),
            a.mode().name(),
            accel.name(),
            a.res.0,
            a.res.1
        );
    }
    println!("wrote   {}", a.output.display());
    Ok(())
}
