//! CPU renderer. Each pixel follows exactly the steps the GPU wavefront kernels take (eye ray,
//! shading with shadow rays, up to two reflection rays), so the two images agree.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use crate::Result;
use crate::accel::{Counters, Hit, NoCounters, PACKET, Ray, TraversalCounters};
use crate::render::{Image, Mode, RayCounts, RenderOptions, RenderStats};
use crate::scene::{Camera, CameraFrame, PointLight, PreparedScene};

/// Shading geometry at a hit, both normals facing the incoming ray.
#[derive(Debug, Clone, Copy)]
pub struct Surface {
    pub position: Vec3,
    /// Unit geometric normal.
    pub ng: Vec3,
    /// Unit interpolated vertex normal (the geometric one where interpolation degenerates).
    pub ns: Vec3,
}

/// Surface at a hit of `ray` on triangle `hit.tri`.
#[inline]
pub fn surface_at(scene: &PreparedScene, ray: &Ray, hit: &Hit) -> Surface {
    let tri = &scene.accel.tris[hit.tri as usize];
    let mut ng = tri.normal().normalize();
    let [i0, i1, i2] = scene.tri_vertices[hit.tri as usize];
    let w = 1.0 - hit.u - hit.v;
    let mut ns =
        (scene.normals[i0 as usize] * w + scene.normals[i1 as usize] * hit.u + scene.normals[i2 as usize] * hit.v)
            .normalize_or_zero();
    if ns == Vec3::ZERO {
        ns = ng;
    }
    // Two-sided surfaces: face both normals towards the viewer.
    if ng.dot(ray.dir) > 0.0 {
        ng = -ng;
    }
    if ns.dot(ng) < 0.0 {
        ns = -ns;
    }
    Surface {
        position: ray.at(hit.t),
        ng,
        ns,
    }
}

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

trait Collect: Counters + Default + Send {
    fn total(&self) -> TraversalCounters;
    /// Adds `other`'s counts to these.
    fn absorb(&mut self, other: Self);
    fn cost(&self) -> u64 {
        let t = self.total();
        t.cells + t.tri_tests
    }
}
impl Collect for NoCounters {
    fn total(&self) -> TraversalCounters {
        TraversalCounters::default()
    }
    fn absorb(&mut self, _: Self) {}
}
impl Collect for TraversalCounters {
    fn total(&self) -> TraversalCounters {
        *self
    }
    fn absorb(&mut self, other: Self) {
        *self += other;
    }
}

fn render_generic<C: Collect>(
    scene: &PreparedScene,
    view: &View,
    opts: &RenderOptions,
    progress: Option<&(dyn Fn(u32) + Sync)>,
) -> Result<(Image, RenderStats)> {
    opts.validate()?;
    scene.accel.check_serves(opts.accel)?;
    view.camera.validate().map_err(crate::Error::Scene)?;
    let t0 = Instant::now();
    let cam = view.camera.frame(opts.width, opts.height);
    let frame_rows = opts.row_range();
    let mut img = Image::new(opts.width, frame_rows.len() as u32);
    const BAND: usize = 4;
    let width = opts.width as usize;
    let (rays, counters) = img
        .pixels
        .par_chunks_mut(width * BAND)
        .enumerate()
        .map(|(band, rows)| {
            let mut rays = RayCounts::default();
            let mut total = TraversalCounters::default();
            if scene.accel.walks_packets() {
                trace_blocks::<C>(scene, &cam, view, opts, (band * BAND, rows), (&mut rays, &mut total));
            } else {
                for (i, px) in rows.iter_mut().enumerate() {
                    let x = (i % width) as u32;
                    let y = frame_rows.start + (band * BAND + i / width) as u32;
                    let mut c = C::default();
                    let eye = |ray: &Ray, c: &mut C| scene.accel.intersect(ray, 0.0, f32::INFINITY, opts.accel, c);
                    let shadow = |_: usize, ray: &Ray, dist: f32, c: &mut C| shadow_query(scene, opts, ray, dist, c);
                    *px = trace_pixel(
                        scene,
                        &cam,
                        view.lights,
                        (x, y),
                        opts,
                        (&mut rays, &mut c),
                        (eye, shadow),
                        &mut (),
                    );
                    if opts.mode == Mode::Heat {
                        *px = Vec3::splat(c.cost() as f32);
                    }
                    total += c.total();
                }
            }
            if let Some(p) = progress {
                p((rows.len() / width) as u32);
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

/// The pixels of a band of rows (`first_row` of the frame's rows onwards) for a structure that
/// walks packets of rays (`Accel::walks_packets`): 2x2 blocks of pixels, whose eye rays are
/// traced as one packet (`Accel::intersect_packet`) and then, light by light, the shadow rays
/// from their hits (`Accel::occluded_packet`); then each pixel's shading and further rays
/// alone (`trace_pixel`, which takes those answers). Neighbouring pixels' rays are coherent,
/// which is what a packet walk needs. The same rays as pixel by pixel, so the same image.
fn trace_blocks<C: Collect>(
    scene: &PreparedScene,
    cam: &CameraFrame,
    view: &View,
    opts: &RenderOptions,
    (first_row, rows): (usize, &mut [Vec3]),
    (rays, total): (&mut RayCounts, &mut TraversalCounters),
) {
    let frame_rows = opts.row_range();
    let width = opts.width as usize;
    let band_rows = rows.len() / width;
    // Shadow rays of the eye hits in packets: not with the ablation that traces them as
    // closest-hit rays, which `trace_pixel` does ray by ray.
    let shadow_packets = opts.mode.shadows() && !opts.ablation.shadow_closest_hit;
    // Per light, whether each pixel's shadow ray towards it is occluded.
    let mut occluded = vec![[false; PACKET]; view.lights.len()];
    for by in (0..band_rows).step_by(2) {
        for bx in (0..width).step_by(2) {
            let mut at = [(0usize, 0u32, 0u32); PACKET];
            let mut eye = [Ray::new(Vec3::ZERO, Vec3::X); PACKET];
            let mut n = 0;
            for (dy, dx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                let (row, col) = (by + dy, bx + dx);
                if row < band_rows && col < width {
                    let (x, y) = (col as u32, frame_rows.start + (first_row + row) as u32);
                    at[n] = (row * width + col, x, y);
                    eye[n] = cam.ray(x, y);
                    n += 1;
                }
            }
            let mut c: [C; PACKET] = std::array::from_fn(|_| C::default());
            let hits = scene
                .accel
                .intersect_packet(&eye[..n], 0.0, f32::INFINITY, opts.accel, &mut c[..n]);
            if shadow_packets {
                // The shadow rays `trace_pixel` would trace at the eye hits, light by light.
                let points: [Option<(Surface, Vec3)>; PACKET] = std::array::from_fn(|k| {
                    (k < n && hits[k].is_hit()).then(|| {
                        let s = surface_at(scene, &eye[k], &hits[k]);
                        (s, shadow_origin(scene, &s))
                    })
                });
                for (light, occluded) in view.lights.iter().zip(&mut occluded) {
                    let mut shadow = [Ray::new(Vec3::ZERO, Vec3::X); PACKET];
                    let mut dist = [0.0; PACKET];
                    let mut lane_of = [0usize; PACKET];
                    let mut m = 0;
                    for (k, point) in points.iter().enumerate() {
                        if let Some((s, origin)) = point
                            && let Some((_, to_light, d)) = light_contribution(s, *origin, light)
                        {
                            (shadow[m], dist[m], lane_of[m]) = (Ray::new(*origin, to_light), d, k);
                            m += 1;
                        }
                    }
                    let mut counted: [C; PACKET] = std::array::from_fn(|_| C::default());
                    let answers = scene
                        .accel
                        .occluded_packet(&shadow[..m], 0.0, dist, opts.accel, &mut counted[..m]);
                    for (j, counted) in counted.into_iter().take(m).enumerate() {
                        occluded[lane_of[j]] = answers[j];
                        c[lane_of[j]].absorb(counted);
                    }
                }
            }
            for k in 0..n {
                let (i, x, y) = at[k];
                let eye_hit = |_: &Ray, _: &mut C| hits[k];
                let shadow = |light: usize, ray: &Ray, dist: f32, c: &mut C| {
                    if shadow_packets {
                        occluded[light][k]
                    } else {
                        shadow_query(scene, opts, ray, dist, c)
                    }
                };
                let px = &mut rows[i];
                *px = trace_pixel(
                    scene,
                    cam,
                    view.lights,
                    (x, y),
                    opts,
                    (rays, &mut c[k]),
                    (eye_hit, shadow),
                    &mut (),
                );
                if opts.mode == Mode::Heat {
                    *px = Vec3::splat(c[k].cost() as f32);
                }
                *total += c[k].total();
            }
        }
    }
}

/// Which kind of ray the renderer traced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayKind {
    Eye,
    Shadow,
    Reflection,
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
        (
            |ray: &Ray, c: &mut NoCounters| scene.accel.intersect(ray, 0.0, f32::INFINITY, opts.accel, c),
            |_: usize, ray: &Ray, dist: f32, c: &mut NoCounters| shadow_query(scene, opts, ray, dist, c),
        ),
        observer,
    )
}

/// One pixel: eye ray, then shading and reflections, accumulating `weight * colour` as the GPU
/// wavefront does (a reflection ray carries the weight `reflectivity` of its parent). Rays are
/// counted into `tally` and shown to `observer`. `first` answers the eye ray (its closest hit)
/// and the shadow rays from the eye hit (`first.1(light, ray, dist, counters)`: occluded?):
/// traced there, or already traced in packets (`trace_blocks`, their work counted).
#[inline]
#[allow(clippy::too_many_arguments)]
fn trace_pixel<C: Counters, O: RayObserver>(
    scene: &PreparedScene,
    cam: &CameraFrame,
    lights: &[PointLight],
    (x, y): (u32, u32),
    opts: &RenderOptions,
    (rays, counters): (&mut RayCounts, &mut C),
    (eye, mut first_shadow): (
        impl FnOnce(&Ray, &mut C) -> Hit,
        impl FnMut(usize, &Ray, f32, &mut C) -> bool,
    ),
    observer: &mut O,
) -> Vec3 {
    let accel = &scene.accel;
    let mut ray = cam.ray(x, y);
    let mut eye = Some(eye);
    let mut weight = Vec3::ONE;
    let mut color = Vec3::ZERO;
    let mut kind = RayKind::Eye;
    rays.eye += 1;
    for depth in 0..=opts.mode.reflection_depth() {
        let hit = match eye.take() {
            Some(eye) => eye(&ray, counters),
            None => accel.intersect(&ray, 0.0, f32::INFINITY, opts.accel, counters),
        };
        observer.closest(kind, &ray, &hit);
        if !hit.is_hit() {
            color += weight * scene.background;
            break;
        }
        if opts.mode == Mode::Heat {
            break;
        }
        let s = surface_at(scene, &ray, &hit);
        let mat = &scene.materials[scene.tri_material[hit.tri as usize] as usize];
        let reflect = if opts.mode == Mode::Trace {
            mat.reflectivity
        } else {
            0.0
        };
        let local = weight * (1.0 - reflect) * mat.diffuse;
        color += local * scene.ambient;
        let origin = shadow_origin(scene, &s);
        for (light_index, light) in lights.iter().enumerate() {
            let (contrib, to_light, dist) = match light_contribution(&s, origin, light) {
                Some(v) => v,
                None => continue,
            };
            if opts.mode.shadows() {
                rays.shadow += 1;
                let shadow = Ray::new(origin, to_light);
                let occluded = if depth == 0 {
                    first_shadow(light_index, &shadow, dist, counters)
                } else {
                    shadow_query(scene, opts, &shadow, dist, counters)
                };
                observer.shadow(&shadow, dist, occluded);
                if occluded {
                    continue;
                }
            }
            color += local * contrib;
        }
        if reflect > 0.0 && depth < opts.mode.reflection_depth() {
            weight *= reflect;
            let d = ray.dir - 2.0 * ray.dir.dot(s.ns) * s.ns;
            ray = Ray::new(origin, d.normalize());
            kind = RayKind::Reflection;
            rays.reflection += 1;
        } else {
            break;
        }
    }
    color
}

/// Whether a shadow ray is occluded before `dist`: an any-hit query, or a closest-hit one
/// under the ablation that measures what any-hit queries save.
#[inline]
fn shadow_query<C: Counters>(scene: &PreparedScene, opts: &RenderOptions, ray: &Ray, dist: f32, c: &mut C) -> bool {
    if opts.ablation.shadow_closest_hit {
        scene.accel.intersect(ray, 0.0, dist, opts.accel, c).is_hit()
    } else {
        scene.accel.occluded(ray, 0.0, dist, opts.accel, c)
    }
}

/// Where the rays leaving a surface start: off it along the geometric normal, so that they do
/// not hit it again.
#[inline]
fn shadow_origin(scene: &PreparedScene, s: &Surface) -> Vec3 {
    s.position + s.ng * scene.ray_epsilon
}

/// Diffuse irradiance from a point light: `intensity * max(0, N.L) / d^2`, with the unit
/// direction and distance for the shadow ray. `None` when the light is behind the surface
/// (then no shadow ray is spent: the paper's masking of rays known not to contribute).
#[inline]
fn light_contribution(
    s: &crate::cpu::Surface,
    origin: Vec3,
    light: &crate::scene::PointLight,
) -> Option<(Vec3, Vec3, f32)> {
    let to = Vec3::from(light.position) - origin;
    let d2 = to.length_squared();
    if d2 == 0.0 {
        return None;
    }
    let dist = d2.sqrt();
    let l = to / dist;
    let ndl = s.ns.dot(l);
    if ndl <= 0.0 || s.ng.dot(l) <= 0.0 {
        return None;
    }
    Some((Vec3::from(light.intensity) * (ndl / d2), l, dist))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::{AccelKind, Resolution};
    use crate::render::Ablation;
    use crate::scene::builtin;

    /// The irregular grid's renders trace eye and shadow rays in 2x2 packets (`trace_blocks`);
    /// every pixel equals, bit for bit, what the pixel-by-pixel walk (`trace_pixel_observed`,
    /// one ray at a time) gives, and heat images count each eye ray's own cells and tests: odd
    /// sizes (blocks cut at the right edge and the band's last row), a band of rows starting on
    /// an odd row, every shading mode, and the ablation that traces shadow rays one by one.
    #[test]
    fn packet_renders_equal_single_rays() {
        for name in ["knot-box", "mirror-spheres", "sparse-room"] {
            let scene = builtin::scene(name).unwrap();
            let prepared = scene.prepare_for(AccelKind::Irregular, Resolution::default()).unwrap();
            assert!(prepared.accel.walks_packets());
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
                    accel: AccelKind::Irregular,
                    ablation,
                    rows,
                };
                let (img, stats) = render_with_counters(&prepared, &scene.camera, &scene.lights, &opts).unwrap();
                let cam = scene.camera.frame(opts.width, opts.height);
                let first = opts.row_range().start;
                let mut expected_rays = RayCounts::default();
                for (i, got) in img.pixels.iter().enumerate() {
                    let (x, y) = (i as u32 % opts.width, first + i as u32 / opts.width);
                    let want = if mode == Mode::Heat {
                        let mut c = TraversalCounters::default();
                        prepared
                            .accel
                            .intersect(&cam.ray(x, y), 0.0, f32::INFINITY, opts.accel, &mut c);
                        Vec3::splat(c.cost() as f32)
                    } else {
                        let alone = |ray: &Ray, c: &mut NoCounters| {
                            prepared.accel.intersect(ray, 0.0, f32::INFINITY, opts.accel, c)
                        };
                        let shadow = |_: usize, ray: &Ray, dist: f32, c: &mut NoCounters| {
                            shadow_query(&prepared, &opts, ray, dist, c)
                        };
                        let tally = (&mut expected_rays, &mut NoCounters);
                        trace_pixel(
                            &prepared,
                            &cam,
                            &scene.lights,
                            (x, y),
                            &opts,
                            tally,
                            (alone, shadow),
                            &mut (),
                        )
                    };
                    assert_eq!(
                        got.to_array().map(f32::to_bits),
                        want.to_array().map(f32::to_bits),
                        "{name} {mode:?} pixel ({x}, {y}): packets {got}, alone {want}"
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
