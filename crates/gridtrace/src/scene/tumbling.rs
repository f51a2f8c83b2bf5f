//! `tumbling-bunnies`: many rigid instances of one mesh (the Stanford Bunny by default), each
//! tumbling about its own axis at its own rate and bobbing a little, for the two levels'
//! dynamic path: a frame moves every instance (`QueryScene::set_transforms`, the top level
//! rebuilt, no mesh structure), casts the camera's primary rays (`QueryScene::cast_rays`) and
//! shades the hits with a headlight (`shade`), or with point lights (`shade_lit`), their
//! shadows from `shadow_rays` through `QueryScene::test_occlusions`. Unlike `animated.rs` no vertex moves, so the one mesh
//! structure is built once, however many frames are played.
//!
//! The instances sit on a cubic lattice of unit spacing (x fastest, then y, then z), each
//! mesh scaled so that its box's diagonal is `DIAGONAL` and turned about its box's centre:
//! turning, a mesh stays within `DIAGONAL / 2` of its lattice point, and bobbing within
//! `BOB` more, so no two instances ever overlap (no ties between instances at equal t).

use std::f32::consts::TAU;

use glam::{Mat4, Quat, Vec3};
use rayon::prelude::*;

use super::{Camera, PointLight};
use crate::query::QueryOptions;
use crate::query_scene::{INVALID_ID, QueryScene, RayHits};
use crate::render::Image;
use crate::util::Rng;
use crate::{Error, Result};

/// The scene's name on the command line (`render --animate --scene tumbling-bunnies`).
pub const NAME: &str = "tumbling-bunnies";
/// Instances when none are asked for.
pub const DEFAULT_INSTANCES: u32 = 1000;
/// The most instances a scene takes: a million Bunnies' top level is about 100 MiB of records
/// and nodes; more is a typo, not an experiment.
pub const MAX_INSTANCES: u32 = 1_000_000;
/// Each mesh's box diagonal in scene units (the lattice spacing is 1).
const DIAGONAL: f32 = 0.85;
/// How far an instance bobs from its lattice point, in scene units.
const BOB: f32 = 0.05;
/// Turning rates, radians per second of animation time.
const SPIN_RAD_PER_S: (f32, f32) = (0.4, 2.0);
/// Bobbing rates, radians (of the sine's phase) per second.
const BOB_RAD_PER_S: (f32, f32) = (0.5, 1.5);
/// The light the shade adds to every hit, whichever way its face turns (a headlight alone
/// leaves faces seen edge-on black).
const AMBIENT: f32 = 0.12;
/// Instance tints (linear RGB), picked by instance so that neighbours are told apart.
const TINTS: [[f32; 3]; 6] = [
    [0.80, 0.62, 0.45],
    [0.55, 0.65, 0.85],
    [0.70, 0.80, 0.50],
    [0.85, 0.50, 0.50],
    [0.75, 0.60, 0.85],
    [0.85, 0.80, 0.45],
];

/// One instance's motion.
#[derive(Debug, Clone, Copy)]
struct Body {
    /// Its lattice point, scene units.
    center: Vec3,
    /// Unit axis it turns about (through its box's centre), and its rate and angle at time 0.
    axis: Vec3,
    spin_rad_per_s: f32,
    spin0_rad: f32,
    /// Unit direction it bobs along (by `BOB * sin(phase)`), the phase's rate and value at 0.
    bob_dir: Vec3,
    bob_rad_per_s: f32,
    bob0_rad: f32,
    tint: Vec3,
}

/// The scene: one mesh in its own space, the instances' motions and a camera that frames
/// them all.
#[derive(Debug, Clone)]
pub struct Tumbling {
    /// The mesh's vertices in its own (file) space, and its faces.
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// Mesh space to an unturned instance at the origin: the box's centre to the origin, the
    /// diagonal scaled to `DIAGONAL`.
    to_unit: Mat4,
    bodies: Vec<Body>,
    pub camera: Camera,
}

impl Tumbling {
    /// `instances` (1 to `MAX_INSTANCES`) tumbling copies of the mesh `vertices` / `faces`;
    /// `what` names the mesh in errors (its file). The motions are the same on every run.
    pub fn new(vertices: Vec<[f32; 3]>, faces: Vec<[u32; 3]>, instances: u32, what: &str) -> Result<Tumbling> {
        if !(1..=MAX_INSTANCES).contains(&instances) {
            return Err(Error::InvalidInput(format!(
                "{NAME}: --instances must be 1 to {MAX_INSTANCES}, got {instances}"
            )));
        }
        let (lo, hi) = vertices.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), p| {
            (l.min(Vec3::from(*p)), h.max(Vec3::from(*p)))
        });
        let diagonal = (hi - lo).length();
        if faces.is_empty() || !(diagonal.is_finite() && diagonal > 0.0) {
            return Err(Error::InvalidInput(format!(
                "{NAME}: the mesh {what} has no extent to place (no faces, or all its vertices at one point)"
            )));
        }
        let to_unit = Mat4::from_scale(Vec3::splat(DIAGONAL / diagonal)) * Mat4::from_translation(-(lo + hi) * 0.5);
        // The smallest cube of lattice points that holds them all.
        let side = (1..)
            .find(|s: &u32| (*s as u64).pow(3) >= instances as u64)
            .expect("a side");
        let mut rng = Rng::new(0x7B_B1E5);
        let unit_vector = |rng: &mut Rng| loop {
            let v = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            if (1e-4..=1.0).contains(&v.length_squared()) {
                break v.normalize();
            }
        };
        let bodies: Vec<Body> = (0..instances)
            .map(|k| {
                let center = Vec3::new((k % side) as f32, (k / side % side) as f32, (k / (side * side)) as f32);
                Body {
                    center,
                    axis: unit_vector(&mut rng),
                    spin_rad_per_s: rng.range(SPIN_RAD_PER_S.0, SPIN_RAD_PER_S.1)
                        * if rng.below(2) == 0 { 1.0 } else { -1.0 },
                    spin0_rad: rng.range(0.0, TAU),
                    bob_dir: unit_vector(&mut rng),
                    bob_rad_per_s: rng.range(BOB_RAD_PER_S.0, BOB_RAD_PER_S.1),
                    bob0_rad: rng.range(0.0, TAU),
                    tint: Vec3::from(TINTS[rng.below(TINTS.len() as u32) as usize]),
                }
            })
            .collect();
        let camera = frame_all(&bodies);
        Ok(Tumbling {
            vertices,
            faces,
            to_unit,
            bodies,
            camera,
        })
    }

    /// How many instances.
    pub fn instances(&self) -> usize {
        self.bodies.len()
    }

    /// Each instance's mesh-to-world transform at `time` seconds (any time is valid).
    pub fn transforms_at(&self, time: f32) -> Vec<Mat4> {
        self.bodies
            .iter()
            .map(|b| {
                let spin = Quat::from_axis_angle(b.axis, b.spin0_rad + b.spin_rad_per_s * time);
                let at = b.center + b.bob_dir * (BOB * (b.bob0_rad + b.bob_rad_per_s * time).sin());
                Mat4::from_rotation_translation(spin, at) * self.to_unit
            })
            .collect()
    }

    /// The two levels: the mesh once (geometry 0, placed as instance 0) and an instance of it
    /// for each other body, placed at `time`; returns the scene and the geometry ids in body
    /// order (`set_transforms` takes them with `transforms_at`'s matrices).
    pub fn query_scene(&self, opts: QueryOptions, time: f32) -> Result<(QueryScene, Vec<u32>)> {
        let transforms = self.transforms_at(time);
        let mut scene = QueryScene::new(opts);
        let ids = scene.add_placed(self.vertices.clone(), self.faces.clone(), &transforms)?;
        // A move marks the scene as one that moves (as `add_instance` does, which a single
        // instance never calls): its CPU rays then walk the two levels from the first query,
        // not a merged mesh that the first move would leave for a second structure.
        scene.set_transforms(&ids, &transforms)?;
        Ok((scene, ids))
    }

    /// The same instances at `time` merged into one world-space mesh: instance k's faces are
    /// faces `k * faces.len() ..` of it (for comparing the two levels with one structure).
    pub fn flat_at(&self, time: f32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let n = self.vertices.len() as u32;
        let mut vertices = Vec::with_capacity(self.vertices.len() * self.bodies.len());
        let mut faces = Vec::with_capacity(self.faces.len() * self.bodies.len());
        for (k, m) in self.transforms_at(time).iter().enumerate() {
            vertices.extend(
                self.vertices
                    .iter()
                    .map(|p| m.transform_point3(Vec3::from(*p)).to_array()),
            );
            faces.extend(self.faces.iter().map(|f| f.map(|i| i + k as u32 * n)));
        }
        (vertices, faces)
    }

    /// The camera's primary rays through the pixels' centres, row by row from the top
    /// (`CameraFrame::ray`, as the renderer makes them), as `[origin, unit direction]`.
    pub fn primary_rays(&self, width: u32, height: u32) -> Vec<[f32; 6]> {
        let frame = self.camera.frame(width, height);
        (0..width * height)
            .into_par_iter()
            .with_min_len(4096)
            .map(|i| {
                let r = frame.ray(i % width, i / width);
                [r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z]
            })
            .collect()
    }

    /// The image of `hits` (`cast_rays` of `rays`, from `query_scene`'s scene): each hit its
    /// instance's tint by a headlight (the cosine between the face's normal and the ray, either
    /// side) over `AMBIENT`; misses a sky gradient by row.
    pub fn shade(&self, rays: &[[f32; 6]], hits: &RayHits, width: u32, height: u32) -> Image {
        let pixels: Vec<Vec3> = (0..rays.len())
            .into_par_iter()
            .with_min_len(4096)
            .map(|i| {
                let id = hits.geometry_ids[i];
                if id == INVALID_ID {
                    return sky(i, width, height);
                }
                let tint = self.tint(id);
                let r = &rays[i];
                let cos = Vec3::from(hits.primitive_normals[i])
                    .dot(Vec3::new(r[3], r[4], r[5]))
                    .abs();
                tint * (AMBIENT + (1.0 - AMBIENT) * cos)
            })
            .collect();
        Image::from_pixels(width, height, pixels)
    }
}

/// How far a shadow ray starts off its hit point along the face's normal, relative to the
/// point's largest coordinate (at least 1): past the rounding of `origin + t * dir`, which is
/// about an ulp of the coordinates, so that a face does not shadow itself.
const SHADOW_OFFSET: f32 = 1e-4;

impl Tumbling {
    /// The middle of the lattice, where the camera looks (`--light` sets a light's intensity
    /// by its distance to it, as `render` does by the scene's centre).
    pub fn center(&self) -> Vec3 {
        let (lo, hi) = self
            .bodies
            .iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), b| {
                (l.min(b.center), h.max(b.center))
            });
        (lo + hi) * 0.5
    }

    /// One shadow ray for each of `rays`' hits and each of `lights` (ray `i`'s toward light
    /// `k` at `i * lights.len() + k`), for `QueryScene::test_occlusions` over `0 < t < 1`:
    /// from the hit, off the face on the side the eye sees, to the light (the direction's
    /// length the distance). A miss, or a face turned from the light, gets a zero direction,
    /// which nothing occludes (and `shade_lit` adds no light there).
    pub fn shadow_rays(&self, rays: &[[f32; 6]], hits: &RayHits, lights: &[PointLight]) -> Vec<[f32; 6]> {
        (0..rays.len())
            .into_par_iter()
            .with_min_len(4096)
            .flat_map_iter(|i| {
                let seen = seen_point(&rays[i], hits, i);
                lights.iter().map(move |l| {
                    let Some((p, n)) = seen else {
                        return [0.0; 6];
                    };
                    let from = p + n * SHADOW_OFFSET * p.abs().max_element().max(1.0);
                    let to = Vec3::from(l.position) - from;
                    if to.dot(n) <= 0.0 {
                        return [0.0; 6];
                    }
                    [from.x, from.y, from.z, to.x, to.y, to.z]
                })
            })
            .collect()
    }

    /// The image of `hits` lit by point `lights` in place of the headlight: each hit its
    /// instance's tint over `AMBIENT`, plus each light's irradiance on the face's side the eye
    /// sees (intensity x cosine / distance squared) where `occluded` (`shadow_rays`' answers;
    /// `None`: no shadows) does not say the light is blocked; misses the sky as in `shade`.
    pub fn shade_lit(
        &self,
        rays: &[[f32; 6]],
        hits: &RayHits,
        lights: &[PointLight],
        occluded: Option<&[bool]>,
        width: u32,
        height: u32,
    ) -> Image {
        let pixels: Vec<Vec3> = (0..rays.len())
            .into_par_iter()
            .with_min_len(4096)
            .map(|i| {
                let Some((p, n)) = seen_point(&rays[i], hits, i) else {
                    return sky(i, width, height);
                };
                let tint = self.tint(hits.geometry_ids[i]);
                let mut irradiance = Vec3::ZERO;
                for (k, l) in lights.iter().enumerate() {
                    if occluded.is_some_and(|o| o[i * lights.len() + k]) {
                        continue;
                    }
                    let to = Vec3::from(l.position) - p;
                    let d2 = to.length_squared();
                    let cos = n.dot(to) / d2.sqrt();
                    if cos > 0.0 && d2 > 0.0 {
                        irradiance += Vec3::from(l.intensity) * (cos / d2);
                    }
                }
                tint * (Vec3::splat(AMBIENT) + (1.0 - AMBIENT) * irradiance)
            })
            .collect();
        Image::from_pixels(width, height, pixels)
    }

    /// Instance `id`'s tint (white for an id no body has).
    fn tint(&self, id: u32) -> Vec3 {
        self.bodies.get(id as usize).map_or(Vec3::ONE, |b| b.tint)
    }
}

/// Ray `i`'s hit point (world space) and its face's unit normal turned toward the ray's
/// origin (the side the eye sees: the faces are lit on either side); `None` for a miss.
fn seen_point(ray: &[f32; 6], hits: &RayHits, i: usize) -> Option<(Vec3, Vec3)> {
    if hits.geometry_ids[i] == INVALID_ID {
        return None;
    }
    let (o, d) = (Vec3::new(ray[0], ray[1], ray[2]), Vec3::new(ray[3], ray[4], ray[5]));
    let n = Vec3::from(hits.primitive_normals[i]);
    Some((o + d * hits.t_hit[i], if n.dot(d) > 0.0 { -n } else { n }))
}

/// Pixel `i`'s sky: a gradient by row, lighter toward the top.
fn sky(i: usize, width: u32, height: u32) -> Vec3 {
    let up = 1.0 - (i as u32 / width) as f32 / height.max(1) as f32;
    Vec3::new(0.55, 0.62, 0.72).lerp(Vec3::new(0.85, 0.9, 0.97), up)
}

/// A camera that sees every lattice point with its instance whatever its pose: from above and
/// to the right of the front, its field of view the sphere about the instances' box.
fn frame_all(bodies: &[Body]) -> Camera {
    let (lo, hi) = bodies.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), b| {
        (l.min(b.center), h.max(b.center))
    });
    let reach = Vec3::splat(DIAGONAL * 0.5 + BOB);
    let (lo, hi) = (lo - reach, hi + reach);
    let target = (lo + hi) * 0.5;
    let radius = (hi - lo).length() * 0.5;
    let vfov_deg = 40.0f32;
    let distance = radius / (vfov_deg.to_radians() * 0.5).sin();
    Camera {
        eye: target + Vec3::new(0.55, 0.45, 1.0).normalize() * distance,
        target,
        up: Vec3::Y,
        vfov_deg,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetrahedron() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let v = vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]];
        (v, vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    }

    #[test]
    fn bad_counts_and_meshes_are_errors() {
        let (v, f) = tetrahedron();
        for n in [0, MAX_INSTANCES + 1, u32::MAX] {
            let e = Tumbling::new(v.clone(), f.clone(), n, "t.ply").unwrap_err().to_string();
            assert!(e.contains("--instances") && e.contains(&n.to_string()), "{e}");
        }
        let e = Tumbling::new(vec![[1.0; 3]; 3], vec![[0, 1, 2]], 5, "flat.ply").unwrap_err();
        assert!(e.to_string().contains("flat.ply"), "{e}");
    }

    /// Instances stay apart (within their lattice cell's sphere), turn rigidly, and move.
    #[test]
    fn rigid_apart_and_moving() {
        let (v, f) = tetrahedron();
        let t = Tumbling::new(v.clone(), f, 30, "t").unwrap();
        let (a, b) = (t.transforms_at(0.0), t.transforms_at(0.5));
        assert_eq!(a.len(), 30);
        for (k, (ma, mb)) in a.iter().zip(&b).enumerate() {
            let c = t.bodies[k].center;
            for p in &v {
                let (pa, pb) = (ma.transform_point3(Vec3::from(*p)), mb.transform_point3(Vec3::from(*p)));
                assert!((pa - c).length() <= DIAGONAL * 0.5 + BOB + 1e-5, "instance {k}");
                assert!((pb - c).length() <= DIAGONAL * 0.5 + BOB + 1e-5, "instance {k}");
            }
            // Rigid: lengths kept (up to the uniform scale).
            let d = |m: &Mat4| (m.transform_point3(Vec3::from(v[1])) - m.transform_point3(Vec3::from(v[0]))).length();
            assert!((d(ma) - d(mb)).abs() < 1e-5);
            assert!(!ma.abs_diff_eq(*mb, 1e-3), "instance {k} does not move");
        }
    }
}
