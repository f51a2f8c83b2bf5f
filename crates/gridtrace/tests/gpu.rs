//! GPU backend against the CPU path, on whatever adapter is present (lavapipe in CI).
//!
//! These tests fail, not skip, when no adapter is found: CI installs lavapipe, and a GPU test
//! that silently skips proves nothing. Set GRIDTRACE_SKIP_GPU=1 to skip them knowingly.

use std::sync::Mutex;

use glam::Vec3;
use gridtrace::accel::{Accel, AccelKind, Hit, NoCounters, Resolution};
use gridtrace::gpu::{GpuContext, GpuRenderer};
use gridtrace::scene::{PointLight, PreparedScene, builtin};
use gridtrace::testing::{differing_pixels, gpu_kinds, ray_set};
use gridtrace::{Mode, RenderOptions};

// One test at a time on the device: lavapipe uses every core for each dispatch anyway.
static GPU_LOCK: Mutex<()> = Mutex::new(());

fn renderer(scene: &PreparedScene) -> Option<GpuRenderer> {
    if std::env::var_os("GRIDTRACE_SKIP_GPU").is_some() {
        eprintln!("GRIDTRACE_SKIP_GPU is set: skipping");
        return None;
    }
    let ctx =
        GpuContext::new().unwrap_or_else(|e| panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}"));
    eprintln!("adapter: {}", ctx.describe());
    Some(
        GpuRenderer::new(std::sync::Arc::new(ctx), scene, &gridtrace::gpu::GpuVariants::default())
            .expect("upload scene"),
    )
}

/// Same hit or miss; t within a relative 1e-4 (the GPU compiler may fuse multiply-adds);
/// same triangle except at ties, where the CPU's triangle is hit at the GPU's t.
fn agree(accel: &Accel, r: &gridtrace::Ray, cpu: &Hit, gpu: &Hit) -> bool {
    if cpu.is_hit() != gpu.is_hit() {
        return false;
    }
    if !cpu.is_hit() {
        return true;
    }
    let close = |a: f32, b: f32| (a - b).abs() <= 1e-4 * a.abs().max(b.abs()).max(1e-6);
    if !close(cpu.t, gpu.t) {
        return false;
    }
    // A different triangle is a tie if the CPU also hits it at that t, or if the CPU's hit lies
    // on an edge or vertex (where neighbours share the point).
    let on_edge = cpu.u.min(cpu.v).min(1.0 - cpu.u - cpu.v) < 1e-5;
    cpu.tri == gpu.tri
        || on_edge
        || accel.tris[gpu.tri as usize]
            .intersect(r.origin, r.dir, 0.0, f32::INFINITY)
            .is_some_and(|h| close(h.t, cpu.t))
}

/// The scene prepared for each structure, with its GPU renderer: the grid (which serves `grid`
/// and `pc`), then one for every kind with a structure of its own (the BVH, the irregular grid).
type Prepared = Vec<(PreparedScene, Option<GpuRenderer>)>;

fn prepared(scene: &PreparedScene) -> Prepared {
    let first = renderer(scene);
    // `hwrt` where the adapter has ray queries (and under CI=1 always: `gpu_runs`).
    let kinds = first.as_ref().map_or(Vec::new(), |g| gpu_kinds(g.context()));
    let mut p = vec![(scene.clone(), first)];
    for kind in kinds.into_iter().filter(|k| !k.uses_grid()) {
        let s = scene.with_accel(kind, &gridtrace::AccelParams::NONE).unwrap();
        let g = renderer(&s);
        p.push((s, g));
    }
    p
}

/// The built-in scene `name` at the default resolution, prepared for every structure with its
/// renderer; `None` when the GPU tests are skipped.
fn builtin_prepared(name: &str) -> Option<Prepared> {
    let scene = builtin::scene(name).unwrap().prepare(Resolution::default()).unwrap();
    let p = prepared(&scene);
    p[0].1.is_some().then_some(p)
}

/// The kinds some prepared scene serves: every kind the GPU tests run here.
fn kinds_of(p: &Prepared) -> Vec<AccelKind> {
    AccelKind::ALL
        .into_iter()
        .filter(|k| p.iter().any(|(s, _)| s.accel.structure_id() == k.structure()))
        .collect()
}

/// The prepared scene whose structure serves `kind`, and its renderer, both switched to it
/// (`set_traversal`: the grid serves `grid` and `pc`).
fn for_kind(p: &mut Prepared, kind: AccelKind) -> (&PreparedScene, &mut GpuRenderer) {
    let (s, g) = p
        .iter_mut()
        .find(|(s, _)| s.accel.structure_id() == kind.structure())
        .unwrap_or_else(|| panic!("no prepared scene serves {}", kind.name()));
    s.accel.set_traversal(kind).unwrap();
    let g = g.as_mut().unwrap();
    g.set_traversal(kind).unwrap();
    (s, g)
}

fn per_ray_agreement(scene_name: &str, res: Resolution) {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let scene = builtin::scene(scene_name).unwrap().prepare(res).unwrap();
    let mut p = prepared(&scene);
    if p[0].1.is_none() {
        return;
    }
    let rays = ray_set(&scene.accel, 100_000, 77);
    for kind in kinds_of(&p) {
        let (scene, gpu) = for_kind(&mut p, kind);
        let accel = &scene.accel;
        let cpu_hits: Vec<Hit> = rays.iter().map(|r| accel.intersect(r, &mut NoCounters)).collect();
        let gpu_hits = gpu.intersect(&rays).unwrap();
        assert_eq!(gpu_hits.len(), rays.len());
        let bad: Vec<_> = (0..rays.len())
            .filter(|&i| !agree(accel, &rays[i], &cpu_hits[i], &gpu_hits[i]))
            .collect();
        // Rays through exact edges and corners may round either way on different hardware; a
        // handful (1 in 10,000) may differ, never more. `hwrt` is the driver's triangle test,
        // not ours: lavapipe's (Mesa 25.0.7) lets rays aimed exactly at a shared edge or vertex
        // through (311 and 535 of these 100,000), so it is held to `DRIVER_LEAKS`.
        let allowed = allowed_differences(kind, rays.len());
        eprintln!(
            "{scene_name} {}: {} of {} rays disagree",
            kind.name(),
            bad.len(),
            rays.len()
        );
        assert!(
            bad.len() <= allowed,
            "{scene_name} {}: {} rays disagree; first: {:?}",
            kind.name(),
            bad.len(),
            bad.iter()
                .take(3)
                .map(|&i| (rays[i], cpu_hits[i], gpu_hits[i]))
                .collect::<Vec<_>>()
        );
        let hits = cpu_hits.iter().filter(|h| h.is_hit()).count();
        assert!(hits > rays.len() / 10);
        // Any hit, with t_max at the CPU's closest hit (+-) and unbounded.
        let cpu_occ: Vec<bool> = rays.iter().map(|r| accel.occluded(r, &mut NoCounters)).collect();
        let gpu_occ = gpu.occluded(&rays).unwrap();
        let bad_occ = cpu_occ.iter().zip(&gpu_occ).filter(|(a, b)| a != b).count();
        assert!(
            bad_occ <= allowed,
            "{scene_name} {}: {bad_occ} occlusion results disagree",
            kind.name()
        );
        assert!(gpu_occ.iter().filter(|o| **o).count().abs_diff(hits) <= allowed);
    }
}

/// The rays of a set of `n` whose answers may differ from the CPU's: 1 in 10,000 for our own
/// triangle test, `DRIVER_LEAKS` of them for a structure the driver intersects (`hwrt`).
fn allowed_differences(kind: AccelKind, n: usize) -> usize {
    if kind.entry().cpu {
        n / 10_000
    } else {
        (n as f64 * DRIVER_LEAKS) as usize
    }
}

/// The share of these adversarial rays (a third aimed exactly at shared edges and vertices) the
/// driver's ray-query triangle test may answer otherwise than ours: lavapipe (Mesa 25.0.7) let
/// rays aimed exactly at shared edges and vertices through, 311 of the knot box's 100,000 and
/// 535 of the sparse room's (2026-11-27). Measured, not hidden (each run prints its count):
/// a watertight hardware test should meet the 1 in 10,000 the others meet.
const DRIVER_LEAKS: f64 = 0.01;

#[test]
fn per_ray_knot_box() {
    per_ray_agreement("knot-box", Resolution::default());
}

#[test]
fn per_ray_mirror_spheres() {
    per_ray_agreement("mirror-spheres", Resolution::default());
}

#[test]
fn per_ray_sparse_room_pc() {
    per_ray_agreement("sparse-room", Resolution::Fixed([48, 48, 48]));
}

/// A GPU scene switches to the kinds its structure serves (the grid's `grid` and `pc`, in
/// place) and refuses the others with an error that names the kind asked for, as the CPU's
/// `Accel::set_traversal`; a switched renderer then walks the kind it was switched to.
#[test]
fn uploads_serve_their_kinds_only() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let Some(mut p) = builtin_prepared("knot-box") else {
        return;
    };
    let rays = ray_set(&p[0].0.accel, 100, 5);
    for (s, g) in &mut p {
        let gpu = g.as_mut().unwrap();
        for kind in AccelKind::ALL {
            let serves = s.accel.structure_id() == kind.structure();
            let switched = gpu.set_traversal(kind);
            assert_eq!(
                switched.is_ok(),
                serves,
                "{} on a {}",
                kind.name(),
                s.accel.structure_name()
            );
            let cpu = s.accel.clone().with_traversal(kind);
            assert_eq!(
                cpu.is_ok(),
                serves,
                "{} on a CPU {}",
                kind.name(),
                s.accel.structure_name()
            );
            match switched {
                Err(e) => assert!(e.to_string().contains(&format!("'{}'", kind.name())), "{e}"),
                Ok(()) => {
                    assert_eq!(gpu.kind(), kind);
                    assert!(gpu.intersect(&rays).is_ok());
                }
            }
        }
    }
}

/// Images of the built-in scenes in every mode equal the CPU's: at most 0.5% of pixels may
/// differ by more than 2 levels (rays through exact edges, shadow boundaries), and ray counts
/// by kind are equal up to those pixels.
#[test]
fn images_match_cpu() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    for name in ["knot-box", "mirror-spheres"] {
        let scene = builtin::scene(name).unwrap().prepare(Resolution::default()).unwrap();
        let mut p = prepared(&scene);
        if p[0].1.is_none() {
            return;
        }
        for mode in Mode::ALL {
            for accel in kinds_of(&p) {
                let (scene, gpu) = for_kind(&mut p, accel);
                let opts = RenderOptions::new(160, 120, mode);
                let (ci, cs) = gridtrace::cpu::render(scene, &opts, None).unwrap();
                let (gi, gs) = gpu.render(&scene.camera, &scene.lights, &opts).unwrap();
                if mode == Mode::Heat && matches!(accel, AccelKind::Bvh | AccelKind::Hwrt) {
                    // The CPU walks eight-wide nodes, the GPU two-wide ones (`hwrt`: the
                    // driver's, counted one per ray query, against its CPU side's BVH): their
                    // costs differ by design. The GPU's heat is its own count: nonzero exactly
                    // where the ray entered the scene's box, and never for a ray that missed it.
                    let lit = gi.pixels().iter().filter(|p| p.x > 0.0).count();
                    let cpu_lit = ci.pixels().iter().filter(|p| p.x > 0.0).count();
                    assert!(
                        lit.abs_diff(cpu_lit) * 200 <= cpu_lit,
                        "{name} {} heat: {lit} vs {cpu_lit}",
                        accel.name()
                    );
                    continue;
                }
                let (ci, gi) = if mode == Mode::Heat {
                    // Heat values are raw counts: compare them directly.
                    let same = ci.pixels().iter().zip(gi.pixels()).filter(|(a, b)| a.x != b.x).count();
                    assert!(
                        same * 200 <= ci.pixels().len(),
                        "{name} heat {}: {same} pixels differ",
                        accel.name()
                    );
                    (ci.heat_to_color(), gi.heat_to_color())
                } else {
                    (ci, gi)
                };
                let frac = differing_pixels(&ci.to_rgb8(), &gi.to_rgb8(), 2);
                assert!(
                    frac <= 0.005,
                    "{name} {} {}: {:.3}% of pixels differ",
                    mode.name(),
                    accel.name(),
                    frac * 100.0
                );
                assert_eq!(cs.rays.eye, gs.render.rays.eye);
                let tol = |a: u64, b: u64| a.abs_diff(b) * 200 <= a.max(1);
                assert!(
                    tol(cs.rays.shadow, gs.render.rays.shadow),
                    "{name} {}: shadow rays {} vs {}",
                    mode.name(),
                    cs.rays.shadow,
                    gs.render.rays.shadow
                );
                assert!(
                    tol(cs.rays.reflection, gs.render.rays.reflection),
                    "{name}: reflection rays {} vs {}",
                    cs.rays.reflection,
                    gs.render.rays.reflection
                );
                if mode == Mode::Trace && name == "mirror-spheres" {
                    assert!(gs.render.rays.reflection > 1000);
                }
            }
        }
    }
}

/// Camera and lights changed between frames give the same images as a fresh renderer.
#[test]
fn dynamic_camera_and_lights() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let scene = builtin::scene("mirror-spheres")
        .unwrap()
        .prepare(Resolution::default())
        .unwrap();
    let Some(mut gpu) = renderer(&scene) else { return };
    let opts = RenderOptions::new(96, 96, Mode::Trace);
    let mut cam2 = scene.camera;
    cam2.eye = Vec3::new(-3.0, 1.5, 4.0);
    let lights2 = vec![
        PointLight::new(Vec3::new(2.0, 4.0, 2.0), Vec3::splat(15.0)),
        PointLight::new(Vec3::new(-2.0, 2.0, 3.0), Vec3::new(3.0, 1.0, 1.0)),
        PointLight::new(Vec3::new(0.0, 5.0, -3.0), Vec3::splat(8.0)),
    ];
    let (first, _) = gpu.render(&scene.camera, &scene.lights, &opts).unwrap();
    let (second, _) = gpu.render(&cam2, &lights2, &opts).unwrap();
    let (third, _) = gpu.render(&scene.camera, &scene.lights, &opts).unwrap();
    assert_eq!(first, third, "returning to the first camera gives the first image");
    assert_ne!(first, second);
    let mut moved = scene.clone();
    moved.camera = cam2;
    moved.lights = lights2;
    let Some(mut fresh) = renderer(&moved) else { return };
    let (want, _) = fresh.render(&moved.camera, &moved.lights, &opts).unwrap();
    assert_eq!(second, want);
    // And the CPU agrees with the changed frame.
    let (cpu, _) = gridtrace::cpu::render(&moved, &opts, None).unwrap();
    assert!(differing_pixels(&cpu.to_rgb8(), &second.to_rgb8(), 2) <= 0.005);
}

/// The lights are a uniform array of `MAX_LIGHTS` (one storage buffer fewer for WebGPU's limit):
/// a frame with that many reads the last one as the CPU does (255 dark lights, then the one
/// that lights the scene), and one more is refused with a message naming the limit, after which
/// the renderer still renders.
#[test]
fn lights_up_to_the_uniform_arrays_length() {
    use gridtrace::gpu::constants::MAX_LIGHTS;
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let scene = builtin::scene("knot-box")
        .unwrap()
        .prepare(Resolution::default())
        .unwrap();
    let Some(mut gpu) = renderer(&scene) else { return };
    let opts = RenderOptions::new(48, 48, Mode::Shadow);
    let mut lights: Vec<PointLight> = (0..MAX_LIGHTS - 1)
        .map(|i| PointLight::new(Vec3::new(i as f32 * 0.01, 3.0, 1.0), Vec3::ZERO))
        .collect();
    lights.push(scene.lights[0]);
    let (image, _) = gpu.render(&scene.camera, &lights, &opts).unwrap();
    let mut lit = scene.clone();
    lit.lights = lights.clone();
    let (cpu, _) = gridtrace::cpu::render(&lit, &opts, None).unwrap();
    assert!(differing_pixels(&cpu.to_rgb8(), &image.to_rgb8(), 2) <= 0.005);
    let (dark, _) = gpu.render(&scene.camera, &lights[..lights.len() - 1], &opts).unwrap();
    assert_ne!(dark, image, "the last light lights the scene");
    lights.push(scene.lights[0]);
    let err = gpu.render(&scene.camera, &lights, &opts).unwrap_err().to_string();
    assert!(
        err.contains(&format!("{} lights", MAX_LIGHTS + 1)) && err.contains("at most"),
        "{err}"
    );
    let (again, _) = gpu
        .render(&scene.camera, &lights[..MAX_LIGHTS as usize], &opts)
        .unwrap();
    assert_eq!(again, image);
}

/// The ablations (`bench --ablate`) change what runs, not what is seen: with shadow rays
/// finding closest hits, or without compacted queues, every structure's GPU image equals its
/// normal image bit for bit, and so does the CPU's with closest-hit shadow rays; ray counts
/// are the same.
#[test]
fn ablations_keep_images() {
    use gridtrace::render::Ablation;
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let Some(mut p) = builtin_prepared("mirror-spheres") else {
        return;
    };
    for accel in kinds_of(&p) {
        let (scene, gpu) = for_kind(&mut p, accel);
        for mode in [Mode::Shadow, Mode::Trace, Mode::Heat] {
            let base = RenderOptions::new(96, 72, mode);
            let (want, ws) = gpu.render(&scene.camera, &scene.lights, &base).unwrap();
            let (cpu_want, _) = gridtrace::cpu::render(scene, &base, None).unwrap();
            for name in Ablation::NAMES {
                let opts = RenderOptions {
                    ablation: Ablation::named(name).unwrap(),
                    ..base
                };
                let (got, gs) = gpu.render(&scene.camera, &scene.lights, &opts).unwrap();
                assert!(
                    got == want,
                    "gpu {} {} without {name}: the image changed",
                    accel.name(),
                    mode.name()
                );
                assert_eq!(
                    (gs.render.rays.shadow, gs.render.rays.reflection),
                    (ws.render.rays.shadow, ws.render.rays.reflection)
                );
                let (cpu_got, _) = gridtrace::cpu::render(scene, &opts, None).unwrap();
                assert!(
                    cpu_got == cpu_want,
                    "cpu {} {} without {name}",
                    accel.name(),
                    mode.name()
                );
            }
        }
    }
    assert!(Ablation::named("nonsense").is_none());
}

/// Per frame only uniforms and lights go to the device, whatever the scene's size: the camera,
/// the scene constants, the lights and three pass uniforms per tile (the paper's point: the
/// scene stays on the GPU while the view changes).
#[test]
fn per_frame_uploads_are_uniforms_only() {
    use gridtrace::gpu::layout::{PassUniform, SceneUniform};
    use gridtrace::scene::CameraFrame;
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    for name in ["knot-box", "sparse-room"] {
        let scene = builtin::scene(name).unwrap().prepare(Resolution::default()).unwrap();
        let Some(mut gpu) = renderer(&scene) else { return };
        let opts = RenderOptions::new(64, 48, Mode::Trace);
        let mut cam = scene.camera;
        let mut sizes = Vec::new();
        for _ in 0..3 {
            cam.eye += Vec3::new(0.05, 0.0, 0.0);
            let (_, s) = gpu.render(&cam, &scene.lights, &opts).unwrap();
            let want = (size_of::<CameraFrame>()
                + size_of::<SceneUniform>()
                + std::mem::size_of_val(&scene.lights[..])
                + s.tiles as usize * 3 * size_of::<PassUniform>()) as u64;
            assert_eq!(s.uploaded_bytes, want, "{name}");
            sizes.push(s.uploaded_bytes);
        }
        assert!(
            sizes.iter().all(|&b| b < 1024),
            "{name}: {sizes:?} ({} triangles)",
            scene.accel.tris.len()
        );
    }
}

/// A frame of many tiles (the largest tile lowered to 1,000 pixels: a 64x48 frame is 4 tiles, as
/// a 4096x4096 frame is 16 on any device) is one submission and one wait, and equals the frame
/// traced as one tile bit for bit, in every mode; the bytes read back are the image's 16 a
/// pixel plus 64 of counters a tile (and the timestamps where the adapter has them).
#[test]
fn a_frame_of_many_tiles_is_one_round_trip() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let scene = builtin::knot_box()
        .prepare_for(AccelKind::ProximityCloud, &gridtrace::AccelParams::NONE)
        .unwrap();
    let Some(mut whole) = renderer(&scene) else { return };
    let Some(mut tiled) = renderer(&scene) else { return };
    tiled.set_max_tile_pixels(1000);
    for mode in [Mode::Cast, Mode::Shadow, Mode::Trace, Mode::Heat] {
        let opts = RenderOptions::new(64, 48, mode);
        let (a, sa) = whole.render(&scene.camera, &scene.lights, &opts).unwrap();
        let (b, sb) = tiled.render(&scene.camera, &scene.lights, &opts).unwrap();
        assert_eq!((sa.tiles, sb.tiles), (1, 4), "{mode:?}");
        assert_eq!((sa.round_trips, sb.round_trips), (1, 1), "{mode:?}");
        assert_eq!(a.pixels(), b.pixels(), "{mode:?}: tiles changed the image");
        assert_eq!(sa.render.rays, sb.render.rays, "{mode:?}");
        if !sb.timings.from_timestamps {
            assert_eq!(sb.downloaded_bytes, 64 * 48 * 16 + 4 * 64, "{mode:?}");
        } else {
            assert!(sb.downloaded_bytes > 64 * 48 * 16 + 4 * 64, "{mode:?}");
        }
        assert!(sb.wall_ms > 0.0 && sb.frame_ms() == sb.wall_ms);
        host_phases_account_for_the_wall(&sb.timings, sb.wall_ms);
    }
}

/// A frame left on the device (`render_to_device`, what the viewer presents from) is the frame
/// `render` reads back as 8-bit sRGB, bit for bit, whole or band by band over many tiles; its
/// one round trip carries the counters and timestamps and no image; heat, a wrong size and
/// another device's image are errors, not a wrong picture.
#[test]
fn frames_left_on_the_device_equal_read_back_frames() {
    use gridtrace::gpu::DeviceImage;
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let scene = builtin::knot_box()
        .prepare_for(AccelKind::ProximityCloud, &gridtrace::AccelParams::NONE)
        .unwrap();
    let Some(mut gpu) = renderer(&scene) else { return };
    gpu.set_max_tile_pixels(1000);
    let (w, h) = (64u32, 48u32);
    let (cam, lights) = (scene.camera, scene.lights.clone());
    let whole = DeviceImage::new(gpu.context(), w, h).unwrap();
    let banded = DeviceImage::new(gpu.context(), w, h).unwrap();
    for mode in [Mode::Cast, Mode::Shadow, Mode::Trace] {
        let opts = RenderOptions::new(w, h, mode).with_pixels(gridtrace::PixelFormat::Srgb8);
        let (want, sw) = gpu.render(&cam, &lights, &opts).unwrap();
        // The device image is 8-bit sRGB whatever the options ask.
        let linear = RenderOptions {
            pixels: gridtrace::PixelFormat::Linear,
            ..opts
        };
        let s = gpu.render_to_device(&cam, &lights, &linear, &whole).unwrap();
        assert_eq!((s.tiles, s.round_trips), (4, 1), "{mode:?}");
        assert_eq!(s.render.rays, sw.render.rays, "{mode:?}");
        assert_eq!(
            sw.downloaded_bytes - s.downloaded_bytes,
            (w * h * 4) as u64,
            "{mode:?}: the device frame reads back all but its image"
        );
        host_phases_account_for_the_wall(&s.timings, s.wall_ms);
        assert!(
            whole.read().unwrap().pixels() == want.pixels(),
            "{mode:?}: the device image differs"
        );
        for (first, end) in [(0, 7), (7, 30), (30, 48)] {
            gpu.render_to_device(&cam, &lights, &opts.band(first, end), &banded)
                .unwrap();
        }
        assert!(
            banded.read().unwrap().pixels() == want.pixels(),
            "{mode:?}: bands out of place"
        );
    }
    let heat = RenderOptions::new(w, h, Mode::Heat);
    assert!(gpu.render_to_device(&cam, &lights, &heat, &whole).is_err());
    let small = RenderOptions::new(w - 1, h, Mode::Cast);
    assert!(gpu.render_to_device(&cam, &lights, &small, &whole).is_err());
    let other = std::sync::Arc::new(GpuContext::new().unwrap());
    let elsewhere = DeviceImage::new(&other, w, h).unwrap();
    let cast = RenderOptions::new(w, h, Mode::Cast);
    let e = gpu.render_to_device(&cam, &lights, &cast, &elsewhere).unwrap_err();
    assert!(e.to_string().contains("another device"), "{e}");
    // An image over one storage binding (16 GiB here, beyond Vulkan's 32-bit binding range)
    // is refused before anything is allocated, saying why; the viewer and `view --headless`
    // then read such frames back.
    let e = DeviceImage::new(gpu.context(), 1 << 16, 1 << 16)
        .err()
        .expect("refused");
    assert!(e.to_string().contains("binds"), "{e}");
    // The errors left the renderer whole.
    gpu.render_to_device(&cam, &lights, &cast, &whole).unwrap();
}

/// The host's phases of a frame or batch are each positive, add up to its wall time, and the
/// wait holds the device's work: the stages' timestamps fall between the submission and the
/// mapped results (with 2% and 1 ms for the clocks' conversion).
fn host_phases_account_for_the_wall(t: &gridtrace::gpu::GpuTimings, wall_ms: f64) {
    let h = t.host;
    assert!(h.prepare_ms >= 0.0 && h.wait_ms > 0.0 && h.readout_ms >= 0.0, "{h:?}");
    let sum = h.prepare_ms + h.wait_ms + h.readout_ms;
    assert!(
        (sum - wall_ms).abs() <= 1e-6 * wall_ms.max(1.0),
        "{h:?} against wall {wall_ms}"
    );
    if t.from_timestamps {
        assert!(
            t.total_ms <= 1.02 * h.wait_ms + 1.0,
            "GPU {} ms outside a wait of {h:?}",
            t.total_ms
        );
    }
}

/// `PixelFormat::Srgb8`: the device packs the pixels to 8-bit sRGB and the frame reads back 4
/// bytes a pixel instead of 16; its PNG bytes equal the linear frame's within one level (the
/// device's `pow` against the host's, on a rounding boundary) and the other pixels exactly; on
/// many tiles too. Heat frames keep their raw costs (16 bytes, the same floats).
#[test]
fn srgb8_frames_read_back_four_bytes_a_pixel() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let scene = builtin::knot_box()
        .prepare_for(AccelKind::ProximityCloud, &gridtrace::AccelParams::NONE)
        .unwrap();
    let Some(mut gpu) = renderer(&scene) else { return };
    gpu.set_max_tile_pixels(1000);
    for mode in [Mode::Cast, Mode::Shadow, Mode::Trace, Mode::Heat] {
        let linear = RenderOptions::new(64, 48, mode);
        let srgb8 = linear.with_pixels(gridtrace::PixelFormat::Srgb8);
        let (a, sa) = gpu.render(&scene.camera, &scene.lights, &linear).unwrap();
        let (b, sb) = gpu.render(&scene.camera, &scene.lights, &srgb8).unwrap();
        assert_eq!((sb.tiles, sb.round_trips), (4, 1), "{mode:?}");
        assert_eq!(sa.render.rays, sb.render.rays, "{mode:?}");
        if mode == Mode::Heat {
            assert_eq!(a.pixels(), b.pixels(), "heat keeps its raw costs");
            assert_eq!(sa.downloaded_bytes, sb.downloaded_bytes);
            continue;
        }
        let (ra, rb) = (a.to_rgb8(), b.to_rgb8());
        assert_eq!(
            differing_pixels(&ra, &rb, 1),
            0.0,
            "{mode:?}: more than one level apart"
        );
        let exact = ra.iter().zip(&rb).filter(|(x, y)| x == y).count();
        assert!(
            exact * 100 >= ra.len() * 99,
            "{mode:?}: {exact} of {} channels equal",
            ra.len()
        );
        assert!(
            rb.iter().any(|&c| c > 0) && rb.iter().any(|&c| c < 255),
            "{mode:?}: a blank frame"
        );
        // The counters are the same in both; the image is 12 bytes a pixel less, and where the
        // adapter has timestamps each tile's pack pass adds a begin and an end (16 bytes).
        let stamps = if sb.timings.from_timestamps { 4 * 16 } else { 0 };
        assert_eq!(
            sa.downloaded_bytes - sb.downloaded_bytes,
            64 * 48 * 12 - stamps,
            "{mode:?}"
        );
    }
}

/// Rays with an interval each, 32 bytes on the wire (origin, t_min, direction, t_max).
struct RaysWithIntervals(Vec<[f32; 8]>);

impl gridtrace::gpu::WireSource for RaysWithIntervals {
    fn len(&self) -> usize {
        self.0.len()
    }
    fn stride(&self) -> usize {
        8
    }
    fn write(&self, first: usize, mut out: wgpu::WriteOnly<'_, [u8]>) -> bool {
        let n = out.len() / 32;
        out.copy_from_slice(bytemuck::cast_slice(&self.0[first..first + n]));
        true
    }
    fn invalid(&self) -> gridtrace::Error {
        gridtrace::Error::InvalidInput("checked".into())
    }
}

/// A ray batch of many chunks (the chunk size lowered, as a batch of millions is cut on any
/// device) is pipelined, two chunks in flight, one submission and one readback a chunk, and
/// gives the one-chunk batch's answers bit for bit, in every answer form: hits with u, v (16
/// bytes a ray down), (t, triangle) pairs (8), occlusion bits; rays with their own intervals
/// (32 bytes up) answer as the same rays given one interval for all. Its statistics count the
/// rays, chunks and bytes: 24 bytes a ray up besides each chunk's constants.
#[test]
fn a_pipelined_batch_of_many_chunks_equals_one_chunk() {
    use gridtrace::gpu::{Answer, ChunkAnswers, RaySlice, TriHit};
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let Some(mut whole) = renderer(&scene) else { return };
    let Some(mut chunked) = renderer(&scene) else { return };
    chunked.set_max_tile_pixels(700);
    let rays = ray_set(&scene.accel, 2500, 11);
    let kind = AccelKind::ProximityCloud;
    whole.set_traversal(kind).unwrap();
    chunked.set_traversal(kind).unwrap();
    let want = whole.intersect(&rays).unwrap();
    assert_eq!(whole.last_query_stats().chunks, 1);
    let got = chunked.intersect(&rays).unwrap();
    let same = |a: &Hit, b: &Hit| {
        a.tri == b.tri
            && a.t.to_bits() == b.t.to_bits()
            && a.u.to_bits() == b.u.to_bits()
            && a.v.to_bits() == b.v.to_bits()
    };
    assert!(want.iter().zip(&got).all(|(a, b)| same(a, b)));
    assert!(want.iter().any(|h| h.is_hit()) && want.iter().any(|h| !h.is_hit()));
    let s = chunked.last_query_stats().clone();
    assert_eq!((s.rays, s.chunks, s.round_trips), (2500, 4, 4));
    let stamps = |s: &gridtrace::gpu::GpuQueryStats, passes: u64| {
        if s.timings.from_timestamps {
            s.chunks as u64 * passes * 2 * 8
        } else {
            0
        }
    };
    assert_eq!(s.downloaded_bytes, 2500 * 16 + stamps(&s, 3));
    // 24 bytes a ray, and per chunk its counters (64), batch constants (48: the interval, the
    // rays' mask and a scan's sensor layout, padded) and the three bounces' pass uniforms
    // (3 x 48).
    assert_eq!(s.uploaded_bytes, 2500 * 24 + 4 * (64 + 48 + 3 * 48));
    // The phases add up to the wall time; the device's work overlaps the host's preparation
    // of the next chunk (that is the pipelining), so it lies within the wall, not the waits.
    let h = s.timings.host;
    assert!(h.prepare_ms >= 0.0 && h.wait_ms > 0.0 && h.readout_ms >= 0.0, "{h:?}");
    assert!((h.prepare_ms + h.wait_ms + h.readout_ms - s.wall_ms).abs() <= 1e-6 * s.wall_ms.max(1.0));
    assert!(
        !s.timings.from_timestamps || s.timings.total_ms <= 1.02 * s.wall_ms + 1.0,
        "{s:?}"
    );
    // One chunk is one submission, waited for as before: its device time lies in its wait.
    host_phases_account_for_the_wall(&whole.last_query_stats().timings, whole.last_query_stats().wall_ms);

    // (t, triangle) only: 8 bytes a ray down, the same bits.
    let mut pairs = vec![TriHit { t: 0.0, tri: 0 }; rays.len()];
    chunked
        .cast(
            &RaySlice::new(&rays),
            (0.0, f32::INFINITY),
            Answer::Hits { uv: false },
            |first, a| {
                let ChunkAnswers::Hits(h) = a else {
                    panic!("asked for (t, triangle)")
                };
                pairs[first..first + h.len()].copy_from_slice(h);
            },
        )
        .unwrap();
    assert!(
        want.iter()
            .zip(&pairs)
            .all(|(a, b)| a.tri == b.tri && a.t.to_bits() == b.t.to_bits())
    );
    let s = chunked.last_query_stats().clone();
    assert_eq!(s.downloaded_bytes, 2500 * 8 + stamps(&s, 4));

    // Occlusion: one bit a ray down, the one-chunk batch's answers, and the closest hits'.
    let want_occ = whole.occluded(&gridtrace::testing::within(&rays, 0.0, 10.0)).unwrap();
    let got_occ = chunked.occluded(&gridtrace::testing::within(&rays, 0.0, 10.0)).unwrap();
    assert_eq!(want_occ, got_occ);
    assert!(want_occ.iter().any(|&o| o) && want_occ.iter().any(|&o| !o));
    for (h, &o) in want.iter().zip(&want_occ) {
        assert_eq!(o, h.is_hit() && h.t < 10.0);
    }
    let s = chunked.last_query_stats().clone();
    assert_eq!((s.rays, s.chunks, s.round_trips), (2500, 4, 4));
    // 700 rays a chunk: 22 words each, the last chunk's 400 rays 13.
    assert_eq!(s.downloaded_bytes, (3 * 22 + 13) * 4 + stamps(&s, 4));

    // Each ray its own interval (32 bytes up): every other ray's [0, 10), the rest [2, 8).
    let within: Vec<[f32; 8]> = rays
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let (t0, t1) = if i % 2 == 0 { (0.0, 10.0) } else { (2.0, 8.0) };
            [r.origin.x, r.origin.y, r.origin.z, t0, r.dir.x, r.dir.y, r.dir.z, t1]
        })
        .collect();
    let mut occ = vec![false; rays.len()];
    chunked
        .cast(&RaysWithIntervals(within), (0.0, 0.0), Answer::Occlusion, |first, a| {
            let ChunkAnswers::Occlusion(bits) = a else {
                panic!("asked for occlusion")
            };
            let end = (first + bits.len() * 32).min(occ.len());
            gridtrace::gpu::unpack_bits(bits, &mut occ[first..end]);
        })
        .unwrap();
    let narrow = whole.occluded(&gridtrace::testing::within(&rays, 2.0, 8.0)).unwrap();
    for i in 0..rays.len() {
        assert_eq!(occ[i], if i % 2 == 0 { want_occ[i] } else { narrow[i] }, "ray {i}");
    }
    assert!(chunked.last_query_stats().uploaded_bytes >= 2500 * 32);
}

/// Batches one after another on one renderer, growing and shrinking (the mapped upload kept,
/// made anew when too small, mapped again after each submission), of many chunks and of one
/// ray, closest and any hit in turn: each answers exactly as a fresh renderer's first batch
/// (which writes into a buffer mapped at creation), so no batch reads another's records.
#[test]
fn consecutive_batches_answer_as_fresh_ones() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let scene = builtin::knot_box().prepare(Resolution::default()).unwrap();
    let Some(mut kept) = renderer(&scene) else { return };
    kept.set_max_tile_pixels(700);
    let rays = ray_set(&scene.accel, 3000, 5);
    let kind = AccelKind::ProximityCloud;
    kept.set_traversal(kind).unwrap();
    for (k, (first, n)) in [(0, 1000), (7, 10), (100, 2900), (2999, 1), (50, 2000), (1, 2999)]
        .into_iter()
        .enumerate()
    {
        let batch = &rays[first..first + n];
        let Some(mut fresh) = renderer(&scene) else { return };
        fresh.set_max_tile_pixels(700);
        fresh.set_traversal(kind).unwrap();
        if k % 2 == 0 {
            let got = kept.intersect(batch).unwrap();
            let want = fresh.intersect(batch).unwrap();
            assert_eq!(got.len(), n);
            let same = got
                .iter()
                .zip(&want)
                .all(|(a, b)| a.tri == b.tri && a.t.to_bits() == b.t.to_bits());
            assert!(
                same,
                "batch {k} ({n} rays from {first}) differs from a fresh renderer's"
            );
        } else {
            let got = kept.occluded(&gridtrace::testing::within(batch, 0.0, 10.0)).unwrap();
            let want = fresh.occluded(&gridtrace::testing::within(batch, 0.0, 10.0)).unwrap();
            assert_eq!(got, want, "batch {k} ({n} rays from {first})");
        }
        assert_eq!(kept.last_query_stats().rays, n as u64);
    }
}

/// A band of rows (`RenderOptions::rows`, how the viewer traces a frame within its time budget)
/// equals the same rows of the whole frame, bit for bit, on the GPU and the CPU, in every mode
/// and for every structure; the bands' rays add up to the frame's. Bands that do not start at
/// a tile boundary, a one-row band and the last row are among them.
#[test]
fn bands_equal_rows_of_the_frame() {
    let _g = GPU_LOCK.lock().unwrap_or_else(|p| p.into_inner());
    let Some(mut p) = builtin_prepared("mirror-spheres") else {
        return;
    };
    let (w, h) = (53u32, 41u32);
    for accel in kinds_of(&p) {
        let (scene, gpu) = for_kind(&mut p, accel);
        for mode in Mode::ALL {
            let whole = RenderOptions::new(w, h, mode);
            let (gpu_whole, gpu_stats) = gpu.render(&scene.camera, &scene.lights, &whole).unwrap();
            let (cpu_whole, cpu_stats) = gridtrace::cpu::render(scene, &whole, None).unwrap();
            let (mut gpu_rays, mut cpu_rays) = (
                gridtrace::render::RayCounts::default(),
                gridtrace::render::RayCounts::default(),
            );
            for (first, end) in [(0, 7), (7, 8), (8, 40), (40, 41)] {
                let band = whole.band(first, end);
                let rows = (first * w) as usize..(end * w) as usize;
                let (g, gs) = gpu.render(&scene.camera, &scene.lights, &band).unwrap();
                let (c, cs) = gridtrace::cpu::render(scene, &band, None).unwrap();
                assert_eq!((g.width, g.height), (w, end - first));
                let what = format!("{} {} rows {first}..{end}", accel.name(), mode.name());
                assert!(*g.pixels() == gpu_whole.pixels()[rows.clone()], "gpu {what}");
                assert!(*c.pixels() == cpu_whole.pixels()[rows], "cpu {what}");
                gpu_rays += gs.render.rays;
                cpu_rays += cs.rays;
            }
            assert_eq!(gpu_rays, gpu_stats.render.rays);
            assert_eq!(cpu_rays, cpu_stats.rays);
        }
    }
    // Bands outside the image, or empty, are errors, not panics.
    let (scene, gpu) = for_kind(&mut p, AccelKind::Grid);
    for (first, end) in [(0, 0), (5, 3), (40, 42)] {
        let band = RenderOptions::new(w, h, Mode::Cast).band(first, end);
        assert!(gpu.render(&scene.camera, &scene.lights, &band).is_err());
        assert!(gridtrace::cpu::render(scene, &band, None).is_err());
    }
}

/// Where a scene is traced (`Backend`): `auto` sends a scene the device cannot hold (a grid
/// whose cells exceed the binding limit of lavapipe's 128 MiB) to the CPU with a note naming
/// the array, and `gpu` fails suggesting the CPU; a scene that fits goes to the device under
/// both. (The CLI's `auto` passes a software adapter over before this check; here the device
/// is given, as on a machine with a GPU.)
#[test]
fn backend_sends_a_scene_the_device_cannot_hold_to_the_cpu() {
    use gridtrace::{Backend, Placement};
    let _g = GPU_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    if std::env::var_os("GRIDTRACE_SKIP_GPU").is_some() {
        return;
    }
    let ctx = std::sync::Arc::new(
        GpuContext::new().unwrap_or_else(|e| panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}")),
    );
    let small = builtin::knot_box()
        .prepare_for(AccelKind::Grid, &Resolution::Fixed([8; 3]).into())
        .unwrap();
    for backend in [Backend::Auto, Backend::Gpu] {
        let mut notes = Vec::new();
        let up = Placement::on_device(backend, ctx.clone())
            .upload(&small, &mut notes)
            .unwrap();
        assert!(up.is_some() && notes.is_empty(), "{backend:?}: {notes:?}");
    }
    let cells = 300 * 300 * 160 * 12;
    if (cells as u64) <= ctx.limits().max_storage_buffer_binding_size {
        eprintln!("this device holds a {cells}-byte binding: nothing to fall back from");
        return;
    }
    let big = builtin::knot_box()
        .prepare_for(AccelKind::Grid, &Resolution::Fixed([300, 300, 160]).into())
        .unwrap();
    let mut notes = Vec::new();
    let up = Placement::on_device(Backend::Auto, ctx.clone())
        .upload(&big, &mut notes)
        .unwrap();
    assert!(up.is_none(), "auto kept a scene over the limit on the device");
    assert!(
        notes.len() == 1 && notes[0].contains("'cells'") && notes[0].contains("using the CPU"),
        "{notes:?}"
    );
    let e = Placement::on_device(Backend::Gpu, ctx)
        .upload(&big, &mut Vec::new())
        .err()
        .expect("gpu refuses it")
        .to_string();
    assert!(e.contains("'cells'") && e.contains("use --backend cpu"), "{e}");
}
