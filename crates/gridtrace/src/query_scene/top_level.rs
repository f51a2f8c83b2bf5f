//! The top level of a scene's two levels: a small binary BVH over the instances' world-space
//! boxes. It holds no triangles: a leaf names instances, and the walk hands each one whose box
//! the ray enters to the caller (`two_level.rs`), which carries the ray into the instance's
//! space and walks that mesh's own structure (the bottom level).
//!
//! The build splits at the median of the boxes' centres along the widest axis of the centres
//! (`select_nth_unstable`, no sort): O(n log n), about 60 us for 1,000 instances on one core,
//! so a move rebuilds it whole rather than refitting (a refit keeps a tree that moved
//! instances make loose; a rebuild of this size costs what a refit's bookkeeping would).

use glam::Vec3;

use crate::accel::Aabb;
use crate::accel::bvh::{Bvh, BvhNode};

/// Instances a leaf holds at most.
const LEAF: usize = 2;

/// A node: its box and either two children (`count == 0`: children at `first` and
/// `first + 1`) or `count` instances (`items[first..first + count]`).
#[derive(Debug, Clone, Copy)]
struct Node {
    bounds: Aabb,
    first: u32,
    count: u32,
}

/// The BVH over instance boxes. Items are indices into the caller's instance array.
#[derive(Debug, Clone, Default)]
pub(crate) struct TopLevel {
    nodes: Vec<Node>,
    items: Vec<u32>,
}

impl TopLevel {
    /// Builds over `boxes[i]` for every `i` (finite boxes: the caller checked the transforms).
    pub fn build(boxes: &[Aabb]) -> TopLevel {
        let mut t = TopLevel {
            nodes: Vec::with_capacity(2 * boxes.len().max(1)),
            items: (0..boxes.len() as u32).collect(),
        };
        if boxes.is_empty() {
            return t;
        }
        let centres: Vec<Vec3> = boxes.iter().map(|b| b.center()).collect();
        t.nodes.push(Node {
            bounds: Aabb::EMPTY,
            first: 0,
            count: 0,
        });
        // (node, first item, item count): nodes to fill, depth first.
        let mut todo = vec![(0usize, 0usize, boxes.len())];
        while let Some((node, first, count)) = todo.pop() {
            let items = &mut t.items[first..first + count];
            let bounds = items.iter().fold(Aabb::EMPTY, |b, &i| b.union(boxes[i as usize]));
            if count <= LEAF {
                t.nodes[node] = Node {
                    bounds,
                    first: first as u32,
                    count: count as u32,
                };
                continue;
            }
            let spread = items
                .iter()
                .fold(Aabb::EMPTY, |b, &i| b.grow(centres[i as usize]))
                .extent();
            let axis = if spread.x >= spread.y && spread.x >= spread.z {
                0
            } else if spread.y >= spread.z {
                1
            } else {
                2
            };
            let half = count / 2;
            items.select_nth_unstable_by(half, |&a, &b| {
                centres[a as usize][axis].total_cmp(&centres[b as usize][axis])
            });
            let left = t.nodes.len();
            let blank = Node {
                bounds: Aabb::EMPTY,
                first: 0,
                count: 0,
            };
            t.nodes.extend([blank, blank]);
            t.nodes[node] = Node {
                bounds,
                first: left as u32,
                count: 0,
            };
            todo.push((left, first, half));
            todo.push((left + 1, first + half, count - half));
        }
        t
    }

    /// The tree as the BVH's binary tree (`accel::bvh::Bvh`: the same node rule, children at
    /// `first` and `first + 1`, leaves' items in `prims`), for the GPU's layout of it
    /// (`gpu::walks::two_level`). `None` for no instances.
    pub fn as_bvh(&self) -> Option<Bvh> {
        if self.nodes.is_empty() {
            return None;
        }
        let nodes: Vec<BvhNode> = self
            .nodes
            .iter()
            .map(|n| BvhNode {
                min: n.bounds.min.to_array(),
                first: n.first,
                max: n.bounds.max.to_array(),
                count: n.count,
            })
            .collect();
        let mut depth = 0;
        let mut todo = vec![(0usize, 0usize)];
        while let Some((i, d)) = todo.pop() {
            depth = depth.max(d);
            if nodes[i].count == 0 {
                let c = nodes[i].first as usize;
                todo.extend([(c, d + 1), (c + 1, d + 1)]);
            }
        }
        Some(Bvh {
            nodes,
            prims: self.items.clone(),
            depth,
        })
    }

    /// Bytes held (nodes and items).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice()) + std::mem::size_of_val(self.items.as_slice())
    }

    /// Hands `visit` the instances of each leaf whose box the ray `origin + t * dir` enters
    /// with `t_min <= t <= t_max` (a leaf holds up to `LEAF`: so every instance whose own box
    /// it enters, and maybe a leaf-mate, which the mesh's own walk then misses), each once,
    /// nearer boxes first where the walk can tell. `visit` returns the
    /// new `t_max` (the closest hit so far, or `-inf` to stop: an any-hit query found one);
    /// boxes past it are skipped.
    #[inline]
    pub fn walk(&self, origin: Vec3, dir: Vec3, t_min: f32, mut t_max: f32, mut visit: impl FnMut(u32, f32) -> f32) {
        if self.nodes.is_empty() || t_max.is_nan() || t_max < t_min {
            return;
        }
        let inv_dir = dir.recip();
        let mut stack = [0u32; 64];
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            if node.bounds.clip(origin, inv_dir, t_min, t_max).is_none() {
                continue;
            }
            if node.count > 0 {
                let first = node.first as usize;
                for &i in &self.items[first..first + node.count as usize] {
                    t_max = visit(i, t_max);
                    // `-inf` (an any-hit query is done) or a hit before `t_min`: stop.
                    if t_max.is_nan() || t_max < t_min {
                        return;
                    }
                }
                continue;
            }
            // Both children on the stack, the nearer on top (walked first). A median split
            // over n items is at most log2(n) + 1 deep; 64 slots hold any u32 count.
            let (a, b) = (node.first, node.first + 1);
            let enter = |k: u32| {
                self.nodes[k as usize]
                    .bounds
                    .clip(origin, inv_dir, t_min, t_max)
                    .map_or(f32::INFINITY, |(t0, _)| t0)
            };
            let (ta, tb) = (enter(a), enter(b));
            let (near, far, t_far) = if ta <= tb { (a, b, tb) } else { (b, a, ta) };
            if t_far.is_finite() {
                stack[top] = far;
                top += 1;
            }
            if ta.min(tb).is_finite() {
                stack[top] = near;
                top += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every box the ray enters is visited, once, whatever the tree's shape (against a scan);
    /// what else is visited shares a leaf whose box the ray enters.
    #[test]
    fn walk_visits_every_box_a_scan_finds_once() {
        let mut s = 7u64;
        let mut r = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 33) as f32 / (1u64 << 31) as f32) * 2.0 - 1.0
        };
        for n in [0usize, 1, 2, 3, 5, 17, 300] {
            let boxes: Vec<Aabb> = (0..n)
                .map(|_| {
                    let c = Vec3::new(r(), r(), r()) * 10.0;
                    let h = Vec3::new(r().abs(), r().abs(), r().abs()) + 0.1;
                    Aabb { min: c - h, max: c + h }
                })
                .collect();
            let t = TopLevel::build(&boxes);
            for _ in 0..200 {
                let o = Vec3::new(r(), r(), r()) * 15.0;
                let d = Vec3::new(r(), r(), r());
                let mut seen = Vec::new();
                t.walk(o, d, 0.0, f32::INFINITY, |i, t_max| {
                    seen.push(i);
                    t_max
                });
                seen.sort_unstable();
                let inv = d.recip();
                let want: Vec<u32> = (0..n as u32)
                    .filter(|&i| boxes[i as usize].clip(o, inv, 0.0, f32::INFINITY).is_some())
                    .collect();
                assert!(seen.windows(2).all(|w| w[0] < w[1]), "n = {n}: visited twice");
                assert!(
                    want.iter().all(|i| seen.contains(i)),
                    "n = {n}: {want:?} not in {seen:?}"
                );
            }
        }
    }
}
