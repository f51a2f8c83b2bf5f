//! The BVH's 8-wide layout (`bvh=wide8`) under a top level: each mesh's wide tree, quantized from
//! the tree the CPU keeps for it (`Wide8::build`, once, at the meshes' upload), laid one after
//! another in the wide walk's own arrays, each moved to its place there (`Wide8::offset`); a
//! mesh's header names its root. The walk is bvh8.wgsl's, from that root.

use super::{Laid, TOP_LEVEL, TOP_LEVEL_ARRAY, WGSL_CONSTANTS};
use crate::accel::StructureId;
use crate::accel::{Accel, Structure};
use crate::gpu::layout::GpuTri;
use crate::gpu::walks::WalkSpec;
use crate::gpu::walks::bvh::{self, wide8::Wide8};
use crate::{Error, Result};

const ARRAYS: &[(&str, &str)] = &[
    bvh::WIDE8_ARRAYS[0],
    bvh::WIDE8_ARRAYS[1],
    bvh::WIDE8_ARRAYS[2],
    TOP_LEVEL_ARRAY,
];

/// The meshes' wide BVHs (private stack) under the top level.
pub const BVH_WIDE8: WalkSpec = WalkSpec {
    structure: StructureId::Bvh,
    name: "bvh (two levels, wide8)",
    wgsl: &[bvh::WIDE8, bvh::WIDE8_PRIVATE, TOP_LEVEL],
    prefix: "top",
    arrays: ARRAYS,
    device_build: false,
    tlas: None,
    software_max_tris: None,
    constants: WGSL_CONSTANTS,
    bottom: Some("bvh8"),
};

/// The meshes' wide BVHs (short stack) under the top level.
pub const BVH_WIDE8_SHORT: WalkSpec = WalkSpec {
    name: "bvh (two levels, wide8, short stack)",
    wgsl: &[bvh::WIDE8, bvh::WIDE8_SHORT, TOP_LEVEL],
    ..BVH_WIDE8
};

/// The bottom walk's arrays for meshes of BVHs in the wide layout (nodes, triangle indices in
/// leaf order, the triangles in that order: `ARRAYS` but the top level's) and each mesh's
/// header (its root node), as `Laid`. The indices stay each mesh's own: an answer names the mesh's
/// triangle, numbered in the answers from its instance's first (`key_base`).
pub(super) fn layout(meshes: &[&Accel]) -> Result<Laid> {
    let (mut nodes, mut prims, mut leaf_tris) = (Vec::new(), Vec::new(), Vec::new());
    let mut headers = Vec::with_capacity(meshes.len());
    for m in meshes {
        let Structure::Bvh(b) = &m.structure else {
            unreachable!("walk_for named the wide BVH's walk for every mesh");
        };
        if b.bvh.depth >= bvh::BVH_STACK as usize {
            return Err(Error::InvalidInput(format!(
                "a mesh's BVH is {} levels deep; the GPU walk's stack holds {}",
                b.bvh.depth,
                bvh::BVH_STACK
            )));
        }
        let mut own = Wide8::build(b)?;
        // `offset` bounds both sums (below `MAX_NODES` and 2^32).
        let (node_base, prim_base) = (nodes.len() as u32, prims.len() as u32);
        own.offset(node_base, prim_base)?;
        headers.push([node_base, 0]);
        leaf_tris.extend(own.prims.iter().map(|&p| GpuTri::new(&m.tris[p as usize])));
        nodes.extend(own.nodes);
        prims.extend(own.prims);
    }
    let arrays = vec![
        bytemuck::cast_slice(&nodes).to_vec(),
        bytemuck::cast_slice(&prims).to_vec(),
        bytemuck::cast_slice(&leaf_tris).to_vec(),
    ];
    // The walk reads its triangles in leaf order (`bvh8_tris`): group 0's `tris` holds one
    // zero triangle (a binding holds at least one element).
    Ok(Laid {
        arrays,
        tris: vec![bytemuck::Zeroable::zeroed()],
        headers,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::BvhAccel;
    use crate::accel::bvh::WIDTH;
    use crate::gpu::walks::bvh::binary::STACK_DONE;
    use crate::testing::triangle_soup;

    /// Wide trees laid one after another (`Wide8::offset`): from each tree's root the walk
    /// reaches exactly its own nodes, each once, whose parent positions name where it came
    /// from (the root's none), and exactly its own triangles, each once, in its own slice of
    /// the shared indices.
    #[test]
    fn wide_trees_one_after_another_keep_to_their_part() {
        let trees: Vec<Wide8> = [1, 9, 200, 3000]
            .iter()
            .map(|&n| Wide8::build(&BvhAccel::build(&triangle_soup(n, n as u64))).unwrap())
            .collect();
        let (mut all, mut prims, mut parts) = (Vec::new(), Vec::new(), Vec::new());
        for t in &trees {
            let mut own = t.clone();
            let (node_base, prim_base) = (all.len() as u32, prims.len() as u32);
            own.offset(node_base, prim_base).unwrap();
            parts.push((node_base, all.len() + own.nodes.len(), prim_base));
            all.extend(own.nodes);
            prims.extend(own.prims);
        }
        for (t, &(root, end, prim_base)) in trees.iter().zip(&parts) {
            let (mut seen, mut reached) = (Vec::new(), vec![0u32; end - root as usize]);
            assert_eq!(all[root as usize].info[3], STACK_DONE, "the root's parent");
            let mut todo = vec![root as usize];
            while let Some(g) = todo.pop() {
                assert!((root as usize..end).contains(&g), "node {g} outside {root}..{end}");
                reached[g - root as usize] += 1;
                let n = &all[g];
                for s in (0..WIDTH).filter(|&s| n.used(s)) {
                    if n.leaf_count(s) > 0 {
                        let first = n.leaf_first(s) as usize;
                        let last = first + n.leaf_count(s) as usize;
                        assert!(first >= prim_base as usize && last <= prim_base as usize + t.prims.len());
                        seen.extend_from_slice(&prims[first..last]);
                    } else {
                        let c = n.child_node(s) as usize;
                        assert_eq!(all[c].info[3], (g as u32) << 3 | s as u32, "node {c}'s parent");
                        todo.push(c);
                    }
                }
            }
            assert!(reached.iter().all(|&r| r == 1), "every node of the tree once");
            seen.sort_unstable();
            let mut want = t.prims.clone();
            want.sort_unstable();
            assert_eq!(seen, want);
        }
    }
}
