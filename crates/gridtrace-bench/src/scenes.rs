//! The paper's four benchmark scenes (Knight, Torus Knot, Bunny, Stanford Bunny), the meshes of
//! the scaling series, and where the mesh files are found.
//!
//! Mesh files are data, not part of the repository: they are read from a data folder (by
//! default `../shared/data/meshes`, see `find_data_dir`). A scene whose file is missing is
//! skipped by the benchmark with a message naming the path.

use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3};

use gridtrace::accel::{Aabb, AccelKind, AccelParams, Resolution};
use gridtrace::scene::procedural::{box_mesh, icosphere, torus_knot};
use gridtrace::scene::{Camera, Material, Mesh, PointLight, Scene, builtin};
use gridtrace::{Error, Result};

/// Relative paths tried, in order, below each candidate root for the mesh folder.
const DATA_SUBDIRS: [&str; 2] = ["../shared/data/meshes", "shared/data/meshes"];

/// The mesh folder: `explicit` if given (it must exist), else `$GRIDTRACE_DATA_DIR`, else
/// `../shared/data/meshes` or `shared/data/meshes` relative to the current directory or any of
/// its ancestors, then relative to the executable's ancestors (so a binary in `target/` of a
/// checkout finds the `shared/` beside the checkout). `None` when none exists.
pub fn find_data_dir(explicit: Option<&Path>) -> Option<PathBuf> {
    if let Some(p) = explicit {
        return p.is_dir().then(|| p.to_path_buf());
    }
    if let Some(p) = std::env::var_os("GRIDTRACE_DATA_DIR").map(PathBuf::from)
        && p.is_dir()
    {
        return Some(p);
    }
    let mut roots: Vec<PathBuf> = Vec::new();
    if let Ok(cwd) = std::env::current_dir() {
        roots.extend(cwd.ancestors().map(Path::to_path_buf));
    }
    if let Ok(exe) = std::env::current_exe() {
        roots.extend(exe.ancestors().skip(1).map(Path::to_path_buf));
    }
    for r in roots {
        for sub in DATA_SUBDIRS {
            let p = r.join(sub);
            if p.join("SOURCES.md").is_file() || p.join("bunny").is_dir() {
                return Some(p);
            }
        }
    }
    None
}

/// One of the paper's scenes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PaperScene {
    /// Short name used on the command line and in the reports.
    pub name: &'static str,
    /// The paper's name of the scene.
    pub title: &'static str,
    /// The paper's triangle count.
    pub paper_tris: usize,
    /// The paper's hand-tuned grid dimensions.
    pub paper_grid: [u32; 3],
    /// Mesh files it needs, relative to the data folder.
    pub files: &'static [&'static str],
    /// Column of the paper's tables (0..4).
    pub column: usize,
}

pub const PAPER_SCENES: [PaperScene; 4] = [
    PaperScene {
        name: "knight",
        title: "Knight",
        paper_tris: 636,
        paper_grid: [14, 16, 14],
        files: &["knight/knight_422.obj"],
        column: 0,
    },
    PaperScene {
        name: "torus-knot",
        title: "Torus knot",
        paper_tris: 1024,
        paper_grid: [16, 16, 16],
        files: &[],
        column: 1,
    },
    PaperScene {
        name: "bunny",
        title: "Bunny",
        paper_tris: 1764,
        paper_grid: [20, 20, 20],
        files: &["bunny_lowpoly/bunny_1k.obj"],
        column: 2,
    },
    PaperScene {
        name: "stanford-bunny",
        title: "Stanford Bunny",
        paper_tris: 69451,
        paper_grid: [128, 128, 128],
        files: &["bunny/bun_zipper.ply"],
        column: 3,
    },
];

/// Looks a paper scene up by name (also accepts `knot-box` for the torus knot).
pub fn paper_scene(name: &str) -> Option<&'static PaperScene> {
    let name = if name == "knot-box" { "torus-knot" } else { name };
    PAPER_SCENES.iter().find(|s| s.name == name)
}

/// The paper's Tables 1-3 in milliseconds: `[mode][resolution 256/512/768][column]` with the
/// columns Knight g, Knight pc, Torus knot g, pc, Bunny g, pc, Stanford Bunny g (no pc column).
pub const PAPER_MS: [[[Option<f64>; 8]; 3]; 3] = {
    const fn row(v: [f64; 7]) -> [Option<f64>; 8] {
        [
            Some(v[0]),
            Some(v[1]),
            Some(v[2]),
            Some(v[3]),
            Some(v[4]),
            Some(v[5]),
            Some(v[6]),
            None,
        ]
    }
    [
        [
            row([45.0, 47.0, 55.0, 55.0, 37.0, 37.0, 142.0]),
            row([103.0, 106.0, 119.0, 133.0, 86.0, 89.0, 327.0]),
            row([177.0, 180.0, 210.0, 229.0, 149.0, 144.0, 551.0]),
        ],
        [
            row([96.0, 91.0, 169.0, 164.0, 75.0, 75.0, 235.0]),
            row([210.0, 215.0, 365.0, 401.0, 176.0, 181.0, 563.0]),
            row([349.0, 360.0, 671.0, 734.0, 302.0, 298.0, 960.0]),
        ],
        [
            row([168.0, 164.0, 306.0, 300.0, 129.0, 130.0, 482.0]),
            row([383.0, 390.0, 656.0, 691.0, 299.0, 306.0, 1243.0]),
            row([630.0, 643.0, 1173.0, 1244.0, 505.0, 501.0, 2188.0]),
        ],
    ]
};

/// The paper's time (ms) for a scene, mode, square resolution and acceleration, if it has one.
pub fn paper_ms(scene: &str, mode: gridtrace::Mode, res: (u32, u32), accel: gridtrace::AccelKind) -> Option<f64> {
    let s = paper_scene(scene)?;
    let m = match mode {
        gridtrace::Mode::Cast => 0,
        gridtrace::Mode::Shadow => 1,
        gridtrace::Mode::Trace => 2,
        gridtrace::Mode::Heat => return None,
    };
    let r = match res {
        (256, 256) => 0,
        (512, 512) => 1,
        (768, 768) => 2,
        _ => return None,
    };
    let a = match accel {
        gridtrace::AccelKind::Grid => 0,
        gridtrace::AccelKind::ProximityCloud => 1,
        // The paper measured only its two grids.
        _ => return None,
    };
    if s.column == 3 {
        return if a == 0 { PAPER_MS[m][r][6] } else { None };
    }
    PAPER_MS[m][r][s.column * 2 + a]
}

/// A scene ready to benchmark.
#[derive(Debug, Clone)]
pub struct BenchScene {
    pub name: String,
    pub title: String,
    pub scene: Scene,
    /// Triangles in the scene's mesh (before degenerate ones are dropped).
    pub triangles: usize,
    pub paper_tris: Option<usize>,
    pub paper_grid: Option<[u32; 3]>,
    /// How it was made (files and what was added), for the reports.
    pub description: String,
}

impl BenchScene {
    /// The grid resolution to use: the paper's hand-tuned dims if asked for and known, else
    /// `fallback`.
    pub fn resolution(&self, paper_grids: bool, fallback: Resolution) -> Resolution {
        match (paper_grids, self.paper_grid) {
            (true, Some(d)) => Resolution::Fixed(d),
            _ => fallback,
        }
    }

    /// The build parameters for `kind`: `resolution`'s for the grid (the benchmark's grid study
    /// sets them), every other structure's defaults.
    pub fn params_for(&self, kind: AccelKind, paper_grids: bool, fallback: Resolution) -> AccelParams {
        if kind.uses_grid() {
            self.resolution(paper_grids, fallback).into()
        } else {
            AccelParams::NONE
        }
    }
}

fn mat(name: &str, rgb: [f32; 3], reflectivity: f32) -> Option<Material> {
    Some(Material {
        name: name.into(),
        diffuse: Vec3::from(rgb),
        reflectivity,
    })
}

/// A transform that scales `mesh` to `height` along +Y and stands it on y = `floor_y`,
/// centred on x = z = 0.
fn stand_on_floor(mesh: &Mesh, height: f32, floor_y: f32) -> Mat4 {
    let b = Aabb::from_points(&mesh.positions);
    let s = height / b.extent().y.max(1e-12);
    let c = b.center();
    Mat4::from_translation(Vec3::new(0.0, floor_y, 0.0))
        * Mat4::from_scale(Vec3::splat(s))
        * Mat4::from_translation(Vec3::new(-c.x, -b.min.y, -c.z))
}

fn load(data_dir: &Path, rel: &str) -> Result<Mesh> {
    let p = data_dir.join(rel);
    if !p.is_file() {
        return Err(Error::InvalidInput(format!("mesh file {} not found", p.display())));
    }
    gridtrace::io::load_mesh(&p)
}

/// The Knight scene: `knight/knight_422.obj` (422 triangles, 2 of them degenerate) standing on
/// a 10x10 checkered board (200 triangles) on top of a slab (12 triangles): 634 triangles
/// against the paper's 636. Reflective board and knight, one light, shadows.
pub fn knight(data_dir: &Path) -> Result<Scene> {
    let knight = load(data_dir, "knight/knight_422.obj")?;
    let mut s = Scene::default();
    let n = 10;
    let sq = 0.25f32;
    let half = n as f32 * sq * 0.5;
    let (mut dark, mut light) = (Mesh::default(), Mesh::default());
    for i in 0..n {
        for j in 0..n {
            let m = if (i + j) % 2 == 0 { &mut dark } else { &mut light };
            let x0 = -half + i as f32 * sq;
            let z0 = -half + j as f32 * sq;
            let b = m.positions.len() as u32;
            m.positions.extend([
                Vec3::new(x0, 0.0, z0),
                Vec3::new(x0 + sq, 0.0, z0),
                Vec3::new(x0 + sq, 0.0, z0 + sq),
                Vec3::new(x0, 0.0, z0 + sq),
            ]);
            m.triangles.extend([[b, b + 2, b + 1], [b, b + 3, b + 2]]);
        }
    }
    s.add_mesh(dark, Mat4::IDENTITY, mat("dark squares", [0.12, 0.1, 0.09], 0.25));
    s.add_mesh(light, Mat4::IDENTITY, mat("light squares", [0.85, 0.82, 0.74], 0.25));
    s.add_mesh(
        box_mesh(Vec3::new(-half, -0.15, -half), Vec3::new(half, -0.001, half), 1, false),
        Mat4::IDENTITY,
        mat("board", [0.35, 0.2, 0.1], 0.0),
    );
    let xf = stand_on_floor(&knight, 1.2, 0.0);
    s.add_mesh(knight, xf, mat("knight", [0.9, 0.88, 0.82], 0.3));
    s.camera = Camera {
        eye: Vec3::new(1.9, 1.5, 2.6),
        target: Vec3::new(0.0, 0.45, 0.0),
        up: Vec3::Y,
        vfov_deg: 45.0,
    };
    s.lights = vec![PointLight::new(Vec3::new(-1.5, 3.0, 2.0), Vec3::splat(16.0))];
    Ok(s)
}

/// The Bunny scene: the 1,000-triangle low-poly bunny (`bunny_lowpoly/bunny_1k.obj`) on the
/// floor of a closed room of 8x8 quads per wall (768 triangles): 1,768 triangles against the
/// paper's 1,764. Camera and light inside the room; slightly reflective walls.
pub fn bunny_room(data_dir: &Path) -> Result<Scene> {
    let bunny = load(data_dir, "bunny_lowpoly/bunny_1k.obj")?;
    let mut s = Scene::default();
    s.add_mesh(
        box_mesh(Vec3::new(-2.0, 0.0, -2.0), Vec3::new(2.0, 2.5, 2.0), 8, true),
        Mat4::IDENTITY,
        mat("room", [0.75, 0.72, 0.68], 0.3),
    );
    let xf = stand_on_floor(&bunny, 1.0, 0.0);
    s.add_mesh(bunny, xf, mat("bunny", [0.85, 0.8, 0.7], 0.1));
    s.camera = Camera {
        eye: Vec3::new(0.9, 1.3, 1.9),
        target: Vec3::new(0.0, 0.45, 0.0),
        up: Vec3::Y,
        vfov_deg: 60.0,
    };
    s.lights = vec![PointLight::new(Vec3::new(-0.8, 2.2, 1.2), Vec3::splat(4.0))];
    Ok(s)
}

/// Builds a paper scene by name. Errors name a missing mesh file.
pub fn build_paper_scene(name: &str, data_dir: Option<&Path>) -> Result<BenchScene> {
    let ps = paper_scene(name).ok_or_else(|| {
        let names: Vec<_> = PAPER_SCENES.iter().map(|s| s.name).collect();
        Error::InvalidInput(format!(
            "unknown benchmark scene '{name}'; scenes: {}",
            names.join(", ")
        ))
    })?;
    let need_dir = || {
        data_dir.ok_or_else(|| {
            Error::InvalidInput(format!(
                "no mesh data folder found (needs {}); pass --data-dir",
                ps.files.join(", ")
            ))
        })
    };
    let (scene, description) = match ps.name {
        "knight" => (
            knight(need_dir()?)?,
            "knight/knight_422.obj on a 10x10 checkered board and a slab".to_string(),
        ),
        "torus-knot" => (
            builtin::knot_box(),
            "built-in knot-box: (2,3) torus knot in a closed box".into(),
        ),
        "bunny" => (
            bunny_room(need_dir()?)?,
            "bunny_lowpoly/bunny_1k.obj in a closed room of 8x8 quads per wall".into(),
        ),
        "stanford-bunny" => (
            builtin::mesh_scene(load(need_dir()?, "bunny/bun_zipper.ply")?, false),
            "bunny/bun_zipper.ply alone, auto-framed".into(),
        ),
        _ => unreachable!(),
    };
    Ok(BenchScene {
        name: ps.name.into(),
        title: ps.title.into(),
        triangles: scene.mesh.triangles.len(),
        scene,
        paper_tris: Some(ps.paper_tris),
        paper_grid: Some(ps.paper_grid),
        description,
    })
}

/// A mesh of the scaling series.
#[derive(Debug, Clone)]
pub struct ScalingMesh {
    pub name: String,
    /// `file:` path relative to the data folder, or `procedural`.
    pub source: String,
    pub mesh: Mesh,
}

/// The scaling series files, smallest first in each family.
pub const SCALING_FILES: [&str; 8] = [
    "bunny/bun_zipper_res4.ply",
    "bunny/bun_zipper_res3.ply",
    "bunny/bun_zipper_res2.ply",
    "bunny/bun_zipper.ply",
    "dragon/dragon_vrip_res4.ply",
    "dragon/dragon_vrip_res3.ply",
    "dragon/dragon_vrip_res2_binary.ply",
    "dragon/dragon_vrip_binary.ply",
];

/// Procedural meshes of the scaling series: icospheres of 20 * 4^level triangles for `levels`
/// and a finely tessellated torus knot (about 1.2 M triangles at the largest).
pub fn procedural_scaling(levels: std::ops::RangeInclusive<u32>, with_knots: bool) -> Vec<ScalingMesh> {
    let mut v: Vec<ScalingMesh> = levels
        .map(|l| ScalingMesh {
            name: format!("icosphere-{l}"),
            source: "procedural".into(),
            mesh: icosphere(Vec3::ZERO, 1.0, l),
        })
        .collect();
    if with_knots {
        for (rings, sides) in [(256u32, 8u32), (1024, 32), (4096, 64), (9600, 64)] {
            v.push(ScalingMesh {
                name: format!("torus-knot-{}", 2 * rings * sides),
                source: "procedural".into(),
                mesh: torus_knot(2, 3, 0.16, rings, sides),
            });
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_table_lookup() {
        use gridtrace::{AccelKind, Mode};
        assert_eq!(paper_ms("knight", Mode::Cast, (256, 256), AccelKind::Grid), Some(45.0));
        assert_eq!(
            paper_ms("torus-knot", Mode::Trace, (768, 768), AccelKind::ProximityCloud),
            Some(1244.0)
        );
        assert_eq!(
            paper_ms("stanford-bunny", Mode::Shadow, (512, 512), AccelKind::Grid),
            Some(563.0)
        );
        assert_eq!(
            paper_ms("stanford-bunny", Mode::Shadow, (512, 512), AccelKind::ProximityCloud),
            None
        );
        assert_eq!(paper_ms("bunny", Mode::Cast, (128, 128), AccelKind::Grid), None);
    }

    #[test]
    fn torus_knot_needs_no_files() {
        let s = build_paper_scene("torus-knot", None).unwrap();
        assert_eq!(s.triangles, 1020);
        assert!(build_paper_scene("knight", None).is_err());
    }
}
