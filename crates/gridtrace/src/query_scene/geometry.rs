//! One geometry of a `QueryScene`: an instance of a mesh. The mesh (triangles in its own space,
//! and its structure, built once: the bottom level) may be shared by many instances; each
//! instance has its own 4x4 affine transform to world space (its inverse kept, to carry rays
//! into the mesh's space), a 32-bit mask, and the checks that name what is wrong with bad input.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use glam::{Affine3A, Mat3, Mat4, Vec3, Vec4};

use super::enclosure::Enclosure;
use crate::accel::winding::FastWinding;
use crate::accel::{Aabb, Ray, Structure};
use crate::query::{Backend, QueryOptions, TraceMesh};
use crate::{Error, Result};

/// A mesh as it was given (vertices in its own space, faces indexing them), shared by the
/// instances that place it (`Arc`), with its structure built on first use.
pub struct SceneMesh {
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// The vertices' box in the mesh's own space.
    bounds: Aabb,
    /// A few points whose hull holds every vertex (`enclosure.rs`), found on first use: the
    /// instances' world boxes.
    enclosure: OnceLock<Enclosure>,
    /// The bottom level: the structure over the mesh's own-space triangles, on the CPU
    /// (`None`: no face with non-zero area, so nothing to hit). Built once, whatever moves.
    bottom: OnceLock<Option<TraceMesh>>,
    /// The fast winding tree over the bottom level's triangles, built on first use by the
    /// two levels' winding numbers (`two_level_points.rs`). Built once, whatever moves.
    winding: OnceLock<FastWinding>,
}

impl std::fmt::Debug for SceneMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneMesh")
            .field("vertices", &self.vertices.len())
            .field("faces", &self.faces.len())
            .field("built", &self.bottom.get().is_some())
            .finish()
    }
}

impl SceneMesh {
    /// Checks and keeps a mesh: finite vertices, faces in range. Errors name the argument and
    /// the place.
    pub fn new(vertices: Vec<[f32; 3]>, faces: Vec<[u32; 3]>) -> Result<SceneMesh> {
        check_vertices(&vertices, "vertices")?;
        let n = vertices.len() as u64;
        if let Some(i) = faces.iter().position(|f| f.iter().any(|&k| k as u64 >= n)) {
            return Err(Error::InvalidInput(format!(
                "faces[{i}] = {:?} indexes a vertex out of range ({n} vertices)",
                faces[i]
            )));
        }
        let bounds = vertices.iter().fold(Aabb::EMPTY, |b, &v| b.grow(Vec3::from(v)));
        Ok(SceneMesh {
            vertices,
            faces,
            bounds,
            enclosure: OnceLock::new(),
            bottom: OnceLock::new(),
            winding: OnceLock::new(),
        })
    }

    /// The points whose hull holds every vertex (`enclosure::dop_corners`), found now if not
    /// yet.
    fn enclosure(&self) -> &Enclosure {
        self.enclosure
            .get_or_init(|| Enclosure::new(&super::enclosure::dop_corners(&self.vertices, self.bounds)))
    }

    /// The bottom level, built now (counted in `builds`) if it is not yet. Its structure is the
    /// scene's (`opts.accel`), built on the CPU whatever the scene's backend: the CPU's two
    /// levels walk it, and the GPU's upload it as it is (`gpu_rays.rs`).
    pub(crate) fn bottom(&self, opts: &QueryOptions, builds: &AtomicUsize) -> Result<Option<&TraceMesh>> {
        if let Some(b) = self.bottom.get() {
            return Ok(b.as_ref());
        }
        let own = &self.vertices;
        let built = if self.faces.iter().all(|&f| is_degenerate(own, f)) {
            None
        } else {
            let cpu = QueryOptions {
                backend: Backend::Cpu,
                ..opts.clone()
            };
            builds.fetch_add(1, Ordering::Relaxed);
            Some(TraceMesh::from_arrays(own, &self.faces, &cpu)?)
        };
        // Queries that build take the scene's two-level lock (`QueryScene::two_level`), so no
        // other build of this mesh raced this one; `set` failing would only drop a copy.
        let _ = self.bottom.set(built);
        Ok(self.bottom.get().and_then(|b| b.as_ref()))
    }

    /// The bottom level if it was built.
    pub(crate) fn built(&self) -> Option<&TraceMesh> {
        self.bottom.get().and_then(|b| b.as_ref())
    }

    /// The fast winding tree over the bottom level's triangles (the bottom level's order:
    /// `Accel::tris`), built now if it is not yet: over the bottom level's BVH where it is
    /// one, else a tree of its own (as the merged mesh's, `Merged::winding`). `None` where the
    /// bottom level is not built or has no triangle.
    pub(crate) fn winding(&self) -> Option<&FastWinding> {
        let accel = &self.built()?.prepared().accel;
        Some(self.winding.get_or_init(|| match &accel.structure {
            Structure::Bvh(b) => FastWinding::from_bvh(&b.bvh, &accel.tris),
            _ => FastWinding::build(&accel.tris),
        }))
    }

    /// Bytes held: the arrays as given and, once built, the structure and its triangles.
    pub fn memory_bytes(&self) -> usize {
        let given = std::mem::size_of_val(self.vertices.as_slice()) + std::mem::size_of_val(self.faces.as_slice());
        let built = self.built().map_or(0, |m| {
            let p = m.prepared();
            p.accel.memory().iter().map(|(_, b)| b).sum::<usize>()
        });
        given + built
    }
}

/// A geometry: an instance of a mesh, placed by an affine transform, seen by rays whose mask
/// shares a bit with its own.
#[derive(Debug, Clone)]
pub struct Geometry {
    mesh: Arc<SceneMesh>,
    /// Own space to world space (affine, invertible: checked).
    transform: Mat4,
    mask: u32,
    /// The transform's uniform scale where it is a similarity (`similarity_scale`), found when
    /// the transform is set: the point queries walk the two levels only where every instance
    /// has one (`two_level_points.rs`).
    scale: Option<f32>,
}

impl Geometry {
    /// Checks and keeps a geometry: finite vertices, faces in range, a finite affine
    /// invertible transform whose world-space vertices are finite too. Errors name the
    /// argument and the place.
    pub fn new(vertices: Vec<[f32; 3]>, faces: Vec<[u32; 3]>, transform: Option<Mat4>) -> Result<Geometry> {
        let mesh = Arc::new(SceneMesh::new(vertices, faces)?);
        Geometry::place(mesh, transform.unwrap_or(Mat4::IDENTITY), u32::MAX, "transform")
    }

    /// `mesh` placed by `transform` with `mask`; `what` names the transform in errors (the
    /// instance it is for).
    pub fn place(mesh: Arc<SceneMesh>, transform: Mat4, mask: u32, what: &str) -> Result<Geometry> {
        Geometry::place_named(mesh, transform, mask, &|| what.to_string())
    }

    /// `place`, with the transform's name made only for an error (a move of a thousand
    /// instances names none).
    fn place_named(mesh: Arc<SceneMesh>, transform: Mat4, mask: u32, what: &dyn Fn() -> String) -> Result<Geometry> {
        check_transform(&transform, &mesh.bounds, what)?;
        Ok(Geometry {
            mesh,
            transform,
            mask,
            scale: similarity_scale(&transform),
        })
    }

    /// The same mesh placed by `transform` instead (checked as `place` checks it; `what` names
    /// it in errors).
    pub fn moved(&self, transform: Mat4, what: &dyn Fn() -> String) -> Result<Geometry> {
        Geometry::place_named(self.mesh.clone(), transform, self.mask, what)
    }

    pub fn mesh(&self) -> &Arc<SceneMesh> {
        &self.mesh
    }

    pub fn vertices(&self) -> &[[f32; 3]] {
        &self.mesh.vertices
    }

    pub fn faces(&self) -> &[[u32; 3]] {
        &self.mesh.faces
    }

    /// Own space to world space.
    pub fn transform(&self) -> Mat4 {
        self.transform
    }

    pub fn mask(&self) -> u32 {
        self.mask
    }

    /// The transform's uniform scale `s` where it is a similarity (rotation, reflection,
    /// uniform scale and translation: own-space distances times `s` are world distances), else
    /// `None` (`similarity_scale`).
    pub fn similarity(&self) -> Option<f32> {
        self.scale
    }

    pub(crate) fn set_mask(&mut self, mask: u32) {
        self.mask = mask;
    }

    /// World to own space: the transform's inverse (the two levels keep it with each
    /// instance, `two_level.rs`; computed here the same way, so the same bits).
    pub fn to_local(&self) -> Affine3A {
        Affine3A::from_mat4(self.transform).inverse()
    }

    /// A world-space ray in the mesh's own space: origin and direction through the inverse,
    /// the direction not normalised, so that a point at `t` along one is the point at the same
    /// `t` along the other (hits keep their `t`, and intervals mean the same in both spaces).
    #[inline]
    pub fn ray_to_local(&self, ray: &Ray) -> Ray {
        carry(&self.to_local(), ray)
    }

    /// The world-space box of the mesh: the box of its enclosure's points through the
    /// transform (`enclosure.rs`), the exact box of the transformed vertices within a few
    /// percent a side, where the own box's corners turned can be half as large again.
    pub fn world_bounds(&self) -> Aabb {
        self.mesh.enclosure().world_box(&self.transform)
    }

    /// The vertices in world space.
    pub fn world_vertices(&self) -> Vec<[f32; 3]> {
        if self.transform == Mat4::IDENTITY {
            return self.mesh.vertices.clone();
        }
        self.mesh
            .vertices
            .iter()
            .map(|&v| self.transform.transform_point3(Vec3::from(v)).to_array())
            .collect()
    }

    /// Replaces the vertices (as many as before; the faces stay), checked as `new` checks
    /// them. The geometry gets a mesh of its own (other instances of its mesh stay as they
    /// were). On an error nothing changes.
    pub fn set_vertices(&mut self, vertices: Vec<[f32; 3]>) -> Result<()> {
        if vertices.len() != self.mesh.vertices.len() {
            return Err(Error::InvalidInput(format!(
                "vertices has {} rows; the geometry has {} vertices (faces stay, so the count must too)",
                vertices.len(),
                self.mesh.vertices.len()
            )));
        }
        let mesh = Arc::new(SceneMesh::new(vertices, self.mesh.faces.clone())?);
        *self = Geometry::place(mesh, self.transform, self.mask, "transform")?;
        Ok(())
    }
}

/// `ray` through `to_local` (see `Geometry::ray_to_local`).
#[inline(always)]
pub(crate) fn carry(to_local: &Affine3A, ray: &Ray) -> Ray {
    // The interval and the mask stay: the direction is carried without normalising, so a
    // point at `t` in world space is the point at the same `t` in the instance's.
    Ray {
        origin: to_local.transform_point3(ray.origin),
        dir: to_local.transform_vector3(ray.dir),
        ..*ray
    }
}

/// The matrix that takes an own-space geometric normal `(v1 - v0) x (v2 - v0)` to the world
/// space one of the transformed face: the cofactor matrix `det(A) A^-T` of the linear part
/// `A`. The inverse-transpose alone would flip the normal of a mirroring transform
/// (`det < 0`), where the world face's winding, and so its normal, flips with it.
pub(crate) fn normal_to_world(to_local: &Affine3A) -> Mat3 {
    let inv = Mat3::from(to_local.matrix3);
    // det(A^-1) = 1 / det(A): the sign is what matters, the length is normalised after.
    inv.transpose() * inv.determinant().signum()
}

/// Relative tolerance of `similarity_scale`: how far `A^T A` of the linear part `A` may be from
/// `s^2 I`, in units of `s^2`. A rotation made in `f32` (a quaternion turned into a matrix) is
/// orthogonal to a few ulps; 1e-5 takes that and refuses any scale uneven by more than about
/// 5e-6.
pub(crate) const SIMILARITY_TOLERANCE: f64 = 1e-5;

/// The uniform scale `s` of an affine `transform` that is a similarity (`A^T A = s^2 I` within
/// `SIMILARITY_TOLERANCE`, `A` its linear part: rotations, reflections, uniform scales, and any
/// translation), else `None`. Under a similarity the nearest point of a mesh in its own space
/// is, carried to world space, the nearest point of the placed mesh, at `s` times the distance.
pub(crate) fn similarity_scale(transform: &Mat4) -> Option<f32> {
    let a = glam::DMat3::from_mat4(transform.as_dmat4());
    let ata = a.transpose() * a;
    let s2 = (ata.x_axis.x + ata.y_axis.y + ata.z_axis.z) / 3.0;
    if !(s2 > 0.0 && s2.is_finite()) {
        return None;
    }
    let cols = [ata.x_axis, ata.y_axis, ata.z_axis];
    let off = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| (cols[i][j] - if i == j { s2 } else { 0.0 }).abs())
        .fold(0.0, f64::max);
    (off <= SIMILARITY_TOLERANCE * s2).then(|| s2.sqrt() as f32)
}

/// Whether `transform` is finite, affine and invertible, with an inverse that is finite, and
/// keeps `bounds` finite; an error naming `what` otherwise.
fn check_transform(transform: &Mat4, bounds: &Aabb, what: &dyn Fn() -> String) -> Result<()> {
    if !transform.is_finite() {
        return Err(Error::InvalidInput(format!(
            "{} has a non-finite entry: {transform}",
            what()
        )));
    }
    if transform.row(3) != Vec4::W {
        return Err(Error::InvalidInput(format!(
            "{} is not affine: its last row is {} (want 0 0 0 1)",
            what(),
            transform.row(3)
        )));
    }
    // A large transform can overflow a finite vertex to infinity (every vertex lies in the
    // box, so finite corners keep every vertex finite).
    if !bounds.is_empty() {
        let b = super::enclosure::box_corners(bounds)
            .into_iter()
            .fold(Aabb::EMPTY, |b, c| b.grow(transform.transform_point3(c)));
        if !(b.min.is_finite() && b.max.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "vertices after the {} are not finite (box {:?} .. {:?})",
                what(),
                b.min,
                b.max
            )));
        }
    }
    let affine = Affine3A::from_mat4(*transform);
    let det = affine.matrix3.determinant();
    let inverse = affine.inverse();
    if det == 0.0 || !det.is_finite() || !inverse.is_finite() {
        return Err(Error::InvalidInput(format!(
            "{} cannot be inverted (determinant {det}): {transform}",
            what()
        )));
    }
    Ok(())
}

pub(crate) fn check_vertices(vertices: &[[f32; 3]], what: &str) -> Result<()> {
    match vertices.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
        Some(i) => Err(Error::InvalidInput(format!(
            "{what}[{i}] = {:?} is not finite",
            vertices[i]
        ))),
        None => Ok(()),
    }
}

/// Whether a face has zero area: the faces the ray queries drop (`TraceMesh`).
pub(crate) fn is_degenerate(world: &[[f32; 3]], f: [u32; 3]) -> bool {
    let [a, b, c] = f.map(|k| Vec3::from(world[k as usize]));
    // The complement of `TraceMesh::from_mesh`'s test (`> 0.0`), NaN (an overflowing cross
    // product) included.
    let area2 = (b - a).cross(c - a).length_squared();
    area2.is_nan() || area2 <= 0.0
}
