//! A scene of two levels on the GPU (`QueryScene`'s instances, `query_scene/two_level.rs` on
//! the CPU): each mesh's structure uploaded once, the meshes' parts one after another in the
//! bottom walk's own arrays, and the top level (`top_level.wgsl`: a BVH over the instances'
//! world boxes and the instance records, one array) after them. The top level's walk carries a
//! ray into each instance its mask sees and calls the bottom structure's walk over that mesh's
//! part, named by the mesh's header (`MeshHeader` in common.wgsl: where its structure starts,
//! and how much of it there is), never by the scene's constants.
//!
//! Where a structure plugs in: its walk file defines `NAME_closest_in(h: MeshHeader, ...)` and
//! `NAME_any_in(h, ...)` (its one-level `NAME_closest` calls them with the scene's one header),
//! its arrays can hold several meshes one after another (a mesh's entries offset by its part's
//! start), and `bottom_levels` below concatenates them and makes each mesh's header; then one
//! `WalkSpec` here (its arrays, then `TOP_LEVEL_ARRAY`) and one arm of `walk_for`. Carried
//! today: every structure. The BVH in either layout (binary nodes; the 8-wide nodes,
//! `bvh_wide8.rs`, each mesh's wide tree quantized once at upload) with either stack, brute
//! force, the uniform grid (grid, pc: its lattice, one per scene in the scene uniform for one
//! level, is a row of a table here, which the mesh's header names), the irregular grid
//! (`irregular.rs`: its lattice of virtual voxels a row of a table the same way, and its
//! entries, voxel maps and references one array of words, to stay within the structure's
//! budget of bindings) and `hwrt`, whose top and bottom levels are the driver's (a TLAS
//! instance a scene instance over a BLAS a mesh, `hwrt::INSTANCES`; its "top level" array is
//! its instance table).
//!
//! A move (`QueryScene::set_transforms`, `set_mask`) uploads the top level alone, whatever the
//! meshes' structure: 64 bytes a node and 64 an instance (`TopRec`); the meshes' arrays stay
//! on the device. For `hwrt` it rebuilds the TLAS alone (64 bytes an instance uploaded) and
//! writes the instance table where it changed.

mod bvh_wide8;
mod irregular;

pub use bvh_wide8::{BVH_WIDE8, BVH_WIDE8_SHORT};
pub use irregular::IRREGULAR;

use crate::accel::StructureId;
use bytemuck::{Pod, Zeroable};
use glam::Affine3A;

use super::bvh::{self, BvhLayout, BvhStack, BvhWalk};
use super::{WalkSpec, brute, grid};
use crate::accel::bvh::Bvh;
use crate::accel::{Accel, AccelKind, Structure};
use crate::gpu::constants::WgslConst;
use crate::gpu::layout::GpuTri;
use crate::{Error, Result};

use super::bvh::binary::{self, GpuBvhNode};

/// The top level's array (the last of a two-level walk's arrays): its report name and its WGSL
/// variable.
pub const TOP_LEVEL_ARRAY: (&str, &str) = ("top level", "top_level");

const TOP_LEVEL: &str = include_str!("top_level.wgsl");

/// Entries of the top-level walk's stack: above any top level's depth (a median split over
/// `n` instances is `log2(n) + 1` deep; checked at upload).
pub const TOP_STACK: u32 = 32;

const WGSL_CONSTANTS: &[(&str, WgslConst)] = &[("TOP_STACK", WgslConst::U32(TOP_STACK))];

const BVH_ARRAYS: &[(&str, &str)] = &[
    bvh::BINARY_ARRAYS[0],
    bvh::BINARY_ARRAYS[1],
    bvh::BINARY_ARRAYS[2],
    TOP_LEVEL_ARRAY,
];

/// The meshes' binary BVHs (private stack) under the top level.
pub const BVH: WalkSpec = WalkSpec {
    structure: StructureId::Bvh,
    name: "bvh (two levels)",
    wgsl: &[bvh::BINARY, bvh::BINARY_PRIVATE, TOP_LEVEL],
    prefix: "top",
    arrays: BVH_ARRAYS,
    device_build: false,
    tlas: None,
    software_max_tris: None,
    constants: WGSL_CONSTANTS,
    bottom: Some("bvh"),
};

/// The meshes' binary BVHs (short stack) under the top level.
pub const BVH_SHORT: WalkSpec = WalkSpec {
    name: "bvh (two levels, short stack)",
    wgsl: &[bvh::BINARY, bvh::BINARY_SHORT, TOP_LEVEL],
    ..BVH
};

/// The meshes' uniform grids (plain or with proximity clouds: the pass says which) under the
/// top level: their cells and references one mesh after another, their lattices in a table
/// (`LatticeRow`) whose row a mesh's header names, their triangles in the shared `tris`.
pub const GRID: WalkSpec = WalkSpec {
    structure: StructureId::Grid,
    name: "grid (two levels)",
    wgsl: &[
        grid::SPEC.wgsl[0],
        super::POINT_RING,
        include_str!("grid_rows.wgsl"),
        TOP_LEVEL,
    ],
    prefix: "top",
    arrays: &[
        grid::SPEC.arrays[0],
        grid::SPEC.arrays[1],
        ("lattices", "grid_lattices"),
        TOP_LEVEL_ARRAY,
    ],
    device_build: false,
    tlas: None,
    software_max_tris: None,
    constants: WGSL_CONSTANTS,
    bottom: Some("grid"),
};

/// A row of the grids' lattice table (`Lattice` in common.wgsl): one mesh's grid's box, cell
/// size, dims, and where its cells and triangles start in the shared arrays.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct LatticeRow {
    pub lo: [f32; 3],
    pub first_cell: u32,
    pub hi: [f32; 3],
    pub first_tri: u32,
    pub cell: [f32; 3],
    pub shift: u32,
    pub inv_cell: [f32; 3],
    /// Where the mesh's voxel maps start (the irregular grid's, `irregular.rs`; 0 for the grid).
    pub first_map: u32,
    pub dims: [u32; 3],
    pub _pad1: u32,
}

/// Every mesh's triangles, brute force, under the top level: no arrays of its own (the shared
/// triangles, `tris`, hold every mesh's, one after another).
pub const BRUTE: WalkSpec = WalkSpec {
    structure: StructureId::Brute,
    name: "brute (two levels)",
    wgsl: &[brute::SPEC.wgsl[0], TOP_LEVEL],
    prefix: "top",
    arrays: &[TOP_LEVEL_ARRAY],
    device_build: false,
    tlas: None,
    // llvmpipe's cap on a shader invocation's loop iterations (`brute::SPEC`), over every
    // instance a ray may test: held against the instances' triangles together.
    software_max_tris: brute::SPEC.software_max_tris,
    constants: WGSL_CONSTANTS,
    bottom: Some("brute"),
};

/// The two-level walk for meshes of `structure`, as the variants choose (`walk`), or `None`
/// where the structure's GPU side is not carried under a top level (every structure is today;
/// a new one answers `None` until it is, and its scenes' GPU rays take the merged mesh): the
/// one place that says which are.
pub fn walk_for(structure: &Structure, walk: BvhWalk) -> Option<&'static WalkSpec> {
    match (structure, walk.layout, walk.stack) {
        (Structure::Bvh(_), BvhLayout::Binary, BvhStack::Private) => Some(&BVH),
        (Structure::Bvh(_), BvhLayout::Binary, BvhStack::Short(_)) => Some(&BVH_SHORT),
        (Structure::Bvh(_), BvhLayout::Wide8, BvhStack::Private) => Some(&BVH_WIDE8),
        (Structure::Bvh(_), BvhLayout::Wide8, BvhStack::Short(_)) => Some(&BVH_WIDE8_SHORT),
        (Structure::Brute(_), _, _) => Some(&BRUTE),
        (Structure::Grid(_), _, _) => Some(&GRID),
        (Structure::Irregular(_), _, _) => Some(&IRREGULAR),
        (Structure::Hwrt(_), _, _) => Some(&super::hwrt::INSTANCES),
    }
}

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

/// A bottom structure's part of `BottomLevels` (the layouts in their own files): its arrays,
/// the triangles group 0 binds and each mesh's header.
struct Laid {
    arrays: Vec<Vec<u8>>,
    tris: Vec<GpuTri>,
    headers: Vec<[u32; 2]>,
}

/// The meshes' structures (`meshes[k]`, each built on the CPU in its own space) laid out for
/// the two-level walk `walk_for` picks for them, or `None` where it picks none (a structure
/// not carried, or meshes of different structures). Builds no structure over triangles: the
/// BVH's binary tree is the one the CPU keeps, its wide layout quantized from the CPU's 8-wide
/// tree.
pub fn bottom_levels(meshes: &[&Accel], walk: BvhWalk) -> Result<Option<BottomLevels>> {
    let Some(first) = meshes.first() else {
        return Ok(None);
    };
    let Some(spec) = walk_for(&first.structure, walk) else {
        return Ok(None);
    };
    if meshes
        .iter()
        .any(|m| !walk_for(&m.structure, walk).is_some_and(|w| std::ptr::eq(w, spec)))
    {
        return Ok(None);
    }
    let tri_counts: Vec<u32> = meshes.iter().map(|m| m.tris.len() as u32).collect();
    let too_many = || Error::InvalidInput("the scene's meshes have more than 2^32 triangles together".into());
    let mut headers = Vec::with_capacity(meshes.len());
    let kind = first.kind();
    if matches!(first.structure, Structure::Hwrt(_)) {
        // The driver's BLASes, built from the meshes' triangles at upload: no arrays of ours.
        return Ok(Some(super::hwrt::instances::bottom_levels(spec, kind, tri_counts)));
    }
    if matches!(first.structure, Structure::Brute(_)) {
        let mut tris = Vec::new();
        for m in meshes {
            let first = u32::try_from(tris.len()).map_err(|_| too_many())?;
            headers.push([first, m.tris.len() as u32]);
            tris.extend(GpuTri::all(&m.tris));
        }
        u32::try_from(tris.len()).map_err(|_| too_many())?;
        return Ok(Some(BottomLevels {
            spec,
            kind,
            arrays: Vec::new(),
            tris,
            headers,
            tri_counts,
        }));
    }
    if matches!(first.structure, Structure::Grid(_)) {
        let (mut cells, mut refs, mut rows, mut tris) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (k, m) in meshes.iter().enumerate() {
            let Structure::Grid(g) = &m.structure else {
                unreachable!("walk_for named the grid's walk for every mesh");
            };
            let first_tri = u32::try_from(tris.len()).map_err(|_| too_many())?;
            let first_ref = u32::try_from(refs.len()).map_err(|_| too_many())?;
            // Every offset entry below fits (the counts after this mesh do).
            u32::try_from(tris.len() + m.tris.len()).map_err(|_| too_many())?;
            u32::try_from(refs.len() + g.refs.len()).map_err(|_| too_many())?;
            let first_cell = u32::try_from(cells.len()).map_err(|_| too_many())?;
            rows.push(LatticeRow {
                lo: g.bounds.min.to_array(),
                first_cell,
                hi: g.bounds.max.to_array(),
                first_tri,
                cell: g.cell_size.to_array(),
                shift: 0,
                inv_cell: g.inv_cell_size.to_array(),
                first_map: 0,
                dims: g.dims.to_array(),
                _pad1: 0,
            });
            headers.push([k as u32, 0]);
            // A cell's references start where the mesh's do; a reference names a triangle of
            // the shared `tris`.
            cells.extend(g.cells.iter().map(|c| crate::accel::Cell {
                start: c.start + first_ref,
                ..*c
            }));
            refs.extend(g.refs.iter().map(|&r| r + first_tri));
            tris.extend(GpuTri::all(&m.tris));
        }
        return Ok(Some(BottomLevels {
            spec,
            kind,
            arrays: vec![
                bytemuck::cast_slice(&cells).to_vec(),
                bytemuck::cast_slice(&refs).to_vec(),
                bytemuck::cast_slice(&rows).to_vec(),
            ],
            tris,
            headers,
            tri_counts,
        }));
    }
    let laid = match first.structure {
        Structure::Irregular(_) => Some(irregular::layout(meshes)?),
        Structure::Bvh(_) if walk.layout == BvhLayout::Wide8 => Some(bvh_wide8::layout(meshes)?),
        _ => None,
    };
    if let Some(Laid { arrays, tris, headers }) = laid {
        return Ok(Some(BottomLevels {
            spec,
            kind,
            arrays,
            tris,
            headers,
            tri_counts,
        }));
    }
    let (mut nodes, mut prims, mut leaf_tris) = (Vec::new(), Vec::new(), Vec::new());
    for m in meshes {
        let Structure::Bvh(b) = &m.structure else {
            unreachable!("walk_for named the BVH's walk for every mesh");
        };
        if b.bvh.depth >= bvh::BVH_STACK as usize {
            return Err(Error::InvalidInput(format!(
                "a mesh's BVH is {} levels deep; the GPU walk's stack holds {}",
                b.bvh.depth,
                bvh::BVH_STACK
            )));
        }
        let mut own = binary::gpu_nodes(&b.bvh)?;
        let node_base = u32::try_from(nodes.len()).map_err(|_| too_many())?;
        let leaf_base = u32::try_from(prims.len()).map_err(|_| too_many())?;
        binary::offset_entries(&mut own, node_base, leaf_base)?;
        headers.push([node_base, 0]);
        nodes.extend(own);
        // The mesh's own triangle indices (an answer names the mesh's triangle).
        prims.extend_from_slice(&b.bvh.prims);
        leaf_tris.extend(b.bvh.prims.iter().map(|&p| GpuTri::new(&m.tris[p as usize])));
    }
    Ok(Some(BottomLevels {
        spec,
        kind,
        arrays: vec![
            bytemuck::cast_slice(&nodes).to_vec(),
            bytemuck::cast_slice(&prims).to_vec(),
            bytemuck::cast_slice(&leaf_tris).to_vec(),
        ],
        tris: vec![GpuTri::zeroed()],
        headers,
        tri_counts,
    }))
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
        let mut first_answer = Vec::with_capacity(tree.prims.len());
        let mut next = 0u32;
        for &i in &tree.prims {
            let inst = &instances[i as usize];
            let m = inst.mesh as usize;
            let [first, count] = bottoms.headers[m];
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
                w: [inst.mask, first, count, next],
            });
            first_answer.push(next);
            // MISS (u32::MAX) is no triangle's number.
            next = next
                .checked_add(bottoms.tri_counts[m])
                .filter(|&x| x < u32::MAX)
                .ok_or_else(|| {
                    Error::InvalidInput("the scene's instances have more than 2^32 - 2 triangles together".into())
                })?;
        }
        Ok(TopLevel {
            recs,
            nodes: nodes.len(),
            order: tree.prims.clone(),
            first_answer,
            answers: next,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::Aabb;
    use crate::util::Rng;
    use glam::Vec3;

    /// A BVH over `n` random boxes.
    fn tree(n: usize, seed: u64) -> Bvh {
        let mut rng = Rng::new(seed);
        let centers: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(rng.range(-5.0, 5.0), rng.range(-5.0, 5.0), rng.range(-5.0, 5.0)))
            .collect();
        let boxes: Vec<Aabb> = centers
            .iter()
            .map(|&c| Aabb {
                min: c - 0.3,
                max: c + 0.3,
            })
            .collect();
        Bvh::build(&boxes, &centers)
    }

    /// Trees laid one after another (`offset_entries`): from each tree's root the walk reaches
    /// exactly its own leaves, each of its items once (the leaves' firsts moved by its leaf
    /// base), through its own nodes only, whose parent links name where the walk came from.
    #[test]
    fn trees_one_after_another_keep_to_their_part() {
        let trees = [tree(1, 1), tree(2, 2), tree(37, 3), tree(500, 4)];
        let (mut all, mut roots, mut items) = (Vec::new(), Vec::new(), Vec::new());
        for t in &trees {
            let mut own = binary::gpu_nodes(t).unwrap();
            let (node_base, leaf_base) = (all.len() as u32, items.len() as u32);
            binary::offset_entries(&mut own, node_base, leaf_base).unwrap();
            roots.push((node_base, node_base + own.len() as u32, leaf_base));
            all.extend(own);
            items.extend_from_slice(&t.prims);
        }
        for (t, &(root, end, leaf_base)) in trees.iter().zip(&roots) {
            let mut seen = Vec::new();
            let mut todo = vec![(root, binary::STACK_DONE)];
            while let Some((node, parent)) = todo.pop() {
                assert!((root..end).contains(&node), "node {node} outside {root}..{end}");
                let n = &all[node as usize];
                assert_eq!(n.child[2], parent, "node {node}'s parent link");
                for k in 0..2 {
                    let e = n.child[k];
                    match binary::decode_leaf(e) {
                        _ if e == binary::STACK_DONE => {}
                        Some((first, count)) => {
                            assert!(first >= leaf_base && first + count <= leaf_base + t.prims.len() as u32);
                            seen.extend_from_slice(&items[first as usize..(first + count) as usize]);
                        }
                        None => todo.push((e, (node << 1) | k as u32)),
                    }
                }
            }
            seen.sort_unstable();
            let mut want = t.prims.clone();
            want.sort_unstable();
            assert_eq!(seen, want);
        }
    }
}
