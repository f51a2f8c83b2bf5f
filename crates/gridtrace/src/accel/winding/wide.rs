//! The fast winding numbers' query tree: eight children a node (its shape from `shape.rs`),
//! each child's second-order coefficients (`expansion.rs`) stored lane by lane, and each leaf's
//! triangles as one block of eight lanes; walked in `f32` lanes (eight, `simd::F8`, where the
//! CPU runs them: AVX2 or NEON; else two halves of four), as libigl walks its four-wide tree.
//!
//! Per node, the eight children are tested at once: a child farther than `accuracy` times
//! its radius adds its expansion; a nearer one is opened, a leaf through the exact solid
//! angles of its triangles (`block_angles`, all lanes at once). The sum is kept in lanes
//! and added up once a point.
//!
//! `f32` is enough here: a far child's terms are small and carry a relative error of `1e-7`,
//! and a near triangle's angle is computed from its vertices relative to the point, with the
//! triple product taken against the edges' cross product (no cancellation of large terms, as
//! `a . (b x c)` has for a far point). Measured against the exact `f64` sum it is far below
//! the expansion's own error (docs/robustness.md); `accuracy = inf` keeps the `f64` path.

use glam::Vec3;

use super::expansion::FIELDS;
use crate::accel::TriAccel;
use crate::accel::lanes::{Lanes, Mask};

/// Children per node: one AVX register of lanes.
pub(super) const WIDTH: usize = 8;

// A leaf of the library's BVH builder fits one block (`shape::Shape::from_bvh`).
const _: () = assert!(crate::accel::bvh::MAX_LEAF <= WIDTH);

/// A child reference: a node's index, or `LEAF | block`, or `EMPTY` (the GPU's walk reads
/// them too: `DEVICE_LEAF`, `DEVICE_EMPTY`).
pub(super) const LEAF: u32 = 1 << 31;
pub(super) const EMPTY: u32 = u32::MAX;
pub(crate) const DEVICE_LEAF: u32 = LEAF;
pub(crate) const DEVICE_EMPTY: u32 = EMPTY;

/// Eight children's coefficients, one row per field (`expansion::FIELDS`), a lane per child;
/// an empty slot has an infinite radius (never far) and `EMPTY` as its child.
#[derive(Debug, Clone)]
#[repr(C, align(32))]
pub(super) struct WideNode {
    pub(super) rows: [[f32; WIDTH]; FIELDS],
    pub(super) child: [u32; WIDTH],
}

/// A leaf's triangles, up to eight, a lane each: `v0, v1, v2`, `[x, y, z]` rows. An unused lane
/// repeats the block's first vertex three times: its angle is exactly 0 (`a . n = 0` and a
/// denominator `4 |a|^3 >= 0`, or `atan2(0, 0)` at that vertex, which `atan2_lanes` calls 0).
#[derive(Debug, Clone)]
#[repr(C, align(32))]
pub(super) struct Block {
    pub(super) v: [[[f32; WIDTH]; 3]; 3],
}

/// The tree.
#[derive(Debug, Clone)]
pub(super) struct WideTree {
    pub(super) nodes: Vec<WideNode>,
    pub(super) blocks: Vec<Block>,
}

impl WideTree {
    /// The tree of `nodes` (the root first) over `blocks` (`shape::Shape::tree` assembles
    /// them: a node's children by `node`).
    pub fn from_parts(nodes: Vec<WideNode>, blocks: Vec<Block>) -> WideTree {
        WideTree { nodes, blocks }
    }

    /// The sum of the solid angles at `p` (steradians), far children by their expansion where
    /// `|c - p|^2 > accuracy2 * r^2`; `stack` is the caller's, kept between points.
    pub fn solid_angle(&self, p: Vec3, accuracy2: f32, stack: &mut Vec<u32>) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        if crate::accel::simd::has_wide() {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            return unsafe { self.solid_angle_wide(p, accuracy2, stack) };
        }
        self.walk::<4, glam::Vec4>(p, accuracy2, stack)
    }

    /// `solid_angle` in lanes of four whatever the CPU has (the path without AVX2), for the
    /// tests to hold it to the eight-lane one.
    #[cfg(test)]
    pub fn solid_angle_fours(&self, p: Vec3, accuracy2: f32, stack: &mut Vec<u32>) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        self.walk::<4, glam::Vec4>(p, accuracy2, stack)
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2,fma"))]
    unsafe fn solid_angle_wide(&self, p: Vec3, accuracy2: f32, stack: &mut Vec<u32>) -> f64 {
        // `F8` is for the eight-lane build only: this function is compiled for it.
        self.walk::<8, crate::accel::lanes::F8>(p, accuracy2, stack)
    }

    /// The walk in lanes of `N` (`WIDTH / N` passes a node).
    #[inline(always)]
    fn walk<const N: usize, L: Lanes<N>>(&self, p: Vec3, accuracy2: f32, stack: &mut Vec<u32>) -> f64 {
        let pl = [L::splat(p.x), L::splat(p.y), L::splat(p.z)];
        let accuracy2 = L::splat(accuracy2);
        let mut sum = L::ZERO;
        stack.clear();
        stack.push(0);
        while let Some(i) = stack.pop() {
            let node = &self.nodes[i as usize];
            let mut base = 0;
            while base < WIDTH {
                let (far, near) = far_field::<N, L>(node, base, pl, accuracy2);
                sum = sum + far;
                let mut bits = near;
                while bits != 0 {
                    let slot = base + bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    match node.child[slot] {
                        EMPTY => {}
                        c if c & LEAF != 0 => {
                            let b = &self.blocks[(c & !LEAF) as usize];
                            let mut lane = 0;
                            while lane < WIDTH {
                                sum = sum + block_angles::<N, L>(b, lane, pl);
                                lane += N;
                            }
                        }
                        c => stack.push(c),
                    }
                }
                base += N;
            }
        }
        sum.to_array().iter().map(|&x| f64::from(x)).sum()
    }
}

/// A child of a wide node: a node's index in the tree or a block's (`node`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Child {
    Node(u32),
    Block(u32),
}

/// A node of up to `WIDTH` children, each with its cluster's coefficients
/// (`Moment::coefficients`); the slots after them empty (an infinite radius: never far).
pub(super) fn node(kids: impl IntoIterator<Item = ([f32; FIELDS], Child)>) -> WideNode {
    let mut rows = [[0.0; WIDTH]; FIELDS];
    rows[3] = [f32::INFINITY; WIDTH];
    let mut child = [EMPTY; WIDTH];
    for (slot, (coefficients, kid)) in kids.into_iter().take(WIDTH).enumerate() {
        for (row, x) in coefficients.into_iter().enumerate() {
            rows[row][slot] = x;
        }
        child[slot] = match kid {
            Child::Node(i) => i,
            Child::Block(b) => LEAF | b,
        };
    }
    WideNode { rows, child }
}

/// A leaf's block: `prims` (one to `WIDTH` of them) index `tris`.
pub(super) fn block(tris: &[TriAccel], prims: &[u32]) -> Block {
    assert!(
        !prims.is_empty() && prims.len() <= WIDTH,
        "a leaf fills one block (MAX_LEAF)"
    );
    let first = tris[prims[0] as usize].v0;
    let mut v = [[[0.0; WIDTH]; 3]; 3];
    let lanes = (0..WIDTH).map(|lane| {
        prims.get(lane).map_or([first; 3], |&t| {
            let t = &tris[t as usize];
            [t.v0, t.v1, t.v2]
        })
    });
    for (lane, t) in lanes.enumerate() {
        for (corner, xyz) in t.iter().enumerate() {
            for (axis, x) in xyz.iter().enumerate() {
                v[corner][axis][lane] = *x;
            }
        }
    }
    Block { v }
}

/// Lanes `base..base + N` of a row, one load. (The rows' loads are where a third of the
/// query's samples fall: perf, 300,000 Dragon points; the node's 832 bytes miss the cache.
/// Prefetching a pushed node's first two lines did not change the samples' count.)
#[inline(always)]
fn lanes<const N: usize, L: Lanes<N>>(row: &[f32; WIDTH], base: usize) -> L {
    L::from_array(*row[base..].first_chunk::<N>().expect("lanes within the row"))
}

/// Children `base..base + N` of `node` seen from `p`: the far ones' expansions summed lane by
/// lane, and the bits (from 0) of the ones to open. A far child whose expansion is not finite
/// (a point so close to a tiny cluster that the powers overflow) is opened instead.
#[inline(always)]
fn far_field<const N: usize, L: Lanes<N>>(node: &WideNode, base: usize, p: [L; 3], accuracy2: L) -> (L, u32) {
    let r = |f: usize| lanes::<N, L>(&node.rows[f], base);
    let q = [r(0) - p[0], r(1) - p[1], r(2) - p[2]];
    let d2 = q[0].mul_add(q[0], q[1].mul_add(q[1], q[2] * q[2]));
    let far = d2.gt(accuracy2 * r(3));
    let all = (1u32 << N) - 1;
    if far.bits() == 0 {
        // Every child near (the common case deep in the tree, near the surface): the
        // expansion's 22 other rows are not read.
        return (L::ZERO, all);
    }
    let omega = expansion::<N, L>(r, q, d2);
    // `abs < inf` is false for NaN and infinities alike.
    let take = far & omega.abs().lt(L::INFINITY);
    (L::select(take, omega, L::ZERO), !take.bits() & all)
}

/// The solid angle a cluster subtends at a point, by its second-order expansion: `r(f)` is
/// field `f` of the cluster's coefficients (`expansion::FIELDS`), `q` its centre relative to
/// the point and `d2` that distance squared, a lane each (eight children at one point in the
/// per-point walk, one child at eight points in `packet.rs`: the same arithmetic, so the same
/// bits lane by lane).
#[inline(always)]
pub(super) fn expansion<const N: usize, L: Lanes<N>>(r: impl Fn(usize) -> L, q: [L; 3], d2: L) -> L {
    // `rsqrt` and FMAs: the Dragon's 1M points (29 nodes a point, nearly all with far
    // children) took 0.55-0.57 s with a division, a root and separate multiplies and adds,
    // 0.49-0.50 s so (the build and the query timed apart, 2-core Xeon). The estimate's Newton step keeps
    // `1e-6` relative, far below the expansion's own error. A point at a centre (`d2 = 0`)
    // gives NaN here, which the callers' finiteness test opens.
    let inv1 = d2.rsqrt();
    let inv2 = inv1 * inv1;
    let (x, y, z) = (q[0] * inv1, q[1] * inv1, q[2] * inv1);
    let order0 = r(4).mul_add(x, r(5).mul_add(y, r(6) * z)) * inv2;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, zx) = (x * y, y * z, z * x);
    let quad = r(7).mul_add(
        xx,
        r(8).mul_add(yy, r(9).mul_add(zz, r(10).mul_add(xy, r(11).mul_add(yz, r(12) * zx)))),
    );
    let order1 = L::splat(-3.0).mul_add(quad, r(7) + r(8) + r(9)) * (inv2 * inv1);
    let lin = r(13).mul_add(x, r(14).mul_add(y, r(15) * z));
    // The cubic's ten monomials, grouped by their first factor.
    let cx = r(16).mul_add(xx, r(19).mul_add(xy, r(20).mul_add(zx, r(25) * yz)));
    let cy = r(17).mul_add(yy, r(21).mul_add(xy, r(22).mul_add(yz, r(24) * zz)));
    let cz = r(18).mul_add(zz, r(23) * zx);
    let cubic = cx.mul_add(x, cy.mul_add(y, cz * z));
    let order2 = L::splat(7.5).mul_add(cubic, L::splat(-1.5) * lin) * (inv2 * inv2);
    order0 + order1 + order2
}

/// The exact solid angles of a block's lanes `base..base + N` at `p` (Van Oosterom and
/// Strackee, as `winding::solid_angle`, with the triple product against the edges' cross
/// product).
#[inline(always)]
fn block_angles<const N: usize, L: Lanes<N>>(b: &Block, base: usize, p: [L; 3]) -> L {
    triangle_angles::<N, L>(|c, a| lanes::<N, L>(&b.v[c][a], base), p)
}

/// The exact solid angles at `p` of triangles whose vertex `c`'s coordinate `a` is `v(c, a)`,
/// a lane each (a block's eight triangles at one point, or one triangle at eight points in
/// `packet.rs`).
#[inline(always)]
pub(super) fn triangle_angles<const N: usize, L: Lanes<N>>(v: impl Fn(usize, usize) -> L, p: [L; 3]) -> L {
    let a = [v(0, 0) - p[0], v(0, 1) - p[1], v(0, 2) - p[2]];
    let bb = [v(1, 0) - p[0], v(1, 1) - p[1], v(1, 2) - p[2]];
    let c = [v(2, 0) - p[0], v(2, 1) - p[1], v(2, 2) - p[2]];
    let e1 = [v(1, 0) - v(0, 0), v(1, 1) - v(0, 1), v(1, 2) - v(0, 2)];
    let e2 = [v(2, 0) - v(0, 0), v(2, 1) - v(0, 1), v(2, 2) - v(0, 2)];
    let n = [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ];
    let dot = |u: [L; 3], w: [L; 3]| u[0] * w[0] + u[1] * w[1] + u[2] * w[2];
    let num = dot(a, n);
    let (la, lb, lc) = (dot(a, a).sqrt(), dot(bb, bb).sqrt(), dot(c, c).sqrt());
    let den = la * lb * lc + dot(a, bb) * lc + dot(bb, c) * la + dot(c, a) * lb;
    L::splat(2.0) * atan2_lanes::<N, L>(num, den)
}

/// `atan2(y, x)` lane by lane, within 2 ulps of `f32::atan2` for finite arguments (the
/// tests), 0 for `(0, 0)` and pi for `(-0, x < 0)` (a zero's sign is not read): the quotient of the smaller by the larger magnitude, reduced
/// to `[0, tan(pi / 8)]` and a polynomial there (Cephes' `atanf`), then the octant put back.
#[inline(always)]
pub(super) fn atan2_lanes<const N: usize, L: Lanes<N>>(y: L, x: L) -> L {
    use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = (ax.min(ay), ax.max(ay));
    let t = L::select(hi.gt(L::ZERO), lo / hi, L::ZERO);
    let big = t.gt(L::splat(0.414_213_57));
    let u = L::select(big, (t - L::ONE) / (t + L::ONE), t);
    let z = u * u;
    let poly = (((L::splat(8.053_744_5e-2) * z - L::splat(1.387_768_6e-1)) * z + L::splat(1.997_771_1e-1)) * z
        - L::splat(3.333_295e-1))
        * z
        * u
        + u;
    let r = L::select(big, poly + L::splat(FRAC_PI_4), poly);
    let r = L::select(ay.gt(ax), L::splat(FRAC_PI_2) - r, r);
    let r = L::select(x.lt(L::ZERO), L::splat(PI) - r, r);
    L::select(y.lt(L::ZERO), L::ZERO - r, r)
}

/// The tree as the GPU walks it (`gpu/winding.rs`, winding.wgsl): the nodes' and the blocks'
/// bytes as they lie in memory (`#[repr(C)]`, no padding: 26 + 1 rows of eight 4-byte lanes a
/// node, 9 a block), and the most entries the walk's stack holds at once (each node opened
/// pushes at most its `WIDTH` children and pops itself).
pub(crate) struct DeviceTree<'a> {
    pub nodes: &'a [u8],
    pub blocks: &'a [u8],
    pub stack: usize,
}

// The WGSL's layouts (winding.wgsl `WindNode`, `WindBlock`) are these sizes, padding-free.
const _: () = assert!(size_of::<WideNode>() == (FIELDS + 1) * WIDTH * 4);
const _: () = assert!(size_of::<Block>() == 9 * WIDTH * 4);

impl WideTree {
    /// The tree for the GPU (`DeviceTree`).
    pub(crate) fn device(&self) -> DeviceTree<'_> {
        // SAFETY: both types are `#[repr(C)]` arrays of `f32` and `u32` with no padding (the
        // asserts above), so every byte is initialised and any alignment of `u8` holds; the
        // slices borrow `self`.
        let bytes = |p: *const u8, len: usize| unsafe { std::slice::from_raw_parts(p, len) };
        let nodes = bytes(self.nodes.as_ptr().cast(), size_of_val(self.nodes.as_slice()));
        let blocks = bytes(self.blocks.as_ptr().cast(), size_of_val(self.blocks.as_slice()));
        // The levels of nodes: a walk's stack holds at most the children one node of each
        // level pushed, `WIDTH` each (the walk pops one before it pushes a node's).
        let (mut levels, mut work) = (0, vec![(0u32, 1usize)]);
        while let Some((i, level)) = work.pop() {
            let Some(node) = self.nodes.get(i as usize) else { break };
            levels = usize::max(levels, level);
            work.extend(
                node.child
                    .iter()
                    .filter(|&&c| c != EMPTY && c & LEAF == 0)
                    .map(|&c| (c, level + 1)),
            );
        }
        DeviceTree {
            nodes,
            blocks,
            stack: levels.max(1) * WIDTH,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4;

    /// The lanes' `atan2` against `f32::atan2` over every octant, the axes, tiny and huge
    /// quotients: within 2e-7 radians (the polynomial's error; `f32`'s spacing at pi is 2.4e-7).
    #[test]
    fn atan2_lanes_follows_atan2() {
        let vals = [
            0.0f32, 1e-30, 1e-3, 0.3, 0.41, 0.42, 0.9, 1.0, 1.1, 2.4, 2.5, 7.0, 1e3, 1e30,
        ];
        let mut worst = 0.0f32;
        for &y in &vals {
            for &x in &vals {
                for (sy, sx) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                    let (yy, xx) = (sy * y, sx * x);
                    let got = atan2_lanes::<4, Vec4>(Vec4::splat(yy), Vec4::splat(xx)).x;
                    if y == 0.0 && x == 0.0 {
                        // `(0, 0)`: 0 by this function's contract, whatever the zeros' signs.
                        assert_eq!(got, 0.0);
                        continue;
                    }
                    let want = yy.atan2(xx);
                    // A zero `y`'s sign is not read: `(-0, x < 0)` gives pi, not -pi.
                    let want = if y == 0.0 { want.abs() } else { want };
                    worst = worst.max((got - want).abs());
                }
            }
        }
        assert!(worst <= 2.5e-7, "atan2 lanes off by {worst}");
    }
}
