//! One geometry of a `QueryScene`: its triangles in its own space, the 4x4 transform that
//! places them in the world, and the checks that name what is wrong with bad input.

use glam::{Mat4, Vec3};

use crate::{Error, Result};

/// A geometry as it was given: vertices in its own space, faces (indices into them) and the
/// transform to world space.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    pub transform: Mat4,
}

impl Geometry {
    /// Checks and keeps a geometry: finite vertices, faces in range, a finite transform whose
    /// world-space vertices are finite too. Errors name the argument and the place.
    pub fn new(vertices: Vec<[f32; 3]>, faces: Vec<[u32; 3]>, transform: Option<Mat4>) -> Result<Geometry> {
        let transform = transform.unwrap_or(Mat4::IDENTITY);
        if !transform.is_finite() {
            return Err(Error::InvalidInput(format!(
                "transform has a non-finite entry: {transform}"
            )));
        }
        check_vertices(&vertices, "vertices")?;
        let n = vertices.len() as u64;
        if let Some(i) = faces.iter().position(|f| f.iter().any(|&k| k as u64 >= n)) {
            return Err(Error::InvalidInput(format!(
                "faces[{i}] = {:?} indexes a vertex out of range ({n} vertices)",
                faces[i]
            )));
        }
        let g = Geometry {
            vertices,
            faces,
            transform,
        };
        // A large transform can overflow a finite vertex to infinity.
        check_vertices(&g.world_vertices(), "vertices after the transform")?;
        Ok(g)
    }

    /// The vertices in world space.
    pub fn world_vertices(&self) -> Vec<[f32; 3]> {
        if self.transform == Mat4::IDENTITY {
            return self.vertices.clone();
        }
        self.vertices
            .iter()
            .map(|&v| self.transform.transform_point3(Vec3::from(v)).to_array())
            .collect()
    }

    /// Replaces the vertices (as many as before; the faces stay), checked as `new` checks
    /// them. On an error nothing changes.
    pub fn set_vertices(&mut self, vertices: Vec<[f32; 3]>) -> Result<()> {
        if vertices.len() != self.vertices.len() {
            return Err(Error::InvalidInput(format!(
                "vertices has {} rows; the geometry has {} vertices (faces stay, so the count must too)",
                vertices.len(),
                self.vertices.len()
            )));
        }
        check_vertices(&vertices, "vertices")?;
        let old = std::mem::replace(&mut self.vertices, vertices);
        if let Err(e) = check_vertices(&self.world_vertices(), "vertices after the transform") {
            self.vertices = old;
            return Err(e);
        }
        Ok(())
    }
}

fn check_vertices(vertices: &[[f32; 3]], what: &str) -> Result<()> {
    match vertices.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
        Some(i) => Err(Error::InvalidInput(format!(
            "{what}[{i}] = {:?} is not finite",
            vertices[i]
        ))),
        None => Ok(()),
    }
}

/// Whether a world-space face has zero area: the faces the ray queries drop (`TraceMesh`).
pub(crate) fn is_degenerate(world: &[[f32; 3]], f: [u32; 3]) -> bool {
    let [a, b, c] = f.map(|k| Vec3::from(world[k as usize]));
    // The complement of `TraceMesh::from_mesh`'s test (`> 0.0`), NaN (an overflowing cross
    // product) included.
    let area2 = (b - a).cross(c - a).length_squared();
    area2.is_nan() || area2 <= 0.0
}
