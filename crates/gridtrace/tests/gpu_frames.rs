//! Frames in flight (`Tracer::render_frames`): frame N+1 prepared and submitted before frame N
//! is read back must not change any frame. Every frame of a moving camera and moving lights, in
//! flight two and three deep, equals the same frame traced one by one bit for bit (pixels and
//! ray counts), read back or left in a device image; a fault in the middle of a run hands the
//! frames in flight to the CPU under `auto`, in order, none lost.
//!
//! Fails, not skips, without an adapter (lavapipe in CI); GRIDTRACE_SKIP_GPU=1 skips knowingly.

use gridtrace::AccelParams;
use std::sync::Arc;

use glam::{Quat, Vec3};
use gridtrace::accel::AccelKind;
use gridtrace::gpu::{DeviceImage, Fault, GpuContext};
use gridtrace::scene::{Camera, PointLight, PreparedScene, builtin};
use gridtrace::testing::skip_gpu;
use gridtrace::{Backend, FramesOptions, Image, Mode, PixelFormat, Placement, RenderOptions, Rendered, Tracer};

fn ctx() -> Arc<GpuContext> {
    Arc::new(GpuContext::new().expect("a GPU adapter (lavapipe in CI)"))
}

/// `n` views: the camera a turn round its target, the lights the other way, so no two frames
/// share their uniforms.
fn views(scene: &PreparedScene, n: usize) -> Vec<(Camera, Vec<PointLight>)> {
    (0..n)
        .map(|i| {
            let turn = i as f32 / n as f32 * std::f32::consts::TAU;
            let rot = Quat::from_axis_angle(Vec3::Y, turn);
            let c = scene.camera;
            let camera = Camera {
                eye: c.target + rot * (c.eye - c.target),
                ..c
            };
            let lights = scene
                .lights
                .iter()
                .map(|l| PointLight::new(rot.inverse() * Vec3::from(l.position), Vec3::from(l.intensity)))
                .collect();
            (camera, lights)
        })
        .collect()
}

/// The frames of `views` through `render_frames` with `in_flight` frames in flight, in the
/// order handed over, each with its index, image and GPU figures.
fn run(
    tracer: &mut Tracer,
    views: &[(Camera, Vec<PointLight>)],
    opts: &RenderOptions,
    in_flight: usize,
) -> Vec<(usize, Image, gridtrace::RenderStats, bool)> {
    let mut out = Vec::new();
    let how = FramesOptions {
        in_flight,
        ..Default::default()
    };
    let stats = tracer
        .render_frames(views.iter().cloned(), opts, how, |i, f| {
            let Rendered::OnHost(f) = f else {
                panic!("a frame without a device image comes to the host")
            };
            out.push((i, f.image, f.stats, f.gpu.is_some()));
            Ok(())
        })
        .unwrap();
    assert_eq!(stats.frames as usize, views.len());
    assert_eq!(stats.rays, out.iter().map(|f| f.2.rays.total()).sum::<u64>());
    out
}

#[test]
fn frames_in_flight_equal_frames_one_by_one() {
    if skip_gpu() {
        return;
    }
    let scene = builtin::knot_box()
        .prepare_for(AccelKind::Bvh, &AccelParams::NONE)
        .unwrap();
    let ctx = ctx();
    let mut notes = Vec::new();
    let mut tracer = Tracer::open(
        scene.clone(),
        &Placement::on_device(Backend::Gpu, ctx.clone()),
        &mut notes,
    )
    .unwrap();
    let views = views(&scene, 5);
    let (w, h) = (48u32, 40u32);
    for (mode, pixels) in [
        (Mode::Cast, PixelFormat::Srgb8),
        (Mode::Shadow, PixelFormat::Linear),
        (Mode::Trace, PixelFormat::Srgb8),
        (Mode::Heat, PixelFormat::Linear),
    ] {
        let opts = RenderOptions::new(w, h, mode).with_pixels(pixels);
        let alone: Vec<_> = views.iter().map(|(c, l)| tracer.render(c, l, &opts).unwrap()).collect();
        for in_flight in [1, 2, 3] {
            let frames = run(&mut tracer, &views, &opts, in_flight);
            for (k, (i, image, stats, on_gpu)) in frames.iter().enumerate() {
                assert_eq!(*i, k, "{mode:?} {in_flight} in flight: frames out of order");
                assert!(on_gpu, "{mode:?}: frame {k} not traced on the GPU");
                assert_eq!(
                    stats.rays, alone[k].stats.rays,
                    "{mode:?} {in_flight} in flight: frame {k}'s rays"
                );
                let same = match pixels {
                    PixelFormat::Srgb8 if mode != Mode::Heat => image.to_rgb8() == alone[k].image.to_rgb8(),
                    _ => image.pixels() == alone[k].image.pixels(),
                };
                assert!(
                    same,
                    "{mode:?} {in_flight} in flight: frame {k}'s pixels differ from it alone"
                );
            }
            // Neighbouring frames differ: the test would see frames swapped or repeated.
            assert!(
                frames[0].1.pixels() != frames[1].1.pixels(),
                "{mode:?}: the views are alike"
            );
        }
    }

    // Left in a device image: it holds the last frame, as that frame alone leaves it, and each
    // frame's figures come back without its image.
    let opts = RenderOptions::new(w, h, Mode::Shadow).with_pixels(PixelFormat::Srgb8);
    let target = DeviceImage::new(&ctx, w, h).unwrap();
    let mut seen = Vec::new();
    let how = FramesOptions {
        in_flight: 3,
        target: Some(&target),
        progress: None,
    };
    tracer
        .render_frames(views.iter().cloned(), &opts, how, |i, f| {
            let Rendered::OnDevice(s) = f else {
                panic!("frame {i} came to the host")
            };
            seen.push((i, s.render.rays));
            Ok(())
        })
        .unwrap();
    let last = views.last().unwrap();
    let want = tracer.render(&last.0, &last.1, &opts).unwrap();
    assert_eq!(seen.iter().map(|s| s.0).collect::<Vec<_>>(), vec![0, 1, 2, 3, 4]);
    assert_eq!(seen[4].1, want.stats.rays);
    assert!(
        target.read().unwrap().to_rgb8() == want.image.to_rgb8(),
        "the device image is not the last frame"
    );
}

/// A device lost while frames are in flight: under `auto` the frames from the first that failed
/// on are the CPU's, handed over in order; none is lost or repeated, and the note says why.
#[test]
fn a_fault_hands_the_frames_in_flight_to_the_cpu() {
    if skip_gpu() {
        return;
    }
    let scene = builtin::knot_box()
        .prepare_for(AccelKind::Bvh, &AccelParams::NONE)
        .unwrap();
    let ctx = ctx();
    let mut notes = Vec::new();
    let mut tracer = Tracer::open(
        scene.clone(),
        &Placement::on_device(Backend::Auto, ctx.clone()),
        &mut notes,
    )
    .unwrap();
    assert!(tracer.gpu().is_some());
    let views = views(&scene, 6);
    let opts = RenderOptions::new(32, 24, Mode::Shadow);
    let mut got = Vec::new();
    let how = FramesOptions {
        in_flight: 2,
        ..Default::default()
    };
    tracer
        .render_frames(views.iter().cloned(), &opts, how, |i, f| {
            let Rendered::OnHost(f) = f else {
                panic!("no device image asked")
            };
            // Frame 2 is in flight when frame 1 is handed over: lose the device now.
            if i == 1 {
                ctx.inject_fault(Fault::DeviceLost);
            }
            got.push((i, f));
            Ok(())
        })
        .unwrap();
    assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), (0..6).collect::<Vec<_>>());
    assert!(
        got[0].1.gpu.is_some() && got[1].1.gpu.is_some(),
        "the first two frames are the GPU's"
    );
    for (i, f) in &got[2..] {
        assert!(f.gpu.is_none(), "frame {i} still on the GPU");
        let (camera, lights) = &views[*i];
        let (want, _) = gridtrace::cpu::render_view(&tracer.scene, camera, lights, &opts, None).unwrap();
        assert!(f.image.pixels() == want.pixels(), "frame {i}: the CPU's frame differs");
    }
    let notes = tracer.take_notes();
    assert!(notes.len() == 1 && notes[0].contains("the GPU failed"), "{notes:?}");
}

/// The browser's way (`gridtrace-web`, where nothing may block): a frame submitted, the device
/// polled without waiting until the frame `is_ready`, then finished, is `render`'s frame; it is
/// not ready before the device was polled (natively a mapping completes only in a poll), so
/// `is_ready` says something.
#[test]
fn a_frame_polled_until_ready_equals_render() {
    if skip_gpu() {
        return;
    }
    let scene = builtin::knot_box()
        .prepare_for(AccelKind::Bvh, &AccelParams::NONE)
        .unwrap();
    let ctx = ctx();
    let placement = Placement::on_device(Backend::Gpu, ctx.clone());
    let mut tracer = Tracer::open(scene.clone(), &placement, &mut Vec::new()).unwrap();
    let opts = RenderOptions::new(48, 40, Mode::Shadow).with_pixels(PixelFormat::Srgb8);
    let (camera, lights) = (scene.camera, scene.lights.clone());
    let alone = tracer.render(&camera, &lights, &opts).unwrap();
    let gpu = tracer.gpu_mut().expect("traced on the GPU");
    let frame = gpu.submit_frame(&camera, &lights, &opts, None).unwrap();
    assert!(!frame.is_ready(), "ready before the device was polled");
    // A bound on the polls, not on time: a frame that never comes back fails instead of hanging.
    let mut polls = 0;
    while !frame.is_ready() {
        ctx.device.poll(wgpu::PollType::Poll).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(1));
        polls += 1;
        assert!(polls < 120_000, "the frame never became ready");
    }
    let (image, stats) = gpu.finish_frame(frame).unwrap();
    let image = image.expect("a frame without a device image comes to the host");
    assert_eq!(stats.render.rays, alone.stats.rays);
    assert!(
        image.to_rgb8() == alone.image.to_rgb8(),
        "the polled frame's pixels differ from render's"
    );
}
