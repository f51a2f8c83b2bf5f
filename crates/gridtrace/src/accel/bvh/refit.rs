//! Refitting: the same tree over triangles that have moved (an animated mesh's next frame).
//!
//! Why refit rather than rebuild: a refit keeps the binary tree's topology (which triangles
//! share a leaf, which nodes are siblings) and only recomputes the boxes, bottom-up, in one
//! pass over the nodes with no sorting or binning; the SAH build spends its time choosing
//! splits. The price is quality: the splits were chosen for the pose the tree was built on. As
//! vertices move far from it, sibling boxes grow and overlap, and rays visit more nodes and
//! test more triangles. The answers stay exact (every box still bounds its triangles); only the
//! speed degrades, so a caller animating over a long time should rebuild now and then (for
//! example when the root's surface area, or the sum of the node areas, has grown well past what
//! it was at the build).

use super::wide::collapse;
use super::{BvhAccel, HugePageArray, padded_boxes};
use crate::accel::{Aabb, TriAccel};

use super::build::Bvh;

impl Bvh {
    /// Recomputes every node's box from new primitive boxes (`boxes[i]` for primitive `i`, as
    /// given to `build`), keeping the tree's topology: a leaf's box is the union of its
    /// primitives' boxes, an internal node's the union of its children's. With the boxes the
    /// tree was built from it reproduces the built boxes exactly.
    ///
    /// # Panics
    /// If `boxes.len()` is not the number of primitives the tree was built over.
    pub fn refit(&mut self, boxes: &[Aabb]) {
        assert_eq!(
            boxes.len(),
            self.prims.len(),
            "refit needs one box per primitive the tree was built over"
        );
        if self.prims.is_empty() {
            // The single empty root of an empty build: nothing to bound.
            return;
        }
        // Every child has a larger index than its parent: `build_range` appends a node's two
        // children after it, and `Bvh::build` puts a deferred subtree's root in the placeholder
        // (an index of the top tree) and appends the rest of it after all the top tree's nodes,
        // keeping its internal order. So one sweep from the last node to the first sees every
        // node after its children: a post-order without a stack.
        for i in (0..self.nodes.len()).rev() {
            let node = self.nodes[i];
            let first = node.first as usize;
            let b = if node.is_leaf() {
                self.prims[first..first + node.count as usize]
                    .iter()
                    .fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize]))
            } else {
                debug_assert!(first > i, "child {first} of node {i} comes before its parent");
                let (l, r) = (&self.nodes[first], &self.nodes[first + 1]);
                Aabb {
                    min: glam::Vec3::from(l.min).min(r.min.into()),
                    max: glam::Vec3::from(l.max).max(r.max.into()),
                }
            };
            self.nodes[i].min = b.min.to_array();
            self.nodes[i].max = b.max.to_array();
        }
    }
}

impl BvhAccel {
    /// Moves the BVH to new positions of the same triangles (`tris[i]` is triangle `i` of the
    /// build, wherever it now is): refits the binary tree to the triangles' boxes, padded as
    /// `build` pads them, then collapses it again into wide nodes and re-packs the triangle
    /// blocks. Hits are then exactly those of a brute-force test on `tris`, as after a build;
    /// traversal gets slower as the triangles move far from the pose of the build (see the
    /// module comment).
    ///
    /// # Panics
    /// If `tris.len()` is not the number of triangles the BVH was built over.
    pub fn refit(&mut self, tris: &[TriAccel]) {
        assert_eq!(
            tris.len(),
            self.bvh.prims.len(),
            "refit needs the triangles the BVH was built over, in the same order"
        );
        self.bvh.refit(&padded_boxes(tris));
        self.leaf_size = super::footprint::leaf_size(&self.bvh);
        let (nodes, blocks, lane_prims) = collapse(&self.bvh, tris);
        self.nodes = HugePageArray::from_slice(&nodes);
        self.blocks = HugePageArray::from_slice(&blocks);
        self.lane_prims = HugePageArray::from_slice(&lane_prims);
    }
}
