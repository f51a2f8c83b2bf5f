//! Closest hits as queries return them: a structure of arrays, filled in parallel pieces.

use std::ops::Range;

use rayon::prelude::*;

use crate::accel::huge::advise_huge_pages_within;

/// Closest hits, one entry per ray (structure of arrays). A miss has `t = inf`,
/// `tri = u32::MAX`, `u = v = 0` and a zero normal.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Hits {
    pub t: Vec<f32>,
    /// Index of the hit triangle in the input faces.
    pub tri: Vec<u32>,
    /// Barycentric coordinates of the hit: weight of the face's second (`u`) and third (`v`)
    /// vertex.
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    /// Unit geometric normal of the hit triangle, `normalize((v1 - v0) x (v2 - v0))` in input
    /// winding order (not flipped towards the ray).
    pub normal: Vec<[f32; 3]>,
}

/// A piece of a `Hits` being filled.
pub(super) struct HitsMut<'a> {
    pub(super) t: &'a mut [f32],
    pub(super) tri: &'a mut [u32],
    pub(super) u: &'a mut [f32],
    pub(super) v: &'a mut [f32],
    pub(super) normal: &'a mut [[f32; 3]],
}

impl Hits {
    pub(super) fn zeroed(n: usize) -> Hits {
        let mut h = Hits {
            t: vec![0.0; n],
            tri: vec![0; n],
            u: vec![0.0; n],
            v: vec![0.0; n],
            normal: vec![[0.0; 3]; n],
        };
        // 32 bytes a ray, in fresh pages: for a million rays, thousands of page faults fewer.
        advise_huge_pages_within(&mut h.t);
        advise_huge_pages_within(&mut h.tri);
        advise_huge_pages_within(&mut h.u);
        advise_huge_pages_within(&mut h.v);
        advise_huge_pages_within(&mut h.normal);
        h
    }

    /// Entries `range`, in pieces of `size`, to fill in parallel.
    pub(super) fn pieces(
        &mut self,
        range: Range<usize>,
        size: usize,
    ) -> impl IndexedParallelIterator<Item = HitsMut<'_>> {
        (
            self.t[range.clone()].par_chunks_mut(size),
            self.tri[range.clone()].par_chunks_mut(size),
            self.u[range.clone()].par_chunks_mut(size),
            self.v[range.clone()].par_chunks_mut(size),
            self.normal[range].par_chunks_mut(size),
        )
            .into_par_iter()
            .map(|(t, tri, u, v, normal)| HitsMut { t, tri, u, v, normal })
    }

    pub fn len(&self) -> usize {
        self.t.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
}
