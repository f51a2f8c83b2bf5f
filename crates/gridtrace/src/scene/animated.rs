//! Built-in animated scenes: the triangles and materials are fixed, the vertex positions are a
//! function of time. For dynamic-scene work: each frame's positions go to a refit (or a
//! rebuild) of the acceleration structure over the same triangles.
//!
//! * `twisting-knot`: a torus knot of 40,000 triangles over a floor, spinning about its axis
//!   and twisted about it by an angle that varies with height and time, so that its triangles
//!   deform, not only move rigidly.
//! * `bouncing-spheres`: five spheres bouncing on a floor, each on a parabola, squashed a little
//!   while in contact with the floor.
//! * `animated`: both in one scene (the default).
//!
//! Every motion repeats after `Animation::period()`; floor vertices never move.

use std::f32::consts::{PI, TAU};
use std::ops::Range;

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use super::procedural::{icosphere, plane, torus_knot};
use super::{Camera, Material, PointLight, Scene};

/// Seconds after which every built-in motion repeats.
const PERIOD: f32 = 6.0;
/// Acceleration of the bouncing spheres (scene units per second squared: about 0.4 g with a
/// scene unit as a metre, which keeps the bounces low enough to frame with the knot).
const GRAVITY: f32 = 4.0;
/// Fraction of a bounce that a sphere spends in contact with the floor, squashing and
/// recovering.
const CONTACT: f32 = 0.06;
/// Vertices per parallel task in `positions_at`: small parts are posed on one thread.
const MIN_CHUNK: usize = 4096;
/// Where the knot's axis stands, and how much it is scaled from `torus_knot`'s unit size.
const KNOT_CENTER: Vec3 = Vec3::new(0.0, 1.25, 0.0);
const KNOT_SCALE: f32 = 1.5;

/// A scene whose vertices move: the topology (triangles, materials) is fixed, positions are a
/// function of time.
#[derive(Debug, Clone)]
pub struct Animation {
    pub name: &'static str,
    /// The scene at time 0: `scene.mesh.positions` is `positions_at(0.0)`, and its normals
    /// are those of that pose.
    pub scene: Scene,
    /// The vertex positions every pose is computed from: the moving parts unposed (for a
    /// sphere, relative to its centre), the static ones where they stay.
    rest: Vec<Vec3>,
    /// The moving vertex ranges and how each moves; vertices in no part are static.
    parts: Vec<Part>,
    period: f32,
}

#[derive(Debug, Clone)]
struct Part {
    vertices: Range<usize>,
    motion: Motion,
}

#[derive(Debug, Clone, Copy)]
enum Motion {
    /// Turns `spins` times per period about the vertical axis through `center`, and twists
    /// about it: a vertex at height `y` turns by a further
    /// `amplitude * sin(TAU * wobbles * phase) * (y - center.y) / half_height` radians.
    Twist {
        center: Vec3,
        half_height: f32,
        amplitude: f32,
        spins: f32,
        wobbles: f32,
    },
    /// A sphere of `radius` (rest positions relative to its centre) bouncing `bounces` times per
    /// period on the floor at `floor_y`, at horizontal position (`x`, `z`), up to `height`
    /// above it, starting `offset` (a fraction of a bounce) into its first bounce. In contact
    /// it squashes by up to `squash` vertically, keeping its volume.
    Bounce {
        x: f32,
        z: f32,
        floor_y: f32,
        radius: f32,
        height: f32,
        bounces: f32,
        offset: f32,
        squash: f32,
    },
}

/// A motion at one moment: what every vertex of a part goes through.
#[derive(Debug, Clone, Copy)]
enum Pose {
    /// A vertex at height `y` above `center` turns about the vertical through `center` by
    /// `spin + twist * y` radians.
    Twist { center: Vec3, spin: f32, twist: f32 },
    /// A vertex at `p` (relative to the sphere's centre) goes to `center + p * scale`.
    Scale { center: Vec3, scale: Vec3 },
}

impl Pose {
    #[inline]
    fn apply(self, p: Vec3) -> Vec3 {
        match self {
            Pose::Twist { center, spin, twist } => {
                let d = p - center;
                let (s, c) = (spin + twist * d.y).sin_cos();
                center + Vec3::new(c * d.x - s * d.z, d.y, s * d.x + c * d.z)
            }
            Pose::Scale { center, scale } => center + p * scale,
        }
    }
}

impl Motion {
    /// The pose at `phase` (time over the period, in [0, 1)).
    fn at(self, phase: f32) -> Pose {
        match self {
            Motion::Twist {
                center,
                half_height,
                amplitude,
                spins,
                wobbles,
            } => Pose::Twist {
                center,
                spin: TAU * spins * phase,
                twist: amplitude * (TAU * wobbles * phase).sin() / half_height,
            },
            Motion::Bounce {
                x,
                z,
                floor_y,
                radius,
                height,
                bounces,
                offset,
                squash,
            } => {
                let b = (phase * bounces + offset).fract();
                // Distance in phase to the middle of the contact (b = 0 or 1).
                let from_contact = b.min(1.0 - b);
                let (lift, sy) = if from_contact < CONTACT {
                    // On the floor: squashed most at the middle of the contact, smoothly less
                    // towards its ends.
                    (0.0, 1.0 - squash * 0.5 * (1.0 + (PI * from_contact / CONTACT).cos()))
                } else {
                    // In the air: a parabola over the rest of the bounce.
                    let s = (b - CONTACT) / (1.0 - 2.0 * CONTACT);
                    (4.0 * height * s * (1.0 - s), 1.0)
                };
                let sxz = 1.0 / sy.sqrt();
                Pose::Scale {
                    center: Vec3::new(x, floor_y + radius * sy + lift, z),
                    scale: Vec3::new(sxz, sy, sxz),
                }
            }
        }
    }
}

impl Animation {
    /// Names accepted by `by_name`; the first, `animated`, is the default.
    pub const NAMES: &[&str] = &["animated", "twisting-knot", "bouncing-spheres"];

    /// A built-in animation, or `None` for an unknown name.
    pub fn by_name(name: &str) -> Option<Animation> {
        let (knot, spheres) = match name {
            "animated" => (true, true),
            "twisting-knot" => (true, false),
            "bouncing-spheres" => (false, true),
            _ => return None,
        };
        let name = Self::NAMES.iter().copied().find(|&n| n == name)?;
        Some(build(name, knot, spheres))
    }

    /// Vertex positions of `scene.mesh` at `time` seconds (same length and order as
    /// scene.mesh.positions). Any time is valid, negative included: the motion repeats every
    /// `period()` seconds. The pose's normals, where wanted, are
    /// `scene::vertex_normals(&positions, &scene.mesh.triangles)`.
    pub fn positions_at(&self, time: f32) -> Vec<Vec3> {
        // The phase in f64, so that at late times the division and the remainder add no error
        // of their own.
        let phase = (time as f64 / self.period as f64).rem_euclid(1.0) as f32;
        let mut out = self.rest.clone();
        for part in &self.parts {
            let pose = part.motion.at(phase);
            out[part.vertices.clone()]
                .par_iter_mut()
                .zip(&self.rest[part.vertices.clone()])
                .with_min_len(MIN_CHUNK)
                .for_each(|(o, &p)| *o = pose.apply(p));
        }
        out
    }

    /// The period after which the motion repeats, in seconds (for looping playback).
    pub fn period(&self) -> f32 {
        self.period
    }
}

fn mat(name: &str, rgb: [f32; 3], reflectivity: f32) -> Option<Material> {
    Some(Material {
        name: name.into(),
        diffuse: Vec3::from(rgb),
        reflectivity,
    })
}

/// One of the bouncing spheres.
struct Ball {
    /// Position around the knot's axis, in degrees.
    angle: f32,
    radius: f32,
    /// Bounces per period.
    bounces: u32,
    /// How far into its first bounce it is at time 0, as a fraction of a bounce.
    offset: f32,
    rgb: [f32; 3],
    reflectivity: f32,
}

const BALLS: &[Ball] = &[
    Ball {
        angle: 0.0,
        radius: 0.5,
        bounces: 3,
        offset: 0.0,
        rgb: [0.15, 0.3, 0.85],
        reflectivity: 0.1,
    },
    Ball {
        angle: 72.0,
        radius: 0.4,
        bounces: 4,
        offset: 0.3,
        rgb: [0.2, 0.7, 0.3],
        reflectivity: 0.0,
    },
    Ball {
        angle: 144.0,
        radius: 0.55,
        bounces: 3,
        offset: 0.55,
        rgb: [0.9, 0.9, 0.9],
        reflectivity: 0.85,
    },
    Ball {
        angle: 216.0,
        radius: 0.35,
        bounces: 5,
        offset: 0.15,
        rgb: [0.9, 0.75, 0.2],
        reflectivity: 0.2,
    },
    Ball {
        angle: 288.0,
        radius: 0.45,
        bounces: 4,
        offset: 0.8,
        rgb: [0.7, 0.25, 0.75],
        reflectivity: 0.0,
    },
];
/// Distance of the spheres' centres from the knot's axis: clear of the knot (whose tube
/// reaches about 1.75 from it) even squashed.
const SPHERE_RING: f32 = 3.0;

fn build(name: &'static str, knot: bool, spheres: bool) -> Animation {
    let mut s = Scene::default();
    let mut parts = Vec::new();
    s.add_mesh(plane(9.0, 8), Mat4::IDENTITY, mat("floor", [0.55, 0.55, 0.58], 0.2));
    if knot {
        let start = s.mesh.positions.len();
        // 2 * 1000 * 20 = 40,000 triangles.
        s.add_mesh(
            torus_knot(2, 3, 0.16, 1000, 20),
            Mat4::from_translation(KNOT_CENTER) * Mat4::from_scale(Vec3::splat(KNOT_SCALE)),
            mat("knot", [0.85, 0.25, 0.15], 0.0),
        );
        let vertices = start..s.mesh.positions.len();
        // The knot's curve spans y in [-1/3, 1/3] before scaling, its tube 0.16 more.
        let half_height = KNOT_SCALE * (1.0 / 3.0 + 0.16);
        parts.push(Part {
            vertices,
            motion: Motion::Twist {
                center: KNOT_CENTER,
                half_height,
                amplitude: 1.2,
                spins: 1.0,
                wobbles: 2.0,
            },
        });
    }
    if spheres {
        for &Ball {
            angle,
            radius,
            bounces,
            offset,
            rgb,
            reflectivity,
        } in BALLS
        {
            let start = s.mesh.positions.len();
            // Level 4: 5,120 triangles. Added at the origin: the rest positions are relative
            // to the sphere's centre.
            s.add_mesh(
                icosphere(Vec3::ZERO, radius, 4),
                Mat4::IDENTITY,
                mat("ball", rgb, reflectivity),
            );
            let (sin, cos) = angle.to_radians().sin_cos();
            let duration = PERIOD / bounces as f32;
            parts.push(Part {
                vertices: start..s.mesh.positions.len(),
                motion: Motion::Bounce {
                    x: SPHERE_RING * cos,
                    z: SPHERE_RING * sin,
                    floor_y: 0.0,
                    radius,
                    // Up and down under constant gravity in the time off the floor.
                    height: GRAVITY * (duration * (1.0 - 2.0 * CONTACT)).powi(2) / 8.0,
                    bounces: bounces as f32,
                    offset,
                    squash: 0.25,
                },
            });
        }
    }
    // Frames everything that moves, over the whole period, in an image at least 4:3 wide (the
    // viewer's default 800 x 600); the knot alone from nearer.
    let target = Vec3::new(0.0, 0.8, 0.0);
    let back = Vec3::new(1.2, 3.2, 10.0);
    s.camera = Camera {
        eye: target + if spheres { back } else { back * 0.55 },
        target,
        up: Vec3::Y,
        vfov_deg: 38.0,
    };
    s.lights = vec![
        PointLight::new(Vec3::new(-4.0, 8.0, 5.0), Vec3::splat(75.0)),
        PointLight::new(Vec3::new(6.0, 4.0, -3.0), Vec3::new(22.0, 18.0, 13.0)),
    ];
    let mut a = Animation {
        name,
        rest: s.mesh.positions.clone(),
        scene: s,
        parts,
        period: PERIOD,
    };
    a.scene.mesh.positions = a.positions_at(0.0);
    // Normals of the pose at time 0. The knot is untwisted and unturned then (its rest
    // normals hold); a sphere squashed at that moment has an ellipsoid's normals.
    for part in &a.parts {
        match part.motion.at(0.0) {
            Pose::Twist { spin, twist, .. } => debug_assert!(spin == 0.0 && twist == 0.0),
            Pose::Scale { scale, .. } => {
                for n in &mut a.scene.mesh.normals[part.vertices.clone()] {
                    *n = (*n / scale).normalize_or_zero();
                }
            }
        }
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Where `p` lands in the image of `camera` with width / height `aspect`, as (x, y) in
    /// [-1, 1] across the image, or `None` behind the eye. The inverse of `CameraFrame::ray`.
    fn project(camera: &Camera, aspect: f32, p: Vec3) -> Option<(f32, f32)> {
        let forward = (camera.target - camera.eye).normalize();
        let right = forward.cross(camera.up).normalize();
        let up = right.cross(forward);
        let tan_half = (camera.vfov_deg.to_radians() * 0.5).tan();
        let d = p - camera.eye;
        let depth = d.dot(forward);
        (depth > 0.0).then(|| {
            (
                d.dot(right) / (depth * tan_half * aspect),
                d.dot(up) / (depth * tan_half),
            )
        })
    }

    /// The scenes are framed for images at least this wide for their height (800 x 600, the
    /// viewer's default).
    const ASPECT: f32 = 4.0 / 3.0;

    fn all() -> Vec<Animation> {
        Animation::NAMES
            .iter()
            .map(|n| Animation::by_name(n).unwrap_or_else(|| panic!("{n} is listed but not built")))
            .collect()
    }

    /// Times across two periods, some negative, some off the frame grid.
    fn times(period: f32) -> Vec<f32> {
        (-8..=40).map(|k| k as f32 * period / 16.0 + 0.013).collect()
    }

    #[test]
    fn names() {
        for a in all() {
            assert!(Animation::NAMES.contains(&a.name));
            a.scene.camera.validate().unwrap();
            assert!(!a.scene.lights.is_empty());
            assert!(a.period() > 0.0 && a.period().is_finite());
            let m = &a.scene.mesh;
            assert_eq!(m.normals.len(), m.positions.len(), "{}", a.name);
            assert!(m.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4), "{}", a.name);
        }
        for bad in ["", "Animated", "twisting_knot", "knot-box", "bouncing-spheres "] {
            assert!(Animation::by_name(bad).is_none(), "{bad:?}");
        }
        let tris = |n: &str| Animation::by_name(n).unwrap().scene.mesh.triangles.len();
        assert!((40_000..=41_000).contains(&tris("twisting-knot")));
        assert_eq!(tris("animated"), tris("twisting-knot") + tris("bouncing-spheres") - 128);
    }

    #[test]
    fn time_zero_is_the_scene() {
        for a in all() {
            assert_eq!(a.positions_at(0.0), a.scene.mesh.positions, "{}", a.name);
            // The scene prepares (no bad vertices, no triangles lost).
            let prepared = a.scene.prepare(crate::Resolution::default()).unwrap();
            assert_eq!(prepared.degenerate_dropped, 0, "{}", a.name);
        }
    }

    /// At every time: as many positions as the scene has, all finite; the floor where it was;
    /// the same pose a period later (and earlier); and everything that moves stays in view of
    /// the scene's camera and above the floor.
    #[test]
    fn poses_are_periodic_finite_and_framed() {
        for a in all() {
            let rest = &a.scene.mesh.positions;
            let moving: Vec<bool> = (0..rest.len())
                .map(|i| a.parts.iter().any(|p| p.vertices.contains(&i)))
                .collect();
            assert!(
                moving.iter().filter(|&&m| !m).count() == 81,
                "{}: the floor's 9 x 9 vertices",
                a.name
            );
            let mut view = 0.0f32;
            for t in times(a.period()) {
                let pose = a.positions_at(t);
                assert_eq!(pose.len(), rest.len(), "{} at {t}", a.name);
                assert!(pose.iter().all(|p| p.is_finite()), "{} at {t}", a.name);
                for later in [a.positions_at(t + a.period()), a.positions_at(t - 2.0 * a.period())] {
                    let err = pose
                        .iter()
                        .zip(&later)
                        .map(|(p, q)| (*p - *q).length())
                        .fold(0.0, f32::max);
                    assert!(err < 1e-4, "{} at {t}: {err} from the pose a period away", a.name);
                }
                for (i, p) in pose.iter().enumerate() {
                    if !moving[i] {
                        assert_eq!(*p, rest[i], "{} at {t}: floor vertex {i} moved", a.name);
                        continue;
                    }
                    assert!(p.y >= 0.0, "{} at {t}: vertex {i} at {p} under the floor", a.name);
                    let (x, y) = project(&a.scene.camera, ASPECT, *p).expect("in front of the camera");
                    view = view.max(x.abs()).max(y.abs());
                }
            }
            assert!(view < 0.95, "{}: moving vertices reach {view} of the image", a.name);
        }
    }

    /// The knot really deforms: the distance between two of its vertices at different heights
    /// changes with time (a rigid motion would keep it), and the spheres squash at contact.
    #[test]
    fn the_motion_deforms() {
        let a = Animation::by_name("animated").unwrap();
        let knot = &a.parts[0];
        assert!(matches!(knot.motion, Motion::Twist { .. }));
        let (lo, hi) = knot
            .vertices
            .clone()
            .fold((knot.vertices.start, knot.vertices.start), |(lo, hi), i| {
                let y = |j: usize| a.rest[j].y;
                (if y(i) < y(lo) { i } else { lo }, if y(i) > y(hi) { i } else { hi })
            });
        let gap = |t: f32| {
            let p = a.positions_at(t);
            (p[lo] - p[hi]).length()
        };
        assert!((gap(0.0) - gap(a.period() / 8.0)).abs() > 0.1, "the knot twists");
        let squashed = (0..200).any(|k| {
            let t = k as f32 * a.period() / 200.0;
            let part = &a.parts[1];
            let p = a.positions_at(t);
            let b = crate::accel::Aabb::from_points(&p[part.vertices.clone()]);
            b.extent().y < 0.9 * b.extent().x
        });
        assert!(squashed, "a sphere squashes");
    }
}
