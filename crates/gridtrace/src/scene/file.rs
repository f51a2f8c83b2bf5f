//! Scene files (TOML): meshes with transforms and materials, lights and camera.
//!
//! ```toml
//! background = [0.05, 0.06, 0.09]      # optional, linear RGB
//! ambient = [0.06, 0.06, 0.06]         # optional
//!
//! [camera]
//! eye = [0, 1, 4]
//! target = [0, 0.5, 0]
//! up = [0, 1, 0]                       # optional, default +Y
//! vfov = 45                            # optional, degrees
//!
//! [[light]]
//! position = [2, 4, 3]
//! intensity = 20                       # a number or [r, g, b]; falls off as 1/d^2
//!
//! [[material]]
//! name = "mirror"
//! diffuse = [0.8, 0.8, 0.8]
//! reflectivity = 0.9
//!
//! [[object]]
//! mesh = "bunny.ply"                   # relative to this file; or:
//! # shape = "icosphere" | "box" | "room" | "plane" | "torus-knot" | "builtin"
//! material = "mirror"                  # optional: overrides the file's materials
//! translate = [0, 0, 0]                # optional; applied as translate * rotate * scale
//! rotate = [0, 90, 0]                  # optional, degrees about x, then y, then z
//! scale = 1.0                          # optional, a number or [x, y, z]
//! copies = [{ translate = [2, 0, 0] }, { translate = [4, 0, 0], rotate = [0, 45, 0] }]
//!                                      # optional: the object placed once per entry, each
//!                                      # entry's transform after the object's own
//! ```
//! Shapes take `radius`/`level` (icosphere), `min`/`max`/`subdiv` (box, room), `size`/`subdiv`
//! (plane), `p`/`q`/`tube`/`rings`/`sides` (torus-knot); `builtin = "knot-box"` imports a whole
//! built-in scene's geometry.

use std::path::Path;

use glam::{EulerRot, Mat4, Quat, Vec3};
use serde::Deserialize;

use super::procedural::{box_mesh, icosphere, plane, torus_knot};
use super::{Camera, Material, PointLight, Scene, builtin};
use crate::{Error, Location, Result};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    background: Option<[f32; 3]>,
    ambient: Option<[f32; 3]>,
    camera: CameraDef,
    #[serde(default)]
    light: Vec<LightDef>,
    #[serde(default)]
    material: Vec<MaterialDef>,
    #[serde(default)]
    object: Vec<ObjectDef>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraDef {
    eye: [f32; 3],
    target: [f32; 3],
    up: Option<[f32; 3]>,
    vfov: Option<f32>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Rgb {
    Gray(f32),
    Rgb([f32; 3]),
}

impl Rgb {
    fn vec(&self) -> Vec3 {
        match self {
            Rgb::Gray(g) => Vec3::splat(*g),
            Rgb::Rgb(c) => Vec3::from(*c),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightDef {
    position: [f32; 3],
    intensity: Rgb,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialDef {
    name: String,
    diffuse: Rgb,
    #[serde(default)]
    reflectivity: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectDef {
    mesh: Option<String>,
    shape: Option<String>,
    builtin: Option<String>,
    material: Option<String>,
    translate: Option<[f32; 3]>,
    rotate: Option<[f32; 3]>,
    scale: Option<Rgb>,
    radius: Option<f32>,
    level: Option<u32>,
    min: Option<[f32; 3]>,
    max: Option<[f32; 3]>,
    size: Option<f32>,
    subdiv: Option<u32>,
    p: Option<u32>,
    q: Option<u32>,
    tube: Option<f32>,
    rings: Option<u32>,
    sides: Option<u32>,
    copies: Option<Vec<PlacementDef>>,
}

/// A transform: `translate * rotate * scale`, each optional (an object's, or one of its
/// `copies`).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PlacementDef {
    translate: Option<[f32; 3]>,
    rotate: Option<[f32; 3]>,
    scale: Option<Rgb>,
}

impl PlacementDef {
    /// The matrix, or `None` when an entry is not finite.
    fn matrix(&self) -> Option<Mat4> {
        placement(self.translate, self.rotate, self.scale.as_ref())
    }
}

/// `translate * rotate * scale` (each optional: none, none, one), or `None` when an entry is not
/// finite: an object's own transform and each of its `copies`.
fn placement(translate: Option<[f32; 3]>, rotate: Option<[f32; 3]>, scale: Option<&Rgb>) -> Option<Mat4> {
    let scale = scale.map(Rgb::vec).unwrap_or(Vec3::ONE);
    let rot = rotate.map(Vec3::from).unwrap_or(Vec3::ZERO);
    let xf = Mat4::from_scale_rotation_translation(
        scale,
        Quat::from_euler(
            EulerRot::ZYX,
            rot.z.to_radians(),
            rot.y.to_radians(),
            rot.x.to_radians(),
        ),
        Vec3::from(translate.unwrap_or([0.0; 3])),
    );
    xf.is_finite().then_some(xf)
}

/// An object's triangles: its mesh file (relative to `base`), a built-in scene's geometry or
/// a procedural shape, exactly one of them; the error without its place (the caller adds it).
fn object_mesh(o: &ObjectDef, base: &Path) -> std::result::Result<crate::Mesh, String> {
    let given = [o.mesh.is_some(), o.shape.is_some(), o.builtin.is_some()]
        .iter()
        .filter(|b| **b)
        .count();
    if given != 1 {
        return Err("an object needs exactly one of 'mesh', 'shape' or 'builtin'".into());
    }
    if let Some(file) = &o.mesh {
        // The mesh's own error (file and place in it), and where the scene refers to it.
        return crate::io::load_mesh(&base.join(file)).map_err(|e| format!("mesh '{file}': {e}"));
    }
    if let Some(name) = &o.builtin {
        return builtin::scene(name)
            .map(|s| s.mesh)
            .ok_or_else(|| format!("unknown builtin scene '{name}'"));
    }
    let min = Vec3::from(o.min.unwrap_or([-1.0; 3]));
    let max = Vec3::from(o.max.unwrap_or([1.0; 3]));
    Ok(match o.shape.as_deref().unwrap_or_default() {
        "icosphere" | "sphere" => icosphere(Vec3::ZERO, o.radius.unwrap_or(1.0), o.level.unwrap_or(3).min(8)),
        "box" => box_mesh(min, max, o.subdiv.unwrap_or(1).min(1024), false),
        "room" => box_mesh(min, max, o.subdiv.unwrap_or(1).min(1024), true),
        "plane" => plane(o.size.unwrap_or(2.0), o.subdiv.unwrap_or(1).min(4096)),
        "torus-knot" => torus_knot(
            o.p.unwrap_or(2),
            o.q.unwrap_or(3),
            o.tube.unwrap_or(0.15),
            o.rings.unwrap_or(84).clamp(3, 1 << 16),
            o.sides.unwrap_or(6).clamp(3, 1 << 10),
        ),
        other => return Err(format!("unknown shape '{other}'")),
    })
}

/// Triangles the copies of one object may make in all: a typo in `copies` (or a big mesh copied
/// many times) is refused before memory is spent, not after. 64M triangles are 1.5 GB of
/// merged vertices and indices, beyond any GPU buffer gridtrace asks for.
const MAX_COPIED_TRIANGLES: usize = 64 << 20;

/// Reads and parses a scene file; meshes are found relative to its folder.
pub fn load_scene(path: &Path) -> Result<Scene> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_scene(&bytes, path)
}

/// Parses scene-file bytes; `path` names the file in errors and anchors relative mesh paths.
pub fn parse_scene(bytes: &[u8], path: &Path) -> Result<Scene> {
    let text = std::str::from_utf8(bytes).map_err(|e| {
        Error::parse(
            path,
            Location::Byte(e.valid_up_to() as u64),
            "scene file is not valid UTF-8",
        )
    })?;
    let line_of = |offset: usize| Location::Line(text[..offset.min(text.len())].matches('\n').count() + 1);
    let def: SceneFile = toml::from_str(text).map_err(|e| {
        let loc = e.span().map(|s| line_of(s.start)).unwrap_or(Location::Whole);
        Error::parse(path, loc, e.message().to_string())
    })?;
    // Semantic errors name the item; find its table header's line for the location.
    let item_line = |table: &str, index: usize| {
        let header = format!("[[{table}]]");
        text.match_indices(&header)
            .nth(index)
            .map(|(o, _)| line_of(o))
            .unwrap_or(Location::Whole)
    };
    let base = path.parent().unwrap_or(Path::new("."));

    let mut scene = Scene::default();
    if let Some(b) = def.background {
        scene.background = Vec3::from(b);
    }
    if let Some(a) = def.ambient {
        scene.ambient = Vec3::from(a);
    }
    scene.camera = Camera {
        eye: Vec3::from(def.camera.eye),
        target: Vec3::from(def.camera.target),
        up: Vec3::from(def.camera.up.unwrap_or([0.0, 1.0, 0.0])),
        vfov_deg: def.camera.vfov.unwrap_or(45.0),
    };
    scene
        .camera
        .validate()
        .map_err(|m| Error::parse(path, Location::Whole, format!("[camera]: {m}")))?;
    scene.lights = def
        .light
        .iter()
        .map(|l| PointLight::new(Vec3::from(l.position), l.intensity.vec()))
        .collect();

    let mut materials = std::collections::HashMap::new();
    for (i, m) in def.material.iter().enumerate() {
        if !(0.0..=1.0).contains(&m.reflectivity) {
            return Err(Error::parse(
                path,
                item_line("material", i),
                format!("material '{}': reflectivity must be in 0..=1", m.name),
            ));
        }
        materials.insert(
            m.name.clone(),
            Material {
                name: m.name.clone(),
                diffuse: m.diffuse.vec(),
                reflectivity: m.reflectivity,
            },
        );
    }

    for (i, o) in def.object.iter().enumerate() {
        let loc = item_line("object", i);
        let err = |m: String| Error::parse(path, loc, m);
        let material = match &o.material {
            Some(name) => Some(
                materials
                    .get(name)
                    .cloned()
                    .ok_or_else(|| err(format!("unknown material '{name}'")))?,
            ),
            None => None,
        };
        let xf = placement(o.translate, o.rotate, o.scale.as_ref())
            .ok_or_else(|| err("non-finite transform (translate, rotate or scale)".into()))?;
        let copies = match &o.copies {
            None => vec![Mat4::IDENTITY],
            Some(c) if c.is_empty() => return Err(err("'copies' is empty: give at least one placement".into())),
            Some(c) => c
                .iter()
                .enumerate()
                .map(|(k, p)| {
                    p.matrix().ok_or_else(|| {
                        err(format!(
                            "copies[{k}]: non-finite transform (translate, rotate or scale)"
                        ))
                    })
                })
                .collect::<Result<Vec<_>>>()?,
        };
        let mesh = object_mesh(o, base).map_err(err)?;
        if mesh.triangles.len().saturating_mul(copies.len()) > MAX_COPIED_TRIANGLES {
            return Err(err(format!(
                "{} copies of {} triangles are more than {MAX_COPIED_TRIANGLES} triangles",
                copies.len(),
                mesh.triangles.len()
            )));
        }
        // The mesh is read (or made) once; each copy adds its triangles placed by its own
        // transform after the object's (the last takes the mesh itself). The renderer traces
        // one merged structure over them.
        let (last, others) = copies.split_last().expect("at least one copy");
        for copy in others {
            scene.add_mesh(mesh.clone(), *copy * xf, material.clone());
        }
        scene.add_mesh(mesh, *last * xf, material);
    }
    if scene.mesh.triangles.is_empty() {
        return Err(Error::parse(
            path,
            Location::Whole,
            "scene has no objects with triangles",
        ));
    }
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_shapes_materials_lights() {
        let text = r#"
[camera]
eye = [0, 1, 4]
target = [0, 0, 0]

[[light]]
position = [1, 2, 3]
intensity = 5

[[material]]
name = "red"
diffuse = [1, 0, 0]
reflectivity = 0.25

[[object]]
shape = "icosphere"
level = 1
material = "red"
translate = [0, 1, 0]

[[object]]
shape = "plane"
scale = 3
"#;
        let s = parse_scene(text.as_bytes(), Path::new("t.toml")).unwrap();
        assert_eq!(s.mesh.triangles.len(), 80 + 2);
        assert_eq!(s.lights.len(), 1);
        assert_eq!(
            s.mesh.materials[s.mesh.triangle_materials[0] as usize].reflectivity,
            0.25
        );
        assert!(s.mesh.positions[..42].iter().all(|p| (p.y - 1.0).abs() <= 1.0 + 1e-6));
    }

    #[test]
    fn copies_place_one_object_many_times() {
        let head = "[camera]\neye = [0, 1, 4]\ntarget = [0, 0, 0]\n";
        let copied = format!(
            "{head}[[object]]\nshape = \"icosphere\"\nlevel = 1\nscale = 0.5\n\
             copies = [{{ translate = [2, 0, 0] }}, {{ translate = [0, 3, 0], rotate = [0, 90, 0] }}]\n"
        );
        let apart = format!(
            "{head}[[object]]\nshape = \"icosphere\"\nlevel = 1\nscale = 0.5\ntranslate = [2, 0, 0]\n\
             [[object]]\nshape = \"icosphere\"\nlevel = 1\nscale = 0.5\ntranslate = [0, 3, 0]\nrotate = [0, 90, 0]\n"
        );
        let a = parse_scene(copied.as_bytes(), Path::new("c.toml")).unwrap();
        let b = parse_scene(apart.as_bytes(), Path::new("a.toml")).unwrap();
        assert_eq!(a.mesh.triangles, b.mesh.triangles);
        assert_eq!(a.mesh.triangles.len(), 160);
        for (p, q) in a.mesh.positions.iter().zip(&b.mesh.positions) {
            assert!((*p - *q).length() < 1e-6, "{p} {q}");
        }
        let err = |extra: &str| {
            let text = format!("{head}\n[[object]]\nshape = \"plane\"\n{extra}\n");
            parse_scene(text.as_bytes(), Path::new("s.toml"))
                .unwrap_err()
                .to_string()
        };
        let e = err("copies = []");
        assert!(e.contains("s.toml:line 5") && e.contains("'copies' is empty"), "{e}");
        let e = err("copies = [{ translate = [1, 0, 0] }, { scale = [1, nan, 1] }]");
        assert!(e.contains("copies[1]: non-finite"), "{e}");
        let e = err("copies = [{ translat = [1, 0, 0] }]");
        assert!(e.contains("s.toml:line 7") && e.contains("translat"), "{e}");
        let e = err(
            "subdiv = 1024\ncopies = [{}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}]",
        );
        assert!(e.contains("33 copies of 2097152 triangles are more than"), "{e}");
    }

    #[test]
    fn errors_name_file_and_line() {
        let text = "[camera]\neye = [0, 1, 4]\ntarget = [0, 0, 0]\n\n[[object]]\nshape = \"cube\"\n";
        let e = parse_scene(text.as_bytes(), Path::new("s.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("s.toml:line 5") && e.contains("unknown shape"), "{e}");
        let text = "[camera]\neye = [0, 1, 4]\ntarget = [0, 0, \"x\"]\n";
        let e = parse_scene(text.as_bytes(), Path::new("s.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("s.toml:line 3"), "{e}");
        let text = "[camera]\neye = [0, 1, 4]\ntarget = [0, 1, 4]\n[[object]]\nshape=\"plane\"\n";
        let e = parse_scene(text.as_bytes(), Path::new("s.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("eye equals target"), "{e}");
        let e = parse_scene(b"\xff\xfe", Path::new("s.toml")).unwrap_err().to_string();
        assert!(e.contains("byte 0"), "{e}");
        let text = "[camera]\neye = [0, 1, 4]\ntarget = [0, 0, 0]\n[[object]]\nmesh = \"missing.ply\"\n";
        let e = parse_scene(text.as_bytes(), Path::new("dir/s.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.ply"), "{e}");
    }
}
