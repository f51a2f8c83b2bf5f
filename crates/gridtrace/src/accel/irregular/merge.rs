//! Merging (the build's phase 3, `build.rs`): a cell absorbs its neighbour across its upper
//! face on one axis when the two have the same extent on the other axes and the surface-area
//! cost says the merged cell is no worse (`MergeRule`), over union-find (`Cells`); a top
//! cell's cells are merged in its own task and leave it as survivors (`TopCells`).

use glam::{UVec3, Vec3};

use super::boxes::{Box16, VoxBox};

/// Cost of stepping through a cell, in triangle tests, for the merge decision. A step is a
/// top-cell entry, a voxel-map entry and a 16-byte cell, about what one triangle test costs.
const COST_STEP: f64 = 1.0;
/// A cell's references during the build: a slice of the second level's array until a merge
/// with a different set gives it its own.
#[derive(Debug, Clone)]
pub(super) enum Refs {
    Span(u32, u32),
    Owned(Vec<u32>),
}

impl Refs {
    pub(super) fn get<'a>(&'a self, flat: &'a [u32]) -> &'a [u32] {
        match self {
            Refs::Span(s, n) => &flat[*s as usize..(*s + *n) as usize],
            Refs::Owned(v) => v,
        }
    }

    /// Consecutive spans of `flat` of the lengths `counts`, the first at `start`.
    pub(super) fn spans(counts: &[u32], start: u32) -> impl Iterator<Item = Refs> + '_ {
        counts.iter().scan(start, |s, &n| {
            *s += n;
            Some(Refs::Span(*s - n, n))
        })
    }
}

/// The merge's state over a set of cells (one top cell's, or all survivors): per cell its
/// union-find parent, its box and its references (spans of `flat`, or sets of their own).
pub(super) struct Cells<'a> {
    pub parent: &'a mut [u32],
    pub boxes: &'a mut [Box16],
    pub refs_of: &'a mut [Refs],
    pub flat: &'a [u32],
}

impl Cells<'_> {
    /// The root of cell `x`'s set, halving the path on the way.
    fn find(&mut self, x: u32) -> u32 {
        find(self.parent, x)
    }
}

/// A top cell's cells after the merge inside it: the survivors, in the order of their first
/// initial cell, and for each initial cell its survivor.
pub(super) struct TopCells {
    /// For each of the top cell's initial cells, its survivor (an index into `boxes`).
    pub rep: Vec<u32>,
    pub boxes: Vec<Box16>,
    /// The survivors' reference counts, and their references one after another.
    pub counts: Vec<u32>,
    pub refs: Vec<u32>,
}

impl TopCells {
    pub(super) fn gather(mut parent: Vec<u32>, boxes: &[Box16], refs_of: &[Refs], flat: &[u32]) -> TopCells {
        let n = parent.len();
        let alive = |k: usize| parent[k] == k as u32;
        let n_surv = (0..n).filter(|&k| alive(k)).count();
        let n_refs = (0..n).filter(|&k| alive(k)).map(|k| refs_of[k].get(flat).len()).sum();
        let mut out = TopCells {
            rep: Vec::with_capacity(n),
            boxes: Vec::with_capacity(n_surv),
            counts: Vec::with_capacity(n_surv),
            refs: Vec::with_capacity(n_refs),
        };
        // The survivors' new indices, in the place of their parents (a survivor is its own).
        let mut ordinal = vec![u32::MAX; n];
        for k in 0..n {
            if alive(k) {
                ordinal[k] = out.boxes.len() as u32;
                let r = refs_of[k].get(flat);
                out.boxes.push(boxes[k]);
                out.counts.push(r.len() as u32);
                out.refs.extend_from_slice(r);
            }
        }
        for k in 0..n as u32 {
            let root = find(&mut parent, k);
            out.rep.push(ordinal[root as usize]);
        }
        out
    }
}

/// When two cells merge (see phase 3 of `build`).
pub(super) struct MergeRule {
    pub voxel_dims: UVec3,
    pub voxel_size: Vec3,
    pub alpha: f64,
}

impl MergeRule {
    fn area(&self, b: &VoxBox) -> f64 {
        let d = ((b[1] - b[0]).as_vec3() * self.voxel_size).as_dvec3();
        d.x * d.y + d.y * d.z + d.z * d.x
    }

    /// One sweep along `axis`: each live cell of `order`, in turn, absorbs its neighbours
    /// across its upper face while the rule allows. `neighbour(mine, v)` is the cell of
    /// `cells` (before `find`: a task's own cell, or the survivor of the initial cell) that
    /// holds voxel `v` just past the face of the cell `mine`, or `None` where the sweep need
    /// not look.
    /// Returns the number of merges.
    pub(super) fn merge_along(
        &self,
        cells: &mut Cells,
        order: impl Iterator<Item = u32>,
        axis: usize,
        neighbour: impl Fn(&VoxBox, UVec3) -> Option<u32>,
    ) -> usize {
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut merged = 0;
        for cell in order {
            let k = cell as usize;
            if cells.parent[k] != cell {
                continue;
            }
            loop {
                let mine = cells.boxes[k].unpack();
                if mine[1][axis] >= self.voxel_dims[axis] {
                    break;
                }
                let mut probe = mine[0];
                probe[axis] = mine[1][axis];
                let Some(initial) = neighbour(&mine, probe) else { break };
                let other = cells.find(initial);
                let o = other as usize;
                let theirs = cells.boxes[o].unpack();
                if theirs[0][b] != mine[0][b]
                    || theirs[1][b] != mine[1][b]
                    || theirs[0][c] != mine[0][c]
                    || theirs[1][c] != mine[1][c]
                {
                    break;
                }
                let mut joined = mine;
                joined[1][axis] = theirs[1][axis];
                let (ra, rb) = (cells.refs_of[k].get(cells.flat), cells.refs_of[o].get(cells.flat));
                let separate = self.area(&mine) * (COST_STEP + ra.len() as f64)
                    + self.area(&theirs) * (COST_STEP + rb.len() as f64);
                let new_refs = if ra == rb {
                    None
                } else {
                    // The union has at least the larger set: skip the merge of sorted lists
                    // when even that is too costly.
                    let lower = self.area(&joined) * (COST_STEP + ra.len().max(rb.len()) as f64);
                    if lower > self.alpha * separate {
                        break;
                    }
                    Some(union(ra, rb))
                };
                let n_joined = new_refs.as_ref().map_or(ra.len(), Vec::len);
                if self.area(&joined) * (COST_STEP + n_joined as f64) > self.alpha * separate {
                    break;
                }
                if let Some(v) = new_refs {
                    cells.refs_of[k] = Refs::Owned(v);
                }
                cells.refs_of[o] = Refs::Span(0, 0);
                cells.boxes[k] = Box16::pack(joined);
                cells.parent[o] = cell;
                merged += 1;
            }
        }
        merged
    }
}

/// The root of `x`'s set, halving the path on the way.
pub(super) fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[x as usize];
        parent[x as usize] = parent[p as usize];
        x = p;
    }
    x
}

/// The union of two ascending lists, ascending.
fn union(a: &[u32], b: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            std::cmp::Ordering::Less => {
                out.push(a[i]);
                i += 1;
            }
            std::cmp::Ordering::Greater => {
                out.push(b[j]);
                j += 1;
            }
            std::cmp::Ordering::Equal => {
                out.push(a[i]);
                i += 1;
                j += 1;
            }
        }
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
    out
}
