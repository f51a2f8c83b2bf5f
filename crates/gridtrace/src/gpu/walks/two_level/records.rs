//! What the two levels' upload hands between its parts, apart from the walks that make and
//! read it (here, so that `hwrt`'s driver instances, which lay the same records out for the
//! driver, take them without reaching into `two_level/mod.rs`, which names `hwrt`'s walk): the
//! top level's array and its records, the meshes' bottom levels, and an instance as the top
//! level takes it.

use bytemuck::{Pod, Zeroable};
use glam::Affine3A;

use super::super::WalkSpec;
use super::super::bvh::binary::{self, GpuBvhNode};
use crate::accel::AccelKind;
use crate::accel::bvh::Bvh;
use crate::gpu::layout::GpuTri;
use crate::{Error, Result};

/// The top level's array (the last of a two-level walk's arrays): its report name and its WGSL
/// variable.
pub const TOP_LEVEL_ARRAY: (&str, &str) = ("top level", "top_level");

/// Entries of the top-level walk's stack: above any top level's depth (a median split over
/// `n` instances is `log2(n) + 1` deep; checked at upload).
pub const TOP_STACK: u32 = 32;

/// A record of the top level's array, 64 bytes: a node (`GpuBvhNode`'s bytes) or an instance
/// (see top_level.wgsl): the world-to-mesh transform's columns (`a`, `b`, `c`: xyz, the
/// translation in the w's), then its mask, its mesh's header (first, count) and its first
/// triangle's number in the answers.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TopRec {
    pub a: [f32; 4],
    pub b: [f32; 4],
    pub c: [f32; 4],
    pub w: [u32; 4],
}

const _: () = assert!(size_of::<TopRec>() == size_of::<GpuBvhNode>());

/// Every mesh's structure as the bottom walk reads it, each mesh's part after the previous
/// one's, and each mesh's header.
pub struct BottomLevels {
    pub spec: &'static WalkSpec,
    /// The meshes' structure.
    pub kind: AccelKind,
    /// The bottom walk's own arrays (`spec.arrays` but the top level's), bytes.
    pub arrays: Vec<Vec<u8>>,
    /// The triangles group 0 binds (`tris`): every mesh's, one after another, where the
    /// bottom walk reads them there (brute force); else one zero triangle (a binding holds at
    /// least one element).
    pub tris: Vec<GpuTri>,
    /// Each mesh's `MeshHeader` (first, count).
    pub headers: Vec<[u32; 2]>,
    /// Each mesh's triangles (the answers number them from each instance's first).
    pub tri_counts: Vec<u32>,
}

impl BottomLevels {
    /// Bytes of the meshes' arrays (the bottom walk's and the triangles).
    pub fn bytes(&self) -> u64 {
        let own: usize = self.arrays.iter().map(Vec::len).sum();
        (own + size_of_val(self.tris.as_slice())) as u64
    }
}

/// One instance as the top level takes it.
#[derive(Debug, Clone, Copy)]
pub struct Instance {
    /// World to the mesh's own space (the transform's inverse, kept).
    pub to_local: Affine3A,
    pub mask: u32,
    /// Index into the meshes of `bottom_levels`.
    pub mesh: u32,
}

/// The top level's array and how to read the answers back.
pub struct TopLevel {
    /// The nodes, then the instances' records in the tree's leaf order.
    pub recs: Vec<TopRec>,
    /// Nodes at the front of `recs`.
    pub nodes: usize,
    /// Each record's instance (index into the instances given), in record order.
    pub order: Vec<u32>,
    /// Each record's first triangle in the answers' numbering, ascending, in record order.
    pub first_answer: Vec<u32>,
    /// Triangles numbered: every instance's.
    pub answers: u32,
}

impl TopLevel {
    /// Lays out the top level: `tree`, a BVH over the instances' world boxes (its `prims` the
    /// instances' indices), its nodes first, then the records in its leaf order, each leaf's
    /// entry naming its records' place in the array.
    pub fn new(tree: &Bvh, instances: &[Instance], bottoms: &BottomLevels) -> Result<TopLevel> {
        if tree.depth >= TOP_STACK as usize {
            return Err(Error::InvalidInput(format!(
                "the top level is {} levels deep; the GPU walk's stack holds {TOP_STACK}",
                tree.depth
            )));
        }
        let mut nodes = binary::gpu_nodes(tree)?;
        let n = u32::try_from(nodes.len()).map_err(|_| Error::InvalidInput("too many instances".into()))?;
        binary::offset_entries(&mut nodes, 0, n)?;
        let mut recs: Vec<TopRec> = nodes.iter().map(|&node| bytemuck::cast(node)).collect();
        let (first_answer, answers) = number_answers(tree.prims.iter().map(|&i| instances[i as usize].mesh), bottoms)?;
        for (&i, &first_answer) in tree.prims.iter().zip(&first_answer) {
            let inst = &instances[i as usize];
            let [first, count] = bottoms.headers[inst.mesh as usize];
            let (x, y, z, t) = (
                inst.to_local.matrix3.x_axis,
                inst.to_local.matrix3.y_axis,
                inst.to_local.matrix3.z_axis,
                inst.to_local.translation,
            );
            recs.push(TopRec {
                a: [x.x, x.y, x.z, t.x],
                b: [y.x, y.y, y.z, t.y],
                c: [z.x, z.y, z.z, t.z],
                w: [inst.mask, first, count, first_answer],
            });
        }
        Ok(TopLevel {
            recs,
            nodes: nodes.len(),
            order: tree.prims.clone(),
            first_answer,
            answers,
        })
    }

    /// The instance (index into the instances given) and the mesh's own triangle an answer's
    /// triangle number names.
    pub fn name(&self, answer: u32) -> (u32, u32) {
        let k = self.first_answer.partition_point(|&f| f <= answer) - 1;
        (self.order[k], answer - self.first_answer[k])
    }

    /// Bytes of the array (what a move uploads).
    pub fn bytes(&self) -> u64 {
        size_of_val(self.recs.as_slice()) as u64
    }
}

/// The answers' numbering of the records whose meshes are `meshes`, in record order: each
/// record's first triangle (its mesh's triangles numbered after the previous record's), and how
/// many are numbered in all (`TopLevel::first_answer`, `answers`).
pub fn number_answers(meshes: impl Iterator<Item = u32>, bottoms: &BottomLevels) -> Result<(Vec<u32>, u32)> {
    let mut first_answer = Vec::with_capacity(meshes.size_hint().0);
    let mut next = 0u32;
    for m in meshes {
        first_answer.push(next);
        // MISS (u32::MAX) is no triangle's number.
        next = next
            .checked_add(bottoms.tri_counts[m as usize])
            .filter(|&x| x < u32::MAX)
            .ok_or_else(|| {
                Error::InvalidInput("the scene's instances have more than 2^32 - 2 triangles together".into())
            })?;
    }
    Ok((first_answer, next))
}
