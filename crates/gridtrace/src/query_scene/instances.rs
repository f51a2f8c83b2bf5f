//! Placing meshes many times and moving them: `add_instance`, `set_transform(s)`, `set_mask`,
//! and what the scene holds (`memory_bytes`). A move checks every matrix before it changes
//! anything, then rebuilds the two levels' top (if they were built) and leaves the merged mesh
//! stale for the queries that use it; no mesh structure is built.

use std::sync::Arc;

use glam::Mat4;

use super::geometry::{Geometry, SceneMesh};
use super::two_level::TwoLevel;
use super::{QueryScene, unknown};
use crate::{Error, Result};

/// The mesh an instance places: one already in the scene (shared with the geometry of that id)
/// or a new one.
#[derive(Debug, Clone)]
pub enum InstanceOf {
    /// The mesh of the geometry with this id.
    Geometry(u32),
    /// A mesh not in the scene yet (`SceneMesh::new`), or one shared with another scene.
    Mesh(Arc<SceneMesh>),
}

impl QueryScene {
    /// Places a mesh once more, by `transform` (identity when `None`) with `mask`; returns the
    /// new geometry's id. Instances of one mesh share its triangles and its structure. An
    /// unknown geometry id, or a transform that is not finite, affine and invertible, is an
    /// error naming it, and adds nothing.
    pub fn add_instance(&mut self, of: InstanceOf, transform: Option<Mat4>, mask: u32) -> Result<u32> {
        let mesh = match of {
            InstanceOf::Geometry(id) => self.geometries.get(&id).ok_or_else(|| unknown(id))?.mesh().clone(),
            InstanceOf::Mesh(m) => m,
        };
        let what = format!("transform of the new instance (geometry {})", self.next_id);
        let g = Geometry::place(mesh, transform.unwrap_or(Mat4::IDENTITY), mask, &what)?;
        self.moving = true;
        self.push(g)
    }

    /// Places one mesh (`vertices`, `faces`) once per transform, all masks full: the mesh added
    /// by the first (`add_triangles`), the others instances of it. Returns the geometry ids in
    /// the transforms' order (`set_transforms` takes them). An error adds what came before it.
    pub fn add_placed(
        &mut self,
        vertices: Vec<[f32; 3]>,
        faces: Vec<[u32; 3]>,
        transforms: &[Mat4],
    ) -> Result<Vec<u32>> {
        let Some((head, rest)) = transforms.split_first() else {
            return Ok(Vec::new());
        };
        let first = self.add_triangles(vertices, faces, Some(*head))?;
        let mut ids = Vec::with_capacity(transforms.len());
        ids.push(first);
        for t in rest {
            ids.push(self.add_instance(InstanceOf::Geometry(first), Some(*t), u32::MAX)?);
        }
        Ok(ids)
    }

    /// Moves geometry `id` (`set_transforms` with one).
    pub fn set_transform(&mut self, id: u32, transform: Mat4) -> Result<()> {
        self.set_transforms(&[id], &[transform])
    }

    /// Moves geometries `ids[k]` to `transforms[k]`, all or none: an unknown id, or a transform
    /// that is not finite, affine and invertible, is an error naming the geometry, and changes
    /// nothing. The two levels' top is rebuilt (the meshes' structures stay; on the GPU the
    /// next ray query uploads the top level alone); the merged mesh (point queries, the GPU
    /// rays of structures the GPU walks merged) is rebuilt by the next query that uses it.
    pub fn set_transforms(&mut self, ids: &[u32], transforms: &[Mat4]) -> Result<()> {
        if ids.len() != transforms.len() {
            return Err(Error::InvalidInput(format!(
                "{} ids and {} transforms: need one transform per id",
                ids.len(),
                transforms.len()
            )));
        }
        let mut moved = Vec::with_capacity(ids.len());
        for (&id, &m) in ids.iter().zip(transforms) {
            let g = self.geometries.get(&id).ok_or_else(|| unknown(id))?;
            moved.push(g.moved(m, &|| format!("transform of geometry {id}"))?);
        }
        for (&id, g) in ids.iter().zip(moved) {
            self.geometries.insert(id, g);
        }
        self.after_move()
    }

    /// Sets geometry `id`'s mask: rays whose mask shares no bit with it pass it by. An
    /// unknown id is an error naming it.
    pub fn set_mask(&mut self, id: u32, mask: u32) -> Result<()> {
        self.geometries.get_mut(&id).ok_or_else(|| unknown(id))?.set_mask(mask);
        self.after_move()
    }

    /// After a move or a mask: the merged mesh stale, the two levels' top rebuilt now if they
    /// were built (every bottom level is, so this builds none), so that the cost of a move is
    /// paid, and measured, here.
    fn after_move(&mut self) -> Result<()> {
        self.moving = true;
        *self.merged.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
        *self.winding_only.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
        let slot = self.two_level.get_mut().unwrap_or_else(|p| p.into_inner());
        if slot.is_some() {
            *slot = Some(Arc::new(TwoLevel::build(&self.geometries, &self.opts, &self.builds)?));
        }
        Ok(())
    }

    /// Bytes the scene holds: each mesh once (its arrays, and its structure once built), the
    /// geometries' records, the two levels' records and top, and the merged mesh when a query
    /// built one (its vertices, faces and structure).
    pub fn memory_bytes(&self) -> usize {
        let (meshes, _) = self.parts();
        let meshes: usize = meshes.iter().map(|m| m.memory_bytes()).sum();
        // A B-tree entry is its key and value; the nodes' own overhead is about a tenth more
        // (11 entries a node), counted as such.
        let records = self.geometries.len() * std::mem::size_of::<(u32, Geometry)>() * 11 / 10;
        let two = self
            .two_level
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
            .map_or(0, |t| t.records_bytes());
        let merged = self
            .merged
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
            .map_or(0, |m| m.memory_bytes());
        meshes + records + two + merged
    }
}
