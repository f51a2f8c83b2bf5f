//! Triangle meshes as loaded from files or generated: plain arrays, no acceleration data. Below
//! both `io` (which fills them) and `scene` (which composes and prepares them).

use glam::Vec3;

/// Surface appearance. Diffuse colour is linear RGB; `reflectivity` in 0..=1 blends a perfect
/// mirror reflection over the diffuse colour.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    pub diffuse: Vec3,
    pub reflectivity: f32,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            diffuse: Vec3::splat(0.75),
            reflectivity: 0.0,
        }
    }
}

/// An indexed triangle mesh.
///
/// * `normals` is either empty (compute them) or has one entry per position.
/// * `triangle_materials` is either empty (every triangle uses material 0) or has one entry per
///   triangle, indexing `materials`.
/// * `materials` may be empty; users of the mesh then use `Material::default()`.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub triangle_materials: Vec<u32>,
    pub materials: Vec<Material>,
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The box of the positions: `(min, max)` corners (infinite, inverted, for no positions).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions
            .iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), &p| (l.min(p), h.max(p)))
    }

    pub fn material_of(&self, tri: usize) -> u32 {
        self.triangle_materials.get(tri).copied().unwrap_or(0)
    }
}
