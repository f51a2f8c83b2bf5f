//! Scene description: meshes, materials, lights, camera; and its preparation for ray tracing.

pub mod animated;
pub mod builtin;
pub mod camera;
pub mod file;
pub mod orbit;
pub mod procedural;
pub mod tumbling;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};

pub use crate::mesh::{Material, Mesh};
pub use camera::{Camera, CameraFrame};

use crate::accel::{Aabb, Accel, AccelKind, AccelParams, Resolution, TriAccel};
use crate::{Error, Result};

/// A point light. Irradiance falls off with the squared distance: `intensity / d^2`.
/// Also the GPU storage layout.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct PointLight {
    pub position: [f32; 3],
    pub _pad0: f32,
    pub intensity: [f32; 3],
    pub _pad1: f32,
}

impl PointLight {
    pub fn new(position: Vec3, intensity: Vec3) -> Self {
        PointLight {
            position: position.to_array(),
            _pad0: 0.0,
            intensity: intensity.to_array(),
            _pad1: 0.0,
        }
    }
}

/// A complete scene: one merged mesh (all objects in world space), lights and camera.
#[derive(Debug, Clone)]
pub struct Scene {
    pub mesh: Mesh,
    pub lights: Vec<PointLight>,
    pub camera: Camera,
    /// Colour of rays that leave the scene (linear RGB).
    pub background: Vec3,
    /// Ambient term added to every diffuse surface (linear RGB, times its colour).
    pub ambient: Vec3,
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            mesh: Mesh::default(),
            lights: Vec::new(),
            camera: Camera::default(),
            background: Vec3::new(0.05, 0.06, 0.09),
            ambient: Vec3::splat(0.06),
        }
    }
}

impl Scene {
    /// Appends `mesh` (transformed by `xf`) with every triangle using `material` if given, else
    /// the mesh's own materials.
    pub fn add_mesh(&mut self, mut mesh: Mesh, xf: Mat4, material: Option<Material>) {
        procedural::transform(&mut mesh, xf);
        if mesh.normals.len() != mesh.positions.len() {
            mesh.normals = vertex_normals(&mesh.positions, &mesh.triangles);
        }
        let dst = &mut self.mesh;
        let vbase = dst.positions.len() as u32;
        let mbase = dst.materials.len() as u32;
        let n_tris = mesh.triangles.len();
        match material {
            Some(m) => {
                dst.materials.push(m);
                dst.triangle_materials.extend(std::iter::repeat_n(mbase, n_tris));
            }
            None if mesh.materials.is_empty() => {
                dst.materials.push(Material::default());
                dst.triangle_materials.extend(std::iter::repeat_n(mbase, n_tris));
            }
            None => {
                dst.materials.extend(mesh.materials.iter().cloned());
                dst.triangle_materials
                    .extend((0..n_tris).map(|t| mbase + mesh.material_of(t)));
            }
        }
        dst.positions.extend(&mesh.positions);
        dst.normals.extend(&mesh.normals);
        dst.triangles
            .extend(mesh.triangles.iter().map(|t| t.map(|i| i + vbase)));
    }

    /// Bounds of all geometry.
    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(&self.mesh.positions)
    }

    /// Validates the scene and builds everything the tracers need, with the paper's grid at
    /// `resolution` (which serves `AccelKind::Grid` and `AccelKind::ProximityCloud`).
    pub fn prepare(&self, resolution: Resolution) -> Result<PreparedScene> {
        self.prepare_for(AccelKind::Grid, &resolution.into())
    }

    /// `prepare`, building the structure that serves `accel`, which reads its own keys of
    /// `params` (`AccelParams::NONE`: its defaults).
    pub fn prepare_for(&self, accel: AccelKind, params: &AccelParams) -> Result<PreparedScene> {
        self.camera.validate().map_err(Error::Scene)?;
        for (i, l) in self.lights.iter().enumerate() {
            if !(Vec3::from(l.position).is_finite() && Vec3::from(l.intensity).is_finite()) {
                return Err(Error::Scene(format!("light {i} has non-finite position or intensity")));
            }
        }
        let m = &self.mesh;
        if let Some(i) = m.positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::Scene(format!(
                "vertex {i} has a non-finite coordinate {}",
                m.positions[i]
            )));
        }
        let n_pos = m.positions.len() as u32;
        if let Some(t) = m.triangles.iter().position(|t| t.iter().any(|&i| i >= n_pos)) {
            return Err(Error::Scene(format!(
                "triangle {t} indexes a vertex out of range (vertices: {n_pos})"
            )));
        }
        let normals = if m.normals.len() == m.positions.len() && m.normals.iter().all(|n| n.is_finite()) {
            m.normals.iter().map(|n| n.normalize_or_zero()).collect()
        } else {
            vertex_normals(&m.positions, &m.triangles)
        };
        let mut tris = Vec::with_capacity(m.triangles.len());
        let mut tri_vertices = Vec::with_capacity(m.triangles.len());
        let mut tri_material = Vec::with_capacity(m.triangles.len());
        let mut dropped = 0usize;
        for (i, t) in m.triangles.iter().enumerate() {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            // Zero area (repeated vertex or collinear) is "degenerate": such a triangle can never
            // be hit by a two-sided MT test with det != 0 and only costs traversal time.
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || (b - a).cross(c - a).length_squared() == 0.0 {
                dropped += 1;
                continue;
            }
            tris.push(TriAccel::new(a, b, c));
            tri_vertices.push(*t);
            tri_material.push(m.material_of(i));
        }
        if tris.is_empty() {
            return Err(Error::Scene(format!(
                "no triangles to trace ({} in the mesh, {dropped} dropped as degenerate)",
                m.triangles.len()
            )));
        }
        let mut materials: Vec<Material> = m.materials.clone();
        if materials.is_empty() {
            materials.push(Material::default());
        }
        if let Some(&bad) = tri_material.iter().find(|&&id| id as usize >= materials.len()) {
            return Err(Error::Scene(format!(
                "material index {bad} out of range ({} materials)",
                materials.len()
            )));
        }
        let ray_epsilon = ray_epsilon(&m.positions);
        Ok(PreparedScene {
            accel: Accel::build(tris, accel, params)?,
            normals,
            tri_vertices,
            tri_material,
            materials,
            lights: self.lights.clone(),
            camera: self.camera,
            background: self.background,
            ambient: self.ambient,
            degenerate_dropped: dropped,
            ray_epsilon,
        })
    }
}

/// Everything the renderers need, built once; camera and lights may change per frame.
#[derive(Debug, Clone)]
pub struct PreparedScene {
    /// The triangles and the structure built over them.
    pub accel: Accel,
    /// Per-vertex unit normals (indexed by `tri_vertices`).
    pub normals: Vec<Vec3>,
    /// Vertex indices of each kept triangle (same order as `accel.tris`).
    pub tri_vertices: Vec<[u32; 3]>,
    pub tri_material: Vec<u32>,
    pub materials: Vec<Material>,
    pub lights: Vec<PointLight>,
    pub camera: Camera,
    pub background: Vec3,
    pub ambient: Vec3,
    /// Zero-area triangles removed from the input.
    pub degenerate_dropped: usize,
    /// Offset of secondary ray origins from the surface, in world units.
    pub ray_epsilon: f32,
}

impl PreparedScene {
    /// Bytes of every CPU-side array that tracing uses.
    pub fn memory(&self) -> Vec<(&'static str, usize)> {
        let mut v = self.accel.memory();
        v.extend([
            ("tri_vertices", std::mem::size_of_val(self.tri_vertices.as_slice())),
            ("normals", std::mem::size_of_val(self.normals.as_slice())),
            ("tri_material", std::mem::size_of_val(self.tri_material.as_slice())),
        ]);
        v
    }

    /// The paper's memory model `M = n*96 + cells*16` (bytes), for a grid.
    pub fn paper_memory_model(&self) -> Option<usize> {
        let cells = self.accel.grid()?.cells.len();
        Some(self.accel.tris.len() * 96 + cells * 16)
    }

    /// The grid this scene was prepared with. Panics for a scene prepared for another
    /// structure: for the benchmark's grid statistics and studies, which prepare their scenes
    /// with a grid themselves (everything else asks `accel.grid()` and handles `None`).
    pub fn grid(&self) -> &crate::accel::Grid {
        self.accel
            .grid()
            .expect("a grid-only code path reached a scene prepared without a grid")
    }

    /// Moves the mesh's vertices to `positions` (as many as the mesh has, in its order; the
    /// triangles and materials stay): new triangles, vertex normals (area-weighted, recomputed
    /// even where the mesh had its own) and ray offset, and the structure updated as
    /// `Accel::update` says, here or, with `RebuildOn::Device`, by the GPU renderer. A wrong
    /// length or a non-finite coordinate is an error that leaves the previous mesh in place.
    ///
    /// Triangles that the move makes degenerate stay in the list (they cannot be hit), so
    /// triangle indices keep their meaning from frame to frame.
    pub fn update_vertices(&mut self, positions: &[Vec3], on: RebuildOn) -> Result<UpdateTimes> {
        use rayon::prelude::*;
        let t0 = crate::util::Instant::now();
        let n = self.normals.len();
        if positions.len() != n {
            return Err(Error::InvalidInput(format!(
                "the vertex array has {} vertices; the mesh has {n}",
                positions.len()
            )));
        }
        if let Some(i) = positions.par_iter().position_first(|p| !p.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "vertex {i} has a non-finite coordinate {}",
                positions[i]
            )));
        }
        let tris: Vec<TriAccel> = self
            .tri_vertices
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| positions[i as usize]);
                TriAccel::new(a, b, c)
            })
            .collect();
        let normals = vertex_normals(positions, &self.tri_vertices);
        let geometry_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = crate::util::Instant::now();
        let how = if on == RebuildOn::Device && self.accel.grid().is_some() {
            self.accel.update_triangles_only(tris)?;
            "left to the GPU"
        } else {
            self.accel.update(tris)?
        };
        let structure_ms = t1.elapsed().as_secs_f64() * 1e3;
        self.normals = normals;
        self.ray_epsilon = ray_epsilon(positions);
        Ok(UpdateTimes {
            geometry_ms,
            structure_ms,
            how,
        })
    }

    /// The same scene with the structure for `accel`: switched in place where the structure
    /// serves it too (`Accel::set_traversal`: the grid's `grid` and `pc`), else rebuilt with
    /// `params`.
    pub fn with_accel(&self, accel: AccelKind, params: &AccelParams) -> Result<PreparedScene> {
        if accel.structure() == self.accel.structure_id() {
            return Ok(PreparedScene {
                accel: self.accel.clone().with_traversal(accel)?,
                ..self.clone()
            });
        }
        Ok(PreparedScene {
            accel: Accel::build(self.accel.tris.clone(), accel, params)?,
            ..self.clone()
        })
    }
}

/// Secondary rays start this far off the surface (along the geometric normal, towards the side
/// they leave on). It scales with the scene size, and with the magnitude of the coordinates,
/// because f32 hit points far from the origin carry larger absolute error.
fn ray_epsilon(positions: &[Vec3]) -> f32 {
    let bounds = Aabb::from_points(positions);
    let max_coord = bounds.min.abs().max(bounds.max.abs()).max_element();
    (bounds.diagonal() * 1e-4).max(max_coord * 4e-6).max(f32::MIN_POSITIVE)
}

/// Where a moved mesh's structure is rebuilt (`PreparedScene::update_vertices`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RebuildOn {
    /// Rebuilt or refitted on the CPU, ready for either backend (the GPU uploads it).
    Cpu,
    /// Left to the GPU renderer that traces the scene (`GpuRenderer::update_vertices`), where
    /// it has a GPU build (the uniform grid); every other structure is updated on the CPU.
    Device,
}

/// What an update did, and its times.
#[derive(Debug, Clone, Default)]
pub struct UpdateTimes {
    /// New triangles, normals and checks.
    pub geometry_ms: f64,
    /// The structure's rebuild or refit on the CPU (0 when left to the GPU).
    pub structure_ms: f64,
    /// "rebuilt", "refitted" or "left to the GPU".
    pub how: &'static str,
}

/// Area-weighted vertex normals: the unnormalised face normal `(b-a) x (c-a)` has length twice
/// the area, so summing it weights each face by its area.
pub fn vertex_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::ZERO));
        let f = (b - a).cross(c - a);
        for &i in t {
            if let Some(v) = n.get_mut(i as usize) {
                *v += f;
            }
        }
    }
    n.iter().map(|v| v.normalize_or_zero()).collect()
}
