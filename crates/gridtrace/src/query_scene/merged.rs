//! The scene's geometries merged into one world-space `TraceMesh`, and the table that names a
//! merged triangle by its geometry and its face there.
//!
//! The merged mesh is the geometries' world-space vertices and faces one after another, in
//! ascending geometry id. `TraceMesh` drops zero-area faces (they can never be hit) and numbers
//! the kept ones densely; `original_index` gives a kept triangle's merged face back, and the
//! prefix table here splits a merged face into (geometry id, face index in that geometry).

use std::collections::BTreeMap;
use std::sync::{Arc, OnceLock};

use crate::accel::winding::FastWinding;
use crate::accel::{Accel, Structure, TriAccel};
use crate::placement::QueryPlacement;
use crate::query::{QueryOptions, TraceMesh};
use crate::{Error, Result};

use super::geometry::{Geometry, is_degenerate};

/// What one geometry occupies in the merged arrays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Span {
    pub id: u32,
    pub first_vertex: usize,
    pub vertices: usize,
    pub first_face: u32,
    pub faces: u32,
}

/// The merged mesh a scene's queries run on.
pub(crate) struct Merged {
    /// `None` when no geometry has a face with non-zero area: every ray misses, every point is
    /// infinitely far.
    pub mesh: Option<TraceMesh>,
    /// One span per geometry, in ascending id (so ascending `first_face`).
    pub spans: Vec<Span>,
    /// All world-space vertices, as handed to the mesh (`update_vertices` rewrites a span).
    pub world: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// Whether each merged face was dropped as zero-area when the mesh was built.
    pub degenerate: Vec<bool>,
    /// The fast winding-number tree over the mesh's triangles, built by the first query that
    /// needs it (signed distance, occupancy).
    pub winding: OnceLock<FastWinding>,
}

impl Merged {
    /// Merges `geometries` (ascending id) and builds the mesh, its GPU work placed by
    /// `placement` (the scene's).
    pub fn build(
        geometries: &BTreeMap<u32, Geometry>,
        opts: &QueryOptions,
        placement: Arc<QueryPlacement>,
    ) -> Result<Merged> {
        let mut spans = Vec::with_capacity(geometries.len());
        let mut world = Vec::new();
        let mut faces = Vec::new();
        for (&id, g) in geometries {
            let first_vertex = world.len();
            let base = u32::try_from(first_vertex)
                .map_err(|_| Error::InvalidInput(format!("the scene has more than {} vertices", u32::MAX)))?;
            world.extend(g.world_vertices());
            faces.extend(g.faces().iter().map(|f| f.map(|k| k + base)));
            let first_face = u32::try_from(faces.len() - g.faces().len())
                .map_err(|_| Error::InvalidInput(format!("the scene has more than {} faces", u32::MAX)))?;
            spans.push(Span {
                id,
                first_vertex,
                vertices: g.vertices().len(),
                first_face,
                faces: g.faces().len() as u32,
            });
        }
        let degenerate: Vec<bool> = faces.iter().map(|&f| is_degenerate(&world, f)).collect();
        let mesh = if degenerate.iter().all(|&d| d) {
            None
        } else {
            Some(TraceMesh::from_arrays_on(&world, &faces, opts, Some(placement))?)
        };
        Ok(Merged {
            mesh,
            spans,
            world,
            faces,
            degenerate,
            winding: OnceLock::new(),
        })
    }

    /// Moves geometry `id`'s world-space vertices in place (`world` as many as it has) and
    /// updates the mesh's structure. Returns false, changing nothing, when that cannot give
    /// what a rebuild would: the set of zero-area faces changes (the mesh drops them at build
    /// time), or the structure the CPU queries read would be left stale (a grid rebuilt on
    /// the GPU). The caller then rebuilds.
    pub fn update(&mut self, id: u32, world: &[[f32; 3]]) -> Result<bool> {
        let Some(span) = self.spans.iter().find(|s| s.id == id).copied() else {
            return Ok(false);
        };
        let Some(mesh) = self.mesh.as_mut() else {
            return Ok(false);
        };
        let mut moved = self.world.clone();
        moved[span.first_vertex..span.first_vertex + span.vertices].copy_from_slice(world);
        let faces = span.first_face as usize..(span.first_face + span.faces) as usize;
        if faces
            .clone()
            .any(|f| is_degenerate(&moved, self.faces[f]) != self.degenerate[f])
        {
            return Ok(false);
        }
        mesh.update_vertices(&moved)?;
        if mesh.prepared().accel.check_current().is_err() {
            return Ok(false);
        }
        self.world = moved;
        self.winding = OnceLock::new();
        Ok(true)
    }

    /// Bytes held: the world-space arrays and the mesh's structure with its triangles.
    pub fn memory_bytes(&self) -> usize {
        let arrays = std::mem::size_of_val(self.world.as_slice())
            + std::mem::size_of_val(self.faces.as_slice())
            + self.degenerate.len()
            + std::mem::size_of_val(self.spans.as_slice());
        arrays
            + self
                .accel()
                .map_or(0, |a| a.memory().iter().map(|(_, b)| b).sum::<usize>())
    }

    /// The structure the CPU queries walk, when there is one.
    pub fn accel(&self) -> Option<&Accel> {
        self.mesh.as_ref().map(|m| &m.prepared().accel)
    }

    /// The triangles of the mesh (kept faces, world space); empty without a mesh.
    pub fn tris(&self) -> &[TriAccel] {
        self.accel().map_or(&[], |a| a.tris.as_slice())
    }

    /// The winding-number tree, built on first use: over the ray BVH's binary tree where the
    /// structure is a BVH (its SAH build is most of a tree's cost: 871,414 Dragon triangles,
    /// docs/benchmarks.md), else a tree of its own.
    pub fn winding(&self) -> &FastWinding {
        self.winding.get_or_init(|| match self.accel().map(|a| &a.structure) {
            Some(Structure::Bvh(b)) => FastWinding::from_bvh(&b.bvh, self.tris()),
            _ => FastWinding::build(self.tris()),
        })
    }

    /// (geometry id, face index in it) of a kept triangle of the mesh.
    #[inline]
    pub fn name(&self, kept: u32) -> (u32, u32) {
        let merged = self.mesh.as_ref().map_or(kept, |m| m.original_index(kept));
        // The last span starting at or before the face: spans are in ascending `first_face`,
        // and a geometry with no faces shares its start with the next one (which comes after
        // it, so is the one found).
        let s = self.spans[self.spans.partition_point(|s| s.first_face <= merged) - 1];
        debug_assert!(merged < s.first_face + s.faces);
        (s.id, merged - s.first_face)
    }
}
