//! Tests of the builder, the box test, the sorting network and the traversal.

use std::mem::MaybeUninit;

use super::box_test::{BoxRay, Pending};
use super::build::{MAX_LEAF, STACK};
use super::*;
use crate::accel::simd::has_wide;
use crate::accel::{NoCounters, brute_force_intersect, brute_force_occluded};

#[test]
fn depth_is_bounded_for_exponentially_spaced_boxes() {
    // Centres at 2^-k: every SAH split peels off one box, the worst case for depth.
    let centers: Vec<Vec3> = (0..2000)
        .map(|k| Vec3::splat(0.5f32.powi(k % 120) * (1 + k / 120) as f32))
        .collect();
    let boxes: Vec<Aabb> = centers.iter().map(|&c| Aabb { min: c, max: c }).collect();
    let bvh = Bvh::build(&boxes, &centers);
    assert!(bvh.depth < STACK, "depth {} >= stack {STACK}", bvh.depth);
    let mut seen = bvh.prims.clone();
    seen.sort();
    assert_eq!(
        seen,
        (0..2000).collect::<Vec<u32>>(),
        "every primitive in exactly one leaf"
    );
}

/// Every primitive in exactly one leaf, inside its leaf's box; every child box inside its
/// parent's. 20,000 boxes exercise the parallel subtrees (deferred below 4,096).
#[test]
fn leaves_cover_their_primitives() {
    for n in [500u32, 20_000] {
        let centers: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new((i * 37 % 101) as f32, (i * 17 % 53) as f32, i as f32 * 0.1))
            .collect();
        let boxes: Vec<Aabb> = centers
            .iter()
            .map(|&c| Aabb {
                min: c - 0.5,
                max: c + 0.5,
            })
            .collect();
        let bvh = Bvh::build(&boxes, &centers);
        let mut seen = vec![0u32; n as usize];
        // Walk from the root so that every reachable node is checked.
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let node = &bvh.nodes[i];
            let b = Aabb {
                min: node.min.into(),
                max: node.max.into(),
            };
            let contains = |o: &Aabb| b.min.cmple(o.min).all() && b.max.cmpge(o.max).all();
            if node.is_leaf() {
                assert!(node.count as usize <= MAX_LEAF);
                for &p in &bvh.prims[node.first as usize..(node.first + node.count) as usize] {
                    assert!(contains(&boxes[p as usize]));
                    seen[p as usize] += 1;
                }
            } else {
                for c in [node.first as usize, node.first as usize + 1] {
                    let cn = &bvh.nodes[c];
                    assert!(contains(&Aabb {
                        min: cn.min.into(),
                        max: cn.max.into()
                    }));
                    stack.push(c);
                }
            }
        }
        assert!(seen.iter().all(|&k| k == 1), "n = {n}: every primitive exactly once");
    }
}

fn random_ray(rng: &mut crate::util::Rng) -> Ray {
    let mut d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
    // Some directions with zero components: rays parallel to slabs.
    for a in 0..3 {
        if rng.below(5) == 0 {
            d[a] = 0.0;
        }
    }
    if d == Vec3::ZERO {
        d = Vec3::Y;
    }
    let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
    Ray::new(o, d * rng.range(0.1, 10.0))
}

/// A node of random boxes (some flat, some points, some slots empty) and a random ray, most
/// of the time aimed through the first box, with `t_min` and `t_max`.
pub(super) fn random_node_and_ray(rng: &mut crate::util::Rng, round: usize) -> (WideNode, Ray, f32, f32) {
    let mut node = WideNode::EMPTY;
    for slot in 0..WIDTH - round % 3 {
        for a in 0..3 {
            let (lo, hi) = if round % 5 == 4 {
                // Nested-ish boxes around the origin: rays enter several.
                (rng.range(-1.0, -0.1), rng.range(0.1, 1.0))
            } else {
                let lo = rng.range(-1.0, 1.0);
                (lo, lo + [0.0, 1e-6, rng.range(0.0, 1.0)][rng.below(3) as usize])
            };
            node.planes[0][a][slot] = lo;
            node.planes[1][a][slot] = hi;
        }
        node.child[slot] = ChildRef::leaf(round * WIDTH + slot, 1 + (slot % MAX_LEAF) as u32);
    }
    let aim = Vec3::from_array(std::array::from_fn(|a| {
        node.planes[0][a][0] + 0.5 * (node.planes[1][a][0] - node.planes[0][a][0])
    }));
    let mut ray = random_ray(rng);
    if !round.is_multiple_of(8) {
        ray = Ray::new(ray.origin, (aim - ray.origin) * rng.range(0.5, 2.0));
    }
    // Some with t_min = -0.0, which `order_key` maps to +0.0.
    let (t_min, t_max) = match round % 4 {
        0 => (0.5, rng.range(0.5, 3.0)),
        1 => (-0.0, f32::INFINITY),
        _ => (0.0, f32::INFINITY),
    };
    (node, ray, t_min, t_max)
}

/// The bitonic network sorts: random keys, many repeated, against the standard sort.
#[test]
fn sort8_sorts() {
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: the network is not used here");
        return;
    }
    // SAFETY: the CPU runs the eight-lane build, checked above.
    unsafe { sort8_rounds() }
}

#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
unsafe fn sort8_rounds() {
    use crate::accel::simd::{U8, sort8};
    let mut rng = crate::util::Rng::new(0x5027);
    for round in 0..20_000 {
        let range = [4, 1000, u32::MAX][round % 3];
        let keys: [u32; 8] = std::array::from_fn(|_| (rng.next_u64() as u32) % range);
        let mut want = keys;
        want.sort_unstable();
        let got = sort8(U8::from_array(keys)).to_array();
        assert_eq!(got, want, "keys {keys:?}");
    }
}

/// A node step's pushed entries, portable and AVX2, are the same bits; they are exactly the
/// children the box test enters, farthest first (up to `order_key`'s eight ulps).
#[test]
fn avx_push_equals_portable_and_sorts_far_to_near() {
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: only the portable push runs here");
        return;
    }
    let mut rng = crate::util::Rng::new(0x9E57);
    let mut several = 0;
    for round in 0..20_000 {
        let (node, ray, t_min, t_max) = random_node_and_ray(&mut rng, round);
        let r = BoxRay::new(&ray);
        let (t, mask) = r.enter(&node, t_min, t_max);
        let mut a = [MaybeUninit::new(Pending {
            child: ChildRef(0),
            t_enter: 0.0,
        }); WIDTH];
        let mut b = a;
        let n = r.push_entered(&node, t_min, t_max, &mut a);
        // SAFETY: the CPU runs the eight-lane build, checked above.
        let n_avx = unsafe { r.push_entered_wide(&node, t_min, t_max, &mut b) };
        assert_eq!((n, n_avx), (mask.count_ones() as usize, n), "round {round}: counts");
        // SAFETY: all WIDTH entries were written by both pushes.
        let (a, b) = unsafe { (a.map(|p| p.assume_init()), b.map(|p| p.assume_init())) };
        let entries = |p: &[Pending]| p.iter().map(|p| (p.child.0, p.t_enter.to_bits())).collect::<Vec<_>>();
        assert_eq!(entries(&a[..n]), entries(&b[..n]), "round {round}: entries");
        let mut slots: Vec<usize> = a[..n].iter().map(|p| p.child.index() as usize % WIDTH).collect();
        for (p, &k) in a[..n].iter().zip(&slots) {
            assert_eq!(p.child, node.child[k], "round {round}: the child of its slot");
            assert_eq!(p.t_enter.to_bits(), t[k].to_bits(), "round {round}: its entry distance");
        }
        for w in a[..n].windows(2) {
            // Bits of a non-negative float, -0.0 as +0.0.
            let bits = |t: f32| (t.to_bits() as i32).max(0) as u32 & !7;
            assert!(
                bits(w[0].t_enter) >= bits(w[1].t_enter),
                "round {round}: {} before {}",
                w[0].t_enter,
                w[1].t_enter
            );
        }
        slots.sort();
        let want: Vec<usize> = (0..WIDTH).filter(|k| mask >> k & 1 != 0).collect();
        assert_eq!(slots, want, "round {round}: the entered slots");
        several += (n >= 3) as usize;
    }
    assert!(several > 1000, "nodes with several entered children: {several}");
}

/// The single walk's node step (`descend_wide`: one or two children picked without the sort)
/// leaves the stack as pushing every entered child would: the same entries, in the same order,
/// the same top. Some rounds with a negative `t_min` (entry distances below zero, which
/// `order_key` orders as zero, by slot).
#[test]
fn descend_equals_the_full_push() {
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: the node step is not used here");
        return;
    }
    let mut rng = crate::util::Rng::new(0xD35C);
    let mut seen = [0usize; 4];
    for round in 0..40_000 {
        let (node, ray, t_min, t_max) = random_node_and_ray(&mut rng, round);
        let t_min = if round % 7 == 6 { -1.0 } else { t_min };
        let r = BoxRay::new(&ray);
        let blank = MaybeUninit::new(Pending {
            child: ChildRef(u32::MAX),
            t_enter: f32::NAN,
        });
        let (mut a, mut b) = ([blank; 2 * WIDTH], [blank; 2 * WIDTH]);
        let base = round % 5;
        let n = r.push_entered(&node, t_min, t_max, (&mut a[base..base + WIDTH]).try_into().unwrap());
        // SAFETY: the CPU runs the eight-lane build, checked above.
        let top = unsafe { r.descend_wide(&node, t_min, t_max, &mut b, base) };
        assert_eq!(top, base + n, "round {round}: the top");
        // SAFETY: the entries below the top were written by both.
        let entries = |p: &[MaybeUninit<Pending>]| {
            p.iter()
                .map(|p| unsafe { p.assume_init() })
                .map(|p| (p.child.0, p.t_enter.to_bits()))
                .collect::<Vec<_>>()
        };
        assert_eq!(entries(&a[base..top]), entries(&b[base..top]), "round {round}: entries");
        seen[n.min(3)] += 1;
    }
    assert!(
        seen.iter().all(|&c| c > 1000),
        "rounds by children entered (0, 1, 2, more): {seen:?}"
    );
}

/// The AVX box test gives the portable one's entry distances and mask bit for bit: random
/// boxes (some flat, some points, some slots empty, some around a common point) against
/// random rays, some parallel to an axis, with and without limits on t.
#[test]
fn avx_box_test_equals_portable() {
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: only the portable box test runs here");
        return;
    }
    let mut rng = crate::util::Rng::new(0xB0C5);
    let mut entered = 0;
    for round in 0..20_000 {
        let (node, ray, t_min, t_max) = random_node_and_ray(&mut rng, round);
        let r = BoxRay::new(&ray);
        let (t, mask) = r.enter(&node, t_min, t_max);
        // SAFETY: the CPU runs the eight-lane build, checked above.
        let (t_avx, mask_avx) = unsafe { r.enter_wide_arrays(&node, t_min, t_max) };
        assert_eq!(mask, mask_avx, "round {round}: masks");
        assert_eq!(
            t.map(f32::to_bits),
            t_avx.map(f32::to_bits),
            "round {round}: entry distances"
        );
        entered += mask.count_ones();
    }
    assert!(entered > 10_000, "the rays really enter boxes: {entered}");
}

/// The batch traversal's AVX2 build and its baseline build give the same hits, bit for bit,
/// closest and any, on random triangles and rays.
#[test]
fn avx_and_baseline_traversals_agree() {
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: only the baseline traversal runs here");
        return;
    }
    let mut rng = crate::util::Rng::new(0x7A5E);
    let tris: Vec<TriAccel> = (0..3000)
        .map(|_| {
            let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            let mut p = || c + Vec3::new(rng.range(-0.1, 0.1), rng.range(-0.1, 0.1), rng.range(-0.1, 0.1));
            TriAccel::new(p(), p(), p())
        })
        .collect();
    let accel = BvhAccel::build(&tris);
    let rays: Vec<Ray> = (0..20_000).map(|_| random_ray(&mut rng)).collect();
    let closest = |avx: bool| {
        let mut out = vec![Hit::MISS; rays.len()];
        let finish = |i: usize, w: &Walk| out[i] = accel.result(&w.best);
        if avx {
            // SAFETY: the CPU runs the eight-lane build, checked above.
            unsafe { accel.interleaved_wide::<false>(rays.iter().enumerate(), finish) }
        } else {
            accel.interleaved_body::<false, false>(rays.iter().enumerate(), finish)
        }
        out
    };
    let short = crate::testing::within(&rays, 0.0, 1.0);
    let any = |avx: bool| {
        let mut out = vec![false; rays.len()];
        let finish = |i: usize, w: &Walk| out[i] = w.best.is_hit();
        if avx {
            // SAFETY: the CPU runs the eight-lane build, checked above.
            unsafe { accel.interleaved_wide::<true>(short.iter().enumerate(), finish) }
        } else {
            accel.interleaved_body::<true, false>(short.iter().enumerate(), finish)
        }
        out
    };
    let bits = |h: &Hit| (h.t.to_bits(), h.tri, h.u.to_bits(), h.v.to_bits());
    let (a, b) = (closest(false), closest(true));
    assert!(a.iter().filter(|h| h.is_hit()).count() > 2000, "the rays really hit");
    for (i, (a, b)) in a.iter().zip(&b).enumerate() {
        assert_eq!(bits(a), bits(b), "ray {i}: {a:?} against {b:?}");
    }
    assert_eq!(any(false), any(true));
}

/// A mesh of `n` small random triangles with their own vertices (`3 * n` positions) in
/// [-1, 1]^3, as positions and triangles.
pub(super) fn random_mesh(rng: &mut crate::util::Rng, n: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut positions = Vec::with_capacity(3 * n);
    for _ in 0..n {
        let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        for _ in 0..3 {
            positions.push(c + Vec3::new(rng.range(-0.1, 0.1), rng.range(-0.1, 0.1), rng.range(-0.1, 0.1)));
        }
    }
    let triangles = (0..n as u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    (positions, triangles)
}

pub(super) fn tris_of(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<TriAccel> {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            TriAccel::new(a, b, c)
        })
        .collect()
}

/// The binary boxes, the prims, and the wide nodes, blocks and lane map, compared exactly.
fn assert_same_accel(a: &BvhAccel, b: &BvhAccel, what: &str) {
    assert_eq!(a.bvh.nodes, b.bvh.nodes, "{what}: binary nodes");
    assert_eq!(a.bvh.prims, b.bvh.prims, "{what}: primitive order");
    assert_eq!(a.nodes.len(), b.nodes.len(), "{what}: wide node count");
    for (i, (x, y)) in a.nodes.iter().zip(b.nodes.iter()).enumerate() {
        assert_eq!(x.planes, y.planes, "{what}: wide node {i} boxes");
        assert_eq!(x.child, y.child, "{what}: wide node {i} children");
    }
    assert_eq!(a.blocks[..], b.blocks[..], "{what}: triangle blocks");
    assert_eq!(a.lane_prims[..], b.lane_prims[..], "{what}: lane map");
}

/// Children come after their parents in the node array, also across the parallel subtrees
/// stitched in by `Bvh::build` (the property the refit's reverse sweep relies on); a refit
/// with the triangles of the build reproduces the build exactly, and so does a refit back to
/// them from another pose. 30,000 triangles: several deferred subtrees (at most 4,096 each).
#[test]
fn refit_with_unchanged_triangles_is_the_build() {
    let mut rng = crate::util::Rng::new(0x8EF1);
    let (positions, triangles) = random_mesh(&mut rng, 30_000);
    let tris = tris_of(&positions, &triangles);
    let built = BvhAccel::build(&tris);
    for (i, node) in built.bvh.nodes.iter().enumerate() {
        if !node.is_leaf() {
            assert!(node.first as usize > i, "node {i}: children at {}", node.first);
        }
    }
    let mut refit = built.clone();
    refit.refit(&tris);
    assert_same_accel(&refit, &built, "refit in place");

    let moved: Vec<Vec3> = positions.iter().map(|p| *p * 1.5 + Vec3::new(0.3, -2.0, 0.1)).collect();
    refit.refit(&tris_of(&moved, &triangles));
    assert_ne!(refit.bvh.nodes, built.bvh.nodes, "the boxes moved");
    refit.refit(&tris);
    assert_same_accel(&refit, &built, "refit there and back");

    // An empty BVH refits to itself.
    let mut empty = BvhAccel::build(&[]);
    empty.refit(&[]);
    assert_same_accel(&empty, &BvhAccel::build(&[]), "empty");
}

#[test]
#[should_panic(expected = "refit needs the triangles the BVH was built over")]
fn refit_with_another_triangle_count_panics() {
    let mut rng = crate::util::Rng::new(5);
    let (positions, triangles) = random_mesh(&mut rng, 100);
    let tris = tris_of(&positions, &triangles);
    BvhAccel::build(&tris).refit(&tris[..99]);
}

/// Built on one pose and refitted to others, the BVH finds what brute force finds: closest
/// hits (same t; the same triangle unless another is hit at the same t) and any hits, per ray
/// and in batches. The poses: a smooth displacement, a twist with a stretch, and a scramble
/// that moves every triangle somewhere else in the mesh (the worst case for a refit's speed,
/// not its answers).
#[test]
fn refit_traversal_equals_brute_force() {
    let mut rng = crate::util::Rng::new(0x2EF17);
    let (pose_a, triangles) = random_mesh(&mut rng, 3000);
    let mut accel = BvhAccel::build(&tris_of(&pose_a, &triangles));
    let smooth: Vec<Vec3> = pose_a
        .iter()
        .map(|&p| p + 0.25 * Vec3::new((2.5 * p.y).sin(), (2.5 * p.z).sin(), (2.5 * p.x).sin()))
        .collect();
    let twist: Vec<Vec3> = pose_a
        .iter()
        .map(|&p| {
            let (s, c) = (2.5 * p.y).sin_cos();
            Vec3::new(1.6 * (c * p.x - s * p.z), 0.5 * p.y, 1.6 * (s * p.x + c * p.z))
        })
        .collect();
    let offsets: Vec<Vec3> = (0..triangles.len())
        .map(|_| Vec3::new(rng.range(-1.5, 1.5), rng.range(-1.5, 1.5), rng.range(-1.5, 1.5)))
        .collect();
    let scramble: Vec<Vec3> = pose_a
        .iter()
        .enumerate()
        .map(|(i, &p)| (p + offsets[i / 3]).clamp(Vec3::splat(-1.2), Vec3::splat(1.2)))
        .collect();
    for (name, pose) in [("smooth", smooth), ("twist", twist), ("scramble", scramble)] {
        let tris = tris_of(&pose, &triangles);
        accel.refit(&tris);
        let rays: Vec<Ray> = (0..4000)
            .map(|i| {
                let o = Vec3::new(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0), rng.range(-3.0, 3.0));
                let mut d = if i % 2 == 0 {
                    pose[rng.below(pose.len() as u32) as usize] - o
                } else {
                    Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0))
                };
                if i % 7 == 0 {
                    d.x = 0.0;
                }
                if i % 11 == 0 {
                    d.z = 0.0;
                }
                if d == Vec3::ZERO {
                    d = Vec3::Y;
                }
                Ray::new(o, d)
            })
            .collect();
        let mut batch = vec![Hit::MISS; rays.len()];
        accel.intersect_batch(&rays, &mut batch);
        let mut occ_batch = vec![false; rays.len()];
        accel.occluded_batch(&rays, &mut occ_batch);
        let mut hits = 0;
        for (i, r) in rays.iter().enumerate() {
            let want = brute_force_intersect(&tris, r);
            let got = accel.intersect(r, &mut NoCounters);
            assert_eq!(
                got.is_hit(),
                want.is_hit(),
                "{name}, ray {i}: got {got:?} want {want:?}"
            );
            assert_eq!(batch[i], got, "{name}, ray {i}: batch");
            assert_eq!(occ_batch[i], want.is_hit(), "{name}, ray {i}: batch any hit");
            assert_eq!(
                accel.occluded(r, &mut NoCounters),
                want.is_hit(),
                "{name}, ray {i}: any hit"
            );
            if !want.is_hit() {
                continue;
            }
            hits += 1;
            assert_eq!(got.t, want.t, "{name}, ray {i}: got {got:?} want {want:?}");
            if got.tri != want.tri {
                // A tie: the other triangle is hit at the same t.
                let alt = tris[got.tri as usize].intersect(r.origin, r.dir, 0.0, f32::INFINITY);
                assert_eq!(alt.map(|h| h.t), Some(want.t), "{name}, ray {i}: not a tie");
            }
            let before = want.t * (1.0 - 1e-5);
            assert_eq!(
                accel.occluded(&r.within(0.0, before), &mut NoCounters),
                brute_force_occluded(&tris, &r.within(0.0, before)),
                "{name}, ray {i}: any hit before the closest"
            );
        }
        assert!(hits > 1000 && hits < 3900, "{name}: a varied ray set ({hits} hits)");
    }
}

/// Packets of 1-8 rays (`intersect_packet`, `occluded_packet`: the rays' walks interleaved)
/// give each ray the hit and the counts of its own walk (`intersect`, `occluded`), bit for
/// bit: coherent packets (rays from one point through neighbouring directions, as a block of
/// pixels), incoherent ones, per-ray `t_max` for the any-hit queries, and rays parallel to
/// slabs. With AVX2 the packets run its build, the single rays too; the lanes past a packet's
/// length are misses.
#[test]
fn packets_equal_single_rays() {
    use crate::accel::{PACKET, TraversalCounters};
    let mut rng = crate::util::Rng::new(0xB7_9AC4);
    let (positions, triangles) = random_mesh(&mut rng, 4000);
    let accel = BvhAccel::build(&tris_of(&positions, &triangles));
    let bits = |h: &Hit| (h.t.to_bits(), h.tri, h.u.to_bits(), h.v.to_bits());
    let (mut hits, mut blocked) = (0, 0);
    for round in 0..4000 {
        let n = 1 + round % PACKET;
        let rays: Vec<Ray> = if round % 2 == 0 {
            let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), -3.0);
            let d = Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), 1.0);
            (0..n)
                .map(|k| Ray::new(o, d + Vec3::new((k % 4) as f32, (k / 4) as f32, 0.0) * 0.002))
                .collect()
        } else {
            (0..n)
                .map(|_| {
                    let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
                    let mut d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
                    if rng.below(6) == 0 {
                        d[rng.below(3) as usize] = 0.0;
                    }
                    Ray::new(o, if d == Vec3::ZERO { Vec3::X } else { d })
                })
                .collect()
        };
        let t_max: [f32; PACKET] = std::array::from_fn(|_| rng.range(0.5, 6.0));
        let mut counted = vec![TraversalCounters::default(); n];
        let got = accel.intersect_packet(&rays, &mut counted);
        for (k, ray) in rays.iter().enumerate() {
            let mut c = TraversalCounters::default();
            let want = accel.intersect(ray, &mut c);
            assert_eq!(bits(&got[k]), bits(&want), "round {round}, ray {k}: closest hit");
            assert_eq!(counted[k], c, "round {round}, ray {k}: closest-hit counts");
            hits += want.is_hit() as usize;
        }
        assert!(
            got[n..].iter().all(|h| !h.is_hit()),
            "round {round}: lanes past the packet miss"
        );
        let mut counted = vec![TraversalCounters::default(); n];
        let got = accel.occluded_packet(&crate::testing::within_each(&rays, 0.0, &t_max), &mut counted);
        for (k, ray) in rays.iter().enumerate() {
            let mut c = TraversalCounters::default();
            let want = accel.occluded(&crate::testing::within(ray, 0.0, t_max[k]), &mut c);
            assert_eq!(got[k], want, "round {round}, ray {k}: any hit before {}", t_max[k]);
            assert_eq!(counted[k], c, "round {round}, ray {k}: any-hit counts");
            blocked += want as usize;
        }
        assert!(
            got[n..].iter().all(|&b| !b),
            "round {round}: lanes past the packet are clear"
        );
    }
    // Neither kind of answer is all one way: the comparison checks something.
    let rays = (0..4000).map(|r| 1 + r % PACKET).sum::<usize>();
    assert!(hits > rays / 10 && hits < rays * 9 / 10, "{hits} of {rays} rays hit");
    assert!(
        blocked > rays / 10 && blocked < rays * 9 / 10,
        "{blocked} of {rays} rays blocked"
    );
}
