//! One pixel's path through the renderer's stages, as the GPU wavefront kernels take them: the
//! eye ray, its closest hit, shading with a shadow ray per light, and a mirror ray (up to two
//! levels), accumulating `weight * colour`. `render.rs` runs a pixel's path a ray at a time
//! (`trace_pixel`); `blocks.rs` runs eight pixels' paths side by side, each stage's rays as one
//! packet. Both call the same stages, in the same order, so their images are the same bits.

use glam::Vec3;

use crate::accel::{Counters, Hit, NoCounters, Ray, TraversalCounters};
use crate::render::{Mode, RenderOptions};
use crate::scene::{PointLight, PreparedScene};

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

/// A pixel's path: the ray it traces next and what it has gathered.
#[derive(Debug, Clone, Copy)]
pub(super) struct Path {
    pub ray: Ray,
    pub kind: RayKind,
    /// What the next hit's colour counts for (a reflection ray carries its parent's
    /// reflectivity).
    weight: Vec3,
    pub color: Vec3,
    /// Mirror bounces so far.
    depth: u32,
}

/// A hit being shaded: what its lights add to, and where its further rays start.
#[derive(Debug, Clone, Copy)]
pub(super) struct Shading {
    surface: Surface,
    /// Secondary rays start `ray_epsilon` off the surface along the geometric normal, so that
    /// they do not hit it again.
    origin: Vec3,
    /// The hit's diffuse colour, weighted: what each light's contribution is multiplied by.
    local: Vec3,
    reflect: f32,
}

impl Path {
    /// The path of an eye ray.
    pub fn new(eye: Ray) -> Path {
        Path {
            ray: eye,
            kind: RayKind::Eye,
            weight: Vec3::ONE,
            color: Vec3::ZERO,
            depth: 0,
        }
    }

    /// Shades `hit`, the closest hit of `self.ray`: the ambient term now, the lights through
    /// the returned `Shading`. `None` when the path ends here: a miss (which adds the
    /// background), or heat mode, which counts the eye ray's work only.
    #[inline]
    pub fn shade(&mut self, scene: &PreparedScene, opts: &RenderOptions, hit: &Hit) -> Option<Shading> {
        if !hit.is_hit() {
            self.color += self.weight * scene.background;
            return None;
        }
        if opts.mode == Mode::Heat {
            return None;
        }
        let surface = surface_at(scene, &self.ray, hit);
        let mat = &scene.materials[scene.tri_material[hit.tri as usize] as usize];
        let reflect = if opts.mode == Mode::Trace {
            mat.reflectivity
        } else {
            0.0
        };
        let local = self.weight * (1.0 - reflect) * mat.diffuse;
        self.color += local * scene.ambient;
        Some(Shading {
            surface,
            origin: surface.position + surface.ng * scene.ray_epsilon,
            local,
            reflect,
        })
    }

    /// Adds a light's contribution (`Shading::light`) that its shadow ray did not find
    /// occluded.
    #[inline]
    pub fn lit(&mut self, shading: &Shading, contribution: Vec3) {
        self.color += shading.local * contribution;
    }

    /// Turns the path into the mirror ray of the hit `shading` shades, if its material
    /// reflects and the mode allows another bounce; false when the path ends.
    #[inline]
    pub fn reflect(&mut self, opts: &RenderOptions, shading: &Shading) -> bool {
        if shading.reflect > 0.0 && self.depth < opts.mode.reflection_depth() {
            self.weight *= shading.reflect;
            let ns = shading.surface.ns;
            let d = self.ray.dir - 2.0 * self.ray.dir.dot(ns) * ns;
            self.ray = Ray::new(shading.origin, d.normalize());
            self.kind = RayKind::Reflection;
            self.depth += 1;
            true
        } else {
            false
        }
    }
}

impl Shading {
    /// Diffuse irradiance from a point light, `intensity * max(0, N.L) / d^2`, with the shadow
    /// ray that decides whether it arrives and the light's distance along it. `None` when the
    /// light is behind the surface: then no shadow ray is spent (the paper's masking of rays
    /// known not to contribute).
    #[inline]
    pub fn light(&self, light: &PointLight) -> Option<(Vec3, Ray, f32)> {
        let s = &self.surface;
        let to = Vec3::from(light.position) - self.origin;
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
        Some((Vec3::from(light.intensity) * (ndl / d2), Ray::new(self.origin, l), dist))
    }
}

/// Which kind of ray the renderer traced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayKind {
    Eye,
    Shadow,
    Reflection,
}

/// Counters a render collects per pixel (or none: `NoCounters` compiles away).
pub(super) trait Collect: Counters + Default + Send {
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

/// What a pixel shows: its colour, or in heat mode the work its eye ray cost (`counters`).
#[inline]
pub(super) fn pixel_value<C: Collect>(opts: &RenderOptions, color: Vec3, counters: &C) -> Vec3 {
    if opts.mode == Mode::Heat {
        Vec3::splat(counters.cost() as f32)
    } else {
        color
    }
}

/// Whether a shadow ray is occluded in its interval (up to the light): an any-hit query, or a
/// closest-hit one under the ablation that measures what any-hit queries save.
#[inline]
pub(super) fn shadow_query<C: Counters>(scene: &PreparedScene, opts: &RenderOptions, ray: &Ray, c: &mut C) -> bool {
    if opts.ablation.shadow_closest_hit {
        scene.accel.intersect(ray, c).is_hit()
    } else {
        scene.accel.occluded(ray, c)
    }
}
