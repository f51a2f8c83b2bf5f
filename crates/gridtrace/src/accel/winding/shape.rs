//! The winding tree's shape (which triangles each child of each eight-wide node holds) and
//! the parallel pass that gives it its numbers: leaves' moments and blocks, then the nodes'
//! moments level by level from the deepest up, then the query tree (`wide.rs`).
//!
//! A shape comes from either builder: the scene's ray BVH collapsed (`from_bvh`, free where
//! the scene has built it) or the Morton-order tree (`morton.rs`, a sort and binary searches,
//! a small fraction of an SAH build). Any partition of the triangles gives right answers (a
//! cluster's moments and radius are its triangles' own); the shape only decides how many
//! nodes a point opens.
//!
//! Nodes are numbered breadth first, so each depth is one run of indices and a node's children
//! are all in the next run: the moments of a depth are computed in parallel from those of the
//! depth below, already final.

use glam::DVec3;
use rayon::prelude::*;

use super::expansion::Moment;
use super::wide::{self, Child, WIDTH, WideTree};
use crate::accel::{Aabb, Bvh, TriAccel};

/// A child in a shape: an inner node (its index) or a leaf (its index in `Shape::leaves`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kid {
    Node(u32),
    Leaf(u32),
}

/// Eight-wide nodes over a permutation of the triangles.
#[derive(Debug, Clone, Default)]
pub(super) struct Shape {
    /// Each node's children (one to `WIDTH`), breadth first from the root.
    pub nodes: Vec<Vec<Kid>>,
    /// The first node of each depth, then `nodes.len()`.
    pub depths: Vec<usize>,
    /// Each leaf's run of `prims`: (first, count), count from 1 to `WIDTH`.
    pub leaves: Vec<(u32, u32)>,
    /// Triangle indices, each leaf's a run.
    pub prims: Vec<u32>,
}

impl Shape {
    /// The shape of items of a tree that the builder opens breadth first from `root`:
    /// `open(item)` gives the up to `WIDTH` items a node over `item` holds (`[item]` itself
    /// for a root that is a leaf), `leaf(item)` the run of `prims` of an item that is a leaf.
    pub fn breadth_first<T: Copy>(
        root: T,
        prims: Vec<u32>,
        open: impl Fn(T) -> Vec<T>,
        leaf: impl Fn(T) -> Option<(u32, u32)>,
    ) -> Shape {
        let mut shape = Shape {
            prims,
            ..Shape::default()
        };
        // (item, depth) of each node, in the order they were numbered.
        let mut queue = std::collections::VecDeque::from([(root, 0usize)]);
        while let Some((item, depth)) = queue.pop_front() {
            if shape.depths.len() == depth {
                shape.depths.push(shape.nodes.len());
            }
            let kids = open(item)
                .into_iter()
                .map(|k| match leaf(k) {
                    Some(run) => {
                        shape.leaves.push(run);
                        Kid::Leaf(shape.leaves.len() as u32 - 1)
                    }
                    None => {
                        // Numbered now, opened after every node numbered before it.
                        let index = shape.nodes.len() + 1 + queue.len();
                        queue.push_back((k, depth + 1));
                        Kid::Node(index as u32)
                    }
                })
                .collect();
            shape.nodes.push(kids);
        }
        shape.depths.push(shape.nodes.len());
        shape
    }

    /// The ray BVH's binary tree collapsed to `WIDTH` children a node, the child of largest
    /// box opened first (`Bvh::wide_children`; the box's diagonal stands for the cluster's
    /// radius, which is not known yet).
    pub fn from_bvh(bvh: &Bvh) -> Shape {
        let bin = &bvh.nodes;
        let diagonal = |k: usize| {
            let n = &bin[k];
            f64::from((glam::Vec3::from(n.max) - glam::Vec3::from(n.min)).length())
        };
        Shape::breadth_first(
            0usize,
            bvh.prims.clone(),
            |b| bvh.wide_children(b, WIDTH, diagonal),
            |k| bin[k].is_leaf().then(|| (bin[k].first, bin[k].count)),
        )
    }

    /// The query tree over `tris` (the triangles the shape's `prims` index), all on rayon's
    /// pool. An empty shape or no triangles: an empty tree.
    pub fn tree(&self, tris: &[TriAccel]) -> WideTree {
        if tris.is_empty() || self.nodes.is_empty() {
            return WideTree::from_parts(Vec::new(), Vec::new());
        }
        let run = |&(first, count): &(u32, u32)| &self.prims[first as usize..(first + count) as usize];
        // A leaf's block, moments and box in one pass: its triangles are read through
        // `prims` (Morton or BVH order: a cache miss each), once for all three.
        let (blocks, leaves): (Vec<_>, Vec<(Moment, Aabb)>) = self
            .leaves
            .par_iter()
            .map(|l| {
                let prims = run(l).iter().map(|&t| &tris[t as usize]);
                let bounds = prims.clone().flat_map(|t| t.vertices()).fold(Aabb::EMPTY, Aabb::grow);
                (wide::block(tris, run(l)), (Moment::leaf(prims), bounds))
            })
            .unzip();
        let mut inner = vec![(Moment::ZERO, Aabb::EMPTY); self.nodes.len()];
        for d in (0..self.depths.len() - 1).rev() {
            let (this, next) = (self.depths[d], self.depths[d + 1]);
            let (head, below) = inner.split_at_mut(next);
            head[this..]
                .par_iter_mut()
                .zip(&self.nodes[this..next])
                .for_each(|(out, kids)| {
                    let parts: Vec<(Moment, Aabb)> = kids
                        .iter()
                        .map(|&k| match k {
                            Kid::Node(i) => below[i as usize - next],
                            Kid::Leaf(l) => leaves[l as usize],
                        })
                        .collect();
                    *out = merged(&parts);
                });
        }
        let nodes = self
            .nodes
            .par_iter()
            .map(|kids| {
                wide::node(kids.iter().map(|&k| match k {
                    Kid::Node(i) => (inner[i as usize].0.coefficients(), Child::Node(i)),
                    Kid::Leaf(l) => (leaves[l as usize].0.coefficients(), Child::Block(l)),
                }))
            })
            .collect();
        WideTree::from_parts(nodes, blocks)
    }
}

/// The union of clusters and of their boxes. Its radius is the smaller of two bounds on its
/// vertices' distance from the centre: the parts' spheres (`Moment::merge`) and the box's
/// farthest corner. Where the children sit side by side the spheres' bound overshoots (two
/// touching spheres of radius `r` give `2r` about the middle, the box of their vertices
/// about `1.4r` to `1.7r`): a smaller radius takes the node as far from nearer points, and the
/// walk stops higher. The radius stays a true bound, so the expansion's error bound holds.
/// The box's corner bound, widened by a tenth: with the bare corner the Dragon's error at
/// accuracy 2 came to libigl's (max 3.44e-3 against 3.36e-3 on 2,000 points, 2026-12-05); a
/// tenth more keeps it below (2.33e-3, mean 4.1e-4 against 5.6e-4) for 6% of the query's
/// time (bench/winding_vs_libigl.py: 0.537 -> 0.569 s for 1M points).
const CORNER_SLACK: f64 = 1.1;

fn merged(parts: &[(Moment, Aabb)]) -> (Moment, Aabb) {
    let moments: Vec<Moment> = parts.iter().map(|p| p.0).collect();
    let bounds = parts.iter().fold(Aabb::EMPTY, |b, p| b.union(p.1));
    let mut m = Moment::merge(&moments);
    let (lo, hi) = (bounds.min.as_dvec3(), bounds.max.as_dvec3());
    // The farthest corner: on each axis the face farther from the centre.
    let far = DVec3::select((m.center - lo).cmpgt(hi - m.center), lo, hi);
    let corner = (far - m.center).length() * CORNER_SLACK;
    if corner < m.radius {
        m.radius = corner;
    }
    (m, bounds)
}
