//! Eight-wide nodes and their child references, and the collapse of the binary SAH tree into
//! them (with each leaf's triangles packed into blocks of four).

use crate::accel::triangle::TriAccel4;
use crate::accel::{Aabb, TriAccel};

use super::build::{Bvh, LEAF_BLOCK, MAX_LEAF, half_area};

/// Children per node of the traversal tree. The binary SAH tree is collapsed to eight-wide
/// nodes (Dammertz et al. 2008; Embree's BVH8): a third of the levels, so a third of the
/// dependent memory loads per ray, and the eight box tests of a node run as one SIMD
/// computation with no branches (one AVX instruction per operation where the CPU has AVX2).
pub const WIDTH: usize = 8;

/// A value per child slot of a node.
pub(super) type Lanes = [f32; WIDTH];

/// An eight-wide node: its children's boxes in structure-of-arrays form (`planes[0][axis]` the
/// low planes, `planes[1][axis]` the high ones, one lane per child) and what each child is.
/// Exactly four cache lines. The two sides are one array so that a ray picks its near plane per
/// axis by an index computed once per ray (Embree's `nearX`), not by a select per node.
///
/// `child[k]` is a `ChildRef`: a node or a leaf. An unused slot has the empty box
/// `low = +inf, high = -inf`, which the near/far-plane box test below never enters.
#[repr(C, align(64))]
#[derive(Debug, Clone, Copy)]
pub struct WideNode {
    pub planes: [[Lanes; 3]; 2],
    pub child: [ChildRef; WIDTH],
}

impl WideNode {
    pub(super) const EMPTY: WideNode = WideNode {
        planes: [[[f32::INFINITY; WIDTH]; 3], [[f32::NEG_INFINITY; WIDTH]; 3]],
        child: [ChildRef(0); WIDTH],
    };
}

/// A child of a wide node in one word, `index << 4 | count`: with `count == 0` a node
/// (`BvhAccel::nodes[index]`), else a leaf of `count` triangles in `count.div_ceil(4)` blocks
/// from `BvhAccel::blocks[index]`. One word, so that a stack entry (`Pending`) is eight bytes
/// and a node's entries are sorted and stored as two AVX registers.
#[repr(transparent)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChildRef(pub u32);

impl ChildRef {
    /// Largest node or block index a reference holds (2^28 - 1: about a billion triangles,
    /// well past what fits in memory as blocks of 144 bytes).
    pub const MAX_INDEX: usize = (1 << 28) - 1;

    pub(super) fn node(index: usize) -> ChildRef {
        assert!(
            index <= Self::MAX_INDEX,
            "BVH node {index} past the largest child index"
        );
        ChildRef((index as u32) << 4)
    }
    pub(super) fn leaf(first_block: usize, count: u32) -> ChildRef {
        assert!(
            first_block <= Self::MAX_INDEX,
            "BVH block {first_block} past the largest child index"
        );
        debug_assert!((1..=MAX_LEAF as u32).contains(&count));
        ChildRef((first_block as u32) << 4 | count)
    }
    #[inline(always)]
    pub fn index(self) -> u32 {
        self.0 >> 4
    }
    /// Triangles in the leaf; 0 for a node.
    #[inline(always)]
    pub fn count(self) -> u32 {
        self.0 & 15
    }
}

/// Collapses the binary tree into eight-wide nodes: each wide node takes a binary node's
/// children and keeps opening the child with the largest surface area (the one a ray is most
/// likely to enter) until it has eight. Packs each leaf's triangles into blocks of four as it
/// meets them (depth first, so that nearby leaves are near in memory); returns the nodes, the
/// blocks and the input index of every block lane.
pub(super) fn collapse(bvh: &Bvh, tris: &[TriAccel]) -> (Vec<WideNode>, Vec<TriAccel4>, Vec<u32>) {
    let bin = &bvh.nodes;
    let mut nodes = vec![WideNode::EMPTY];
    let mut blocks = Vec::with_capacity(bvh.prims.len().div_ceil(2));
    let mut lane_prims = Vec::with_capacity(LEAF_BLOCK * blocks.capacity());
    if bvh.prims.is_empty() {
        // No primitives: a root with only empty slots, which no ray enters.
        return (nodes, blocks, lane_prims);
    }
    let area = |i: usize| {
        half_area(&Aabb {
            min: bin[i].min.into(),
            max: bin[i].max.into(),
        })
    };
    // (wide node to fill, binary node it stands for)
    let mut work = vec![(0usize, 0usize)];
    while let Some((wide, b)) = work.pop() {
        // f32 to f64 is exact: the areas order as they are.
        let kids = bvh.wide_children(b, WIDTH, |i| area(i) as f64);
        for (slot, &k) in kids.iter().enumerate() {
            let n = &bin[k];
            for a in 0..3 {
                nodes[wide].planes[0][a][slot] = n.min[a];
                nodes[wide].planes[1][a][slot] = n.max[a];
            }
            if n.is_leaf() {
                nodes[wide].child[slot] = ChildRef::leaf(blocks.len(), n.count);
                for ids in bvh.prims[n.first as usize..(n.first + n.count) as usize].chunks(LEAF_BLOCK) {
                    let block: Vec<TriAccel> = ids.iter().map(|&i| tris[i as usize]).collect();
                    blocks.push(TriAccel4::pack(&block));
                    lane_prims.extend(ids.iter().copied().chain(std::iter::repeat(u32::MAX)).take(LEAF_BLOCK));
                }
            } else {
                let w = nodes.len();
                nodes.push(WideNode::EMPTY);
                nodes[wide].child[slot] = ChildRef::node(w);
                work.push((w, k));
            }
        }
    }
    (nodes, blocks, lane_prims)
}
