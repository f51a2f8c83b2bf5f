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
pub mod records;

pub use bvh_wide8::{BVH_WIDE8, BVH_WIDE8_SHORT};
pub use irregular::IRREGULAR;
pub use records::{BottomLevels, Instance, TOP_LEVEL_ARRAY, TOP_STACK, TopLevel, TopRec};

use crate::accel::StructureId;
use bytemuck::{Pod, Zeroable};

use super::bvh::{self, BvhLayout, BvhStack, BvhWalk};
use super::{WalkSpec, brute, grid};
use crate::accel::{Accel, Structure};
use crate::gpu::constants::WgslConst;
use crate::gpu::layout::GpuTri;
use crate::{Error, Result};

use super::bvh::binary;

const TOP_LEVEL: &str = include_str!("top_level.wgsl");

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::Aabb;
    use crate::accel::bvh::Bvh;
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
