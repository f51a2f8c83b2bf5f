//! Built-in procedural scenes: they need no file, so the first-run demo and the tests always work.

use glam::{Mat4, Vec3};

use super::procedural::{box_mesh, icosphere, plane, torus_knot};
use super::{Camera, Material, Mesh, PointLight, Scene};

/// Names accepted by `scene()`, with a one-line description each.
pub const SCENES: &[(&str, &str)] = &[
    (
        "knot-box",
        "torus knot inside a closed box, camera inside (the paper's Torus Knot scene, 1,020 triangles)",
    ),
    (
        "mirror-spheres",
        "spheres and a knot over a mirror floor in a room: reflections two levels deep",
    ),
    (
        "sparse-room",
        "a small sphere in a large empty room: where proximity clouds pay off",
    ),
];

pub fn scene(name: &str) -> Option<Scene> {
    match name {
        "knot-box" => Some(knot_box()),
        "mirror-spheres" => Some(mirror_spheres()),
        "sparse-room" => Some(sparse_room()),
        _ => None,
    }
}

fn mat(name: &str, rgb: [f32; 3], reflectivity: f32) -> Option<Material> {
    Some(Material {
        name: name.into(),
        diffuse: Vec3::from(rgb),
        reflectivity,
    })
}

/// The paper's Torus Knot scene: a (2,3) knot of 1,008 triangles in a 12-triangle box, camera
/// and light inside the box, so every shadow ray stays inside the geometry.
pub fn knot_box() -> Scene {
    let mut s = Scene::default();
    s.add_mesh(
        box_mesh(Vec3::splat(-1.5), Vec3::splat(1.5), 1, true),
        Mat4::IDENTITY,
        mat("walls", [0.8, 0.78, 0.72], 0.0),
    );
    s.add_mesh(
        torus_knot(2, 3, 0.16, 84, 6),
        Mat4::from_scale(Vec3::splat(1.1)),
        mat("knot", [0.85, 0.25, 0.15], 0.0),
    );
    s.camera = Camera {
        eye: Vec3::new(0.5, 1.05, 1.35),
        target: Vec3::new(0.0, -0.1, 0.0),
        up: Vec3::Y,
        vfov_deg: 75.0,
    };
    s.lights = vec![
        PointLight::new(Vec3::new(0.6, 1.3, 0.9), Vec3::splat(2.2)),
        PointLight::new(Vec3::new(-1.1, 0.4, -0.6), Vec3::new(0.5, 0.6, 0.9)),
    ];
    s
}

/// Spheres (one mirror), a reflective knot and a mirror floor inside a room.
pub fn mirror_spheres() -> Scene {
    let mut s = Scene::default();
    s.add_mesh(
        box_mesh(Vec3::new(-6.0, -0.001, -6.0), Vec3::new(6.0, 6.0, 6.0), 2, true),
        Mat4::IDENTITY,
        mat("room", [0.7, 0.72, 0.8], 0.0),
    );
    s.add_mesh(
        plane(8.0, 4),
        Mat4::IDENTITY,
        mat("mirror floor", [0.35, 0.35, 0.38], 0.6),
    );
    s.add_mesh(
        icosphere(Vec3::new(0.0, 1.0, 0.0), 1.0, 3),
        Mat4::IDENTITY,
        mat("mirror ball", [0.9, 0.9, 0.9], 0.9),
    );
    s.add_mesh(
        icosphere(Vec3::new(-2.2, 0.7, 0.8), 0.7, 3),
        Mat4::IDENTITY,
        mat("red", [0.85, 0.15, 0.12], 0.0),
    );
    s.add_mesh(
        icosphere(Vec3::new(2.1, 0.6, 1.0), 0.6, 3),
        Mat4::IDENTITY,
        mat("blue", [0.15, 0.3, 0.85], 0.15),
    );
    s.add_mesh(
        torus_knot(2, 3, 0.12, 96, 8),
        Mat4::from_translation(Vec3::new(0.6, 2.9, -2.2)) * Mat4::from_scale(Vec3::splat(1.2)),
        mat("gold knot", [0.9, 0.7, 0.25], 0.35),
    );
    s.camera = Camera {
        eye: Vec3::new(0.4, 2.3, 5.6),
        target: Vec3::new(0.0, 1.1, 0.0),
        up: Vec3::Y,
        vfov_deg: 55.0,
    };
    s.lights = vec![
        PointLight::new(Vec3::new(-3.0, 5.0, 3.0), Vec3::splat(22.0)),
        PointLight::new(Vec3::new(4.0, 3.0, -1.0), Vec3::new(6.0, 5.0, 3.5)),
    ];
    s
}

/// A 320-triangle sphere in a 40-unit room, seen from near a wall: mostly empty space.
pub fn sparse_room() -> Scene {
    let mut s = Scene::default();
    s.add_mesh(
        box_mesh(Vec3::splat(-20.0), Vec3::splat(20.0), 1, true),
        Mat4::IDENTITY,
        mat("room", [0.75, 0.75, 0.75], 0.0),
    );
    s.add_mesh(
        icosphere(Vec3::new(2.0, -1.0, -3.0), 1.0, 2),
        Mat4::IDENTITY,
        mat("ball", [0.3, 0.7, 0.35], 0.0),
    );
    s.camera = Camera {
        eye: Vec3::new(-12.0, 6.0, 15.0),
        target: Vec3::new(2.0, -1.0, -3.0),
        up: Vec3::Y,
        vfov_deg: 30.0,
    };
    s.lights = vec![PointLight::new(Vec3::new(-5.0, 15.0, 10.0), Vec3::splat(400.0))];
    s
}

/// Puts any mesh into an auto-framed scene: optionally a floor under it (+Y up), one light, a
/// camera that sees the whole mesh from the front and slightly above. Without the floor the mesh
/// is alone, as in the paper's Stanford Bunny scene (a floor 3x the mesh's size also makes the
/// grid 3x wider and the mesh's share of cells small).
pub fn mesh_scene(mesh: Mesh, floor: bool) -> Scene {
    let mut s = Scene::default();
    let b = super::Aabb::from_points(&mesh.positions);
    let c = b.center();
    let r = (b.diagonal() * 0.5).max(1e-6);
    s.add_mesh(mesh, Mat4::IDENTITY, None);
    if floor {
        let floor_y = b.min.y - r * 1e-3;
        s.add_mesh(
            plane(r * 3.0, 1),
            Mat4::from_translation(Vec3::new(c.x, floor_y, c.z)),
            mat("floor", [0.55, 0.55, 0.55], 0.0),
        );
    }
    let vfov = 40.0f32;
    let dist = r / (vfov.to_radians() * 0.5).sin() * 1.05;
    s.camera = Camera {
        eye: c + Vec3::new(0.0, 0.35, 1.0).normalize() * dist,
        target: c,
        up: Vec3::Y,
        vfov_deg: vfov,
    };
    let light = c + Vec3::new(-1.2, 2.2, 1.6) * r;
    s.lights = vec![PointLight::new(light, Vec3::splat((light - c).length_squared() * 1.1))];
    s
}
