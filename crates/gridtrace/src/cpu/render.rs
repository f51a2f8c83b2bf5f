//! CPU renderer. Each pixel follows exactly the steps the GPU wavefront kernels take (eye ray,
//! shading with shadow rays, up to two reflection rays), so the two images agree.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use crate::Result;
use crate::accel::{Counters, Hit, NoCounters, Ray, TraversalCounters};
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
    fn cost(&self) -> u64 {
        let t = self.total();
        t.cells + t.tri_tests
    }
}
impl Collect for NoCounters {
    fn total(&self) -> TraversalCounters {
        TraversalCounters::default()
    }
}
impl Collect for TraversalCounters {
    fn total(&self) -> TraversalCounters {
        *self
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
            for (i, px) in rows.iter_mut().enumerate() {
                let x = (i % width) as u32;
                let y = frame_rows.start + (band * BAND + i / width) as u32;
                let mut c = C::default();
                *px = trace_pixel(scene, &cam, view.lights, (x, y), opts, (&mut rays, &mut c), &mut ());
                if opts.mode == Mode::Heat {
                    *px = Vec3::splat(c.cost() as f32);
                }
                total += c.total();
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
        observer,
    )
}

/// One pixel: eye ray, then shading and reflections, accumulating `weight * colour` as the GPU
/// wavefront does (a reflection ray carries the weight `reflectivity` of its parent). Rays are
/// counted into `tally` and shown to `observer`.
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
    let accel = &scene.accel;
    let mut ray = cam.ray(x, y);
    let mut weight = Vec3::ONE;
    let mut color = Vec3::ZERO;
    let mut kind = RayKind::Eye;
    rays.eye += 1;
    for depth in 0..=opts.mode.reflection_depth() {
        let hit = accel.intersect(&ray, 0.0, f32::INFINITY, opts.accel, counters);
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
        let origin = s.position + s.ng * scene.ray_epsilon;
        for light in lights {
            let (contrib, to_light, dist) = match light_contribution(&s, origin, light) {
                Some(v) => v,
                None => continue,
            };
            if opts.mode.shadows() {
                rays.shadow += 1;
                let shadow = Ray::new(origin, to_light);
                let occluded = if opts.ablation.shadow_closest_hit {
                    accel.intersect(&shadow, 0.0, dist, opts.accel, counters).is_hit()
                } else {
                    accel.occluded(&shadow, 0.0, dist, opts.accel, counters)
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
