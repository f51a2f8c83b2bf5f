//! CPU renderer. Each pixel follows exactly the steps the GPU wavefront kernels take (eye ray,
//! shading with shadow rays, up to two reflection rays: `path.rs`), so the two images agree.
//! Pixels go in 4x2 blocks whose rays are traced as packets (`blocks.rs`); `trace_pixel` is
//! the same path one ray at a time (the reference the block renders are tested against, and
//! what `rays` records).

use crate::util::Instant;

use glam::Vec3;
use rayon::prelude::*;

use crate::Result;
use crate::accel::{Counters, Hit, NoCounters, Ray, TraversalCounters};
use crate::render::{Image, Mode, RayCounts, RenderOptions, RenderStats};
use crate::scene::{Camera, CameraFrame, PointLight, PreparedScene};

use super::blocks::trace_blocks;
use super::path::{Collect, Path, RayKind, shadow_query};

/// Renders the scene with its own camera and lights. `progress` is called with the number of
/// image rows finished, as bands of rows finish (from any thread).
pub fn render(
    scene: &PreparedScene,
    opts: &RenderOptions,
    progress: Option<&(dyn Fn(u32) + Sync)>,
) -> Result<(Image, RenderStats)> {
    render_view(scene, &scene.camera, &scene.lights, opts, progress)
}

/// Renders the scene from `camera` with `lights` (the scene's own need not be used): the CPU
/// form of a frame of the interactive tracer, where both change every frame.
pub fn render_view(
    scene: &PreparedScene,
    camera: &Camera,
    lights: &[PointLight],
    opts: &RenderOptions,
    progress: Option<&(dyn Fn(u32) + Sync)>,
) -> Result<(Image, RenderStats)> {
    scene.accel.check_current()?;
    let view = View { camera, lights };
    if opts.mode == Mode::Heat {
        render_generic::<TraversalCounters>(scene, &view, opts, progress)
    } else {
        render_generic::<NoCounters>(scene, &view, opts, progress)
    }
}

/// `render_view`, also counting traversal work (cells, jumps, triangle tests).
pub fn render_with_counters(
    scene: &PreparedScene,
    camera: &Camera,
    lights: &[PointLight],
    opts: &RenderOptions,
) -> Result<(Image, RenderStats)> {
    scene.accel.check_current()?;
    render_generic::<TraversalCounters>(scene, &View { camera, lights }, opts, None)
}

/// What changes per frame: where the camera is and where the lights are.
struct View<'a> {
    camera: &'a Camera,
    lights: &'a [PointLight],
}

fn render_generic<C: Collect>(
    scene: &PreparedScene,
    view: &View,
    opts: &RenderOptions,
    progress: Option<&(dyn Fn(u32) + Sync)>,
) -> Result<(Image, RenderStats)> {
    opts.validate()?;
    view.camera.validate().map_err(crate::Error::Scene)?;
    let t0 = Instant::now();
    let cam = view.camera.frame(opts.width, opts.height);
    let frame_rows = opts.row_range();
    let mut img = Image::new(opts.width, frame_rows.len() as u32);
    const BAND: usize = 4;
    let width = opts.width as usize;
    let (rays, counters) = img
        .pixels_mut()
        .par_chunks_mut(width * BAND)
        .enumerate()
        .map(|(band, rows)| {
            let mut rays = RayCounts::default();
            let mut total = TraversalCounters::default();
            let first_y = frame_rows.start + (band * BAND) as u32;
            let n_rows = rows.len() / width;
            trace_blocks::<C>(scene, &cam, view.lights, opts, (first_y, rows), (&mut rays, &mut total));
            if let Some(p) = progress {
                p(n_rows as u32);
            }
            (rays, total)
        })
        .reduce(
            || (RayCounts::default(), TraversalCounters::default()),
            |(mut ra, mut ca), (rb, cb)| {
                ra += rb;
                ca += cb;
                (ra, ca)
            },
        );
    let stats = RenderStats {
        rays,
        counters,
        render_ms: t0.elapsed().as_secs_f64() * 1e3,
    };
    Ok((img, stats))
}

/// Sees every ray a pixel's walk traces, in order, with its result: how the ray export of the
/// benchmarks records exactly what the renderer traces, without a second copy of the walk. The
/// no-op observer `()` compiles away.
pub trait RayObserver {
    /// An eye or reflection ray and its closest hit.
    fn closest(&mut self, _kind: RayKind, _ray: &Ray, _hit: &Hit) {}
    /// A shadow ray towards a light `dist` away, and whether something occludes it.
    fn shadow(&mut self, _ray: &Ray, _dist: f32, _occluded: bool) {}
}

impl RayObserver for () {}

/// Traces pixel `(x, y)` as `render` does, from the scene's camera and lights, showing every ray
/// to `observer`; returns the pixel's colour.
pub fn trace_pixel_observed(
    scene: &PreparedScene,
    cam: &CameraFrame,
    (x, y): (u32, u32),
    opts: &RenderOptions,
    observer: &mut impl RayObserver,
) -> Vec3 {
    let mut rays = RayCounts::default();
    trace_pixel(
        scene,
        cam,
        &scene.lights,
        (x, y),
        opts,
        (&mut rays, &mut NoCounters),
        observer,
    )
}

/// One pixel's path (`Path`) ray by ray: the eye ray, shading with a shadow ray per light,
/// mirror rays. Rays are counted into `rays`, their work into `counters`, and each is shown to
/// `observer`.
#[inline]
fn trace_pixel<C: Counters, O: RayObserver>(
    scene: &PreparedScene,
    cam: &CameraFrame,
    lights: &[PointLight],
    (x, y): (u32, u32),
    opts: &RenderOptions,
    (rays, counters): (&mut RayCounts, &mut C),
    observer: &mut O,
) -> Vec3 {
    let mut path = Path::new(cam.ray(x, y));
    rays.eye += 1;
    loop {
        let hit = scene.accel.intersect(&path.ray, counters);
        observer.closest(path.kind, &path.ray, &hit);
        let Some(shading) = path.shade(scene, opts, &hit) else {
            break;
        };
        for light in lights {
            let Some((contribution, shadow, dist)) = shading.light(light) else {
                continue;
            };
            if opts.mode.shadows() {
                rays.shadow += 1;
                let occluded = shadow_query(scene, opts, &shadow.within(0.0, dist), counters);
                observer.shadow(&shadow, dist, occluded);
                if occluded {
                    continue;
                }
            }
            path.lit(&shading, contribution);
        }
        if !path.reflect(opts, &shading) {
            break;
        }
        rays.reflection += 1;
    }
    path.color
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::{AccelKind, AccelParams};
    use crate::render::Ablation;
    use crate::scene::builtin;

    /// Renders trace every ray in 4x2 packets (`blocks.rs`: eye, shadow and mirror rays; the
    /// irregular grid walks a packet's rays together, the other structures interleave their
    /// walks); for every structure every pixel equals, bit for bit, what the pixel-by-pixel walk
    /// (`trace_pixel`, one ray at a time) gives, with the same rays, and heat images count
    /// each eye ray's own cells and tests: odd sizes (blocks cut at the right edge and the
    /// band's last row), a band of rows starting on an odd row, every shading mode (two levels
    /// of mirrors in `mirror-spheres`), and the ablation that traces shadow rays one by one.
    #[test]
    fn packet_renders_equal_single_rays() {
        for (name, kind) in AccelKind::ALL
            .into_iter()
            .flat_map(|kind| ["knot-box", "mirror-spheres", "sparse-room"].map(|name| (name, kind)))
        {
            let scene = builtin::scene(name).unwrap();
            let prepared = scene.prepare_for(kind, &AccelParams::NONE).unwrap();
            for (mode, ablation, rows) in [
                (Mode::Cast, Ablation::default(), None),
                (Mode::Shadow, Ablation::default(), Some((5, 18))),
                (Mode::Trace, Ablation::default(), None),
                (Mode::Shadow, Ablation::named("shadow-any-hit").unwrap(), None),
                (Mode::Heat, Ablation::default(), Some((3, 22))),
            ] {
                let opts = RenderOptions {
                    width: 37,
                    height: 23,
                    mode,
                    ablation,
                    rows,
                    pixels: Default::default(),
                };
                let (img, stats) = render_with_counters(&prepared, &scene.camera, &scene.lights, &opts).unwrap();
                let cam = scene.camera.frame(opts.width, opts.height);
                let first = opts.row_range().start;
                let mut expected_rays = RayCounts::default();
                for (i, got) in img.pixels().iter().enumerate() {
                    let (x, y) = (i as u32 % opts.width, first + i as u32 / opts.width);
                    let want = if mode == Mode::Heat {
                        let mut c = TraversalCounters::default();
                        prepared.accel.intersect(&cam.ray(x, y), &mut c);
                        Vec3::splat(c.cost() as f32)
                    } else {
                        let tally = (&mut expected_rays, &mut NoCounters);
                        trace_pixel(&prepared, &cam, &scene.lights, (x, y), &opts, tally, &mut ())
                    };
                    assert_eq!(
                        got.to_array().map(f32::to_bits),
                        want.to_array().map(f32::to_bits),
                        "{name} {kind:?} {mode:?} pixel ({x}, {y}): packets {got}, alone {want}"
                    );
                }
                if mode != Mode::Heat {
                    assert_eq!(stats.rays, expected_rays, "{name} {mode:?}: the same rays");
                }
                if mode == Mode::Shadow {
                    assert!(stats.rays.shadow > 0, "{name}: shadow rays were traced");
                }
            }
        }
    }
}
