//! The coherent packet walk (`coherent.rs`) gives every ray its single walk's answer, bit for
//! bit: coherent and incoherent packets, mixed direction signs, zero direction components,
//! `t` ranges, and exact ties between triangles (a plane of triangles hit through its shared
//! edges and vertices), directly and through the packet and batch queries.

use glam::Vec3;

use super::coherent::{coherent, transpose8};
use super::tests::{random_mesh, tris_of};
use super::*;
use crate::accel::simd::has_wide;
use crate::accel::{NoCounters, PACKET};
use crate::util::Rng;

fn bits(h: &Hit) -> (u32, u32, u32, u32) {
    (h.t.to_bits(), h.tri, h.u.to_bits(), h.v.to_bits())
}

/// The packet walk forced on `rays` (whatever `coherent` says), ties redone by the single walk
/// as the queries do; the closest hits as answered, and how many rays needed the redo.
fn forced(accel: &BvhAccel, rays: &[Ray], t_min: f32, t_max: [f32; PACKET]) -> (Vec<Hit>, Vec<bool>, u32) {
    let rays = crate::testing::within_each(rays, t_min, &t_max);
    // SAFETY: the callers checked that the CPU runs the eight-lane build.
    let closest = unsafe { accel.walk_coherent::<false>(&rays) };
    // SAFETY: as above.
    let any = unsafe { accel.walk_coherent::<true>(&rays) };
    assert_eq!(any.redo, 0, "any-hit answers have no ties");
    let hits = (0..rays.len())
        .map(|k| {
            if closest.redo >> k & 1 != 0 {
                accel.intersect(&crate::testing::within(&rays[k], t_min, t_max[k]), &mut NoCounters)
            } else {
                accel.result(&closest.best[k])
            }
        })
        .collect();
    let blocked = (0..rays.len()).map(|k| any.best[k].is_hit()).collect();
    (hits, blocked, closest.redo.count_ones())
}

/// Checks every ray of `rays` (any length up to `PACKET`) both ways; returns (hits, redone).
fn check(accel: &BvhAccel, rays: &[Ray], t_min: f32, t_max: [f32; PACKET], what: &str) -> (usize, u32) {
    let (got, blocked, redone) = forced(accel, rays, t_min, t_max);
    let mut hits = 0;
    for (k, ray) in rays.iter().enumerate() {
        let want = accel.intersect(&crate::testing::within(ray, t_min, t_max[k]), &mut NoCounters);
        assert_eq!(bits(&got[k]), bits(&want), "{what}, ray {k} {ray:?}: closest hit");
        let want_any = accel.occluded(&crate::testing::within(ray, t_min, t_max[k]), &mut NoCounters);
        assert_eq!(blocked[k], want_any, "{what}, ray {k} {ray:?}: any hit");
        hits += want.is_hit() as usize;
    }
    (hits, redone)
}

fn unit(rng: &mut Rng) -> Vec3 {
    loop {
        let d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        if d.length_squared() > 1e-4 {
            return d;
        }
    }
}

#[test]
fn transpose8_transposes() {
    let mut rng = Rng::new(0x7A);
    for _ in 0..1000 {
        let x = (rng.below(1 << 30) as u64) << 34 ^ (rng.below(1 << 30) as u64) << 17 ^ rng.below(1 << 30) as u64;
        let t = transpose8(x);
        for r in 0..8 {
            for c in 0..8 {
                assert_eq!(x >> (8 * r + c) & 1, t >> (8 * c + r) & 1, "{x:#x} bit ({r}, {c})");
            }
        }
    }
}

#[test]
fn coherent_packets_equal_single_rays_on_random_triangles() {
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: the packet walk does not run here");
        return;
    }
    let mut rng = Rng::new(0xC0_4E5E);
    let (positions, triangles) = random_mesh(&mut rng, 4000);
    let accel = BvhAccel::build(&tris_of(&positions, &triangles));
    let (mut hits, mut rays_in) = (0, 0);
    for round in 0..3000 {
        let n = 1 + round % PACKET;
        let rays: Vec<Ray> = match round % 4 {
            // A camera's block of pixels, from outside the mesh or inside it.
            0 => {
                let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-3.0, 0.0));
                let d = Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), 1.0);
                (0..n)
                    .map(|k| Ray::new(o, d + Vec3::new((k % 4) as f32, (k / 4) as f32, 0.0) * 0.002))
                    .collect()
            }
            // Mixed direction signs: a block straddling the axes (components of both signs
            // and exact zeros).
            1 => {
                let o = Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), -3.0);
                (0..n)
                    .map(|k| match k {
                        0 => Ray::new(o, Vec3::Z),
                        _ => Ray::new(
                            o,
                            Vec3::new(((k % 4) as f32 - 1.5) * 0.01, ((k / 4) as f32 - 0.5) * 0.01, 1.0),
                        ),
                    })
                    .collect()
            }
            // Incoherent: random origins and directions, some components zero.
            2 => (0..n)
                .map(|_| {
                    let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
                    let mut d = unit(&mut rng);
                    if rng.below(4) == 0 {
                        d[rng.below(3) as usize] = 0.0;
                    }
                    Ray::new(o, if d == Vec3::ZERO { Vec3::X } else { d })
                })
                .collect(),
            // Axis-parallel rays on a lattice (two components zero, some -0.0).
            _ => (0..n)
                .map(|k| {
                    let o = Vec3::new(rng.range(-1.0, 1.0), (k as f32) * 0.01, -3.0);
                    let d = if k % 2 == 0 { Vec3::Z } else { Vec3::new(-0.0, 0.0, 1.0) };
                    Ray::new(o, d)
                })
                .collect(),
        };
        // t ranges: from 0, or a window (some rays' `t_max` short of everything).
        let t_min = if round % 3 == 0 { rng.range(0.0, 2.0) } else { 0.0 };
        let t_max: [f32; PACKET] = std::array::from_fn(|_| {
            if round % 5 == 0 {
                f32::INFINITY
            } else {
                t_min + rng.range(0.0, 6.0)
            }
        });
        hits += check(&accel, &rays, t_min, t_max, &format!("round {round}")).0;
        rays_in += n;
    }
    assert!(
        hits > rays_in / 10 && hits < rays_in * 9 / 10,
        "{hits} of {rays_in} rays hit"
    );
}

/// A plane of triangles (two per square of a lattice) hit through its vertices and edges: the
/// same `t` from several triangles, where the single walk keeps the one it meets first. The
/// packet walk must hand those rays back to the single walk (and does: some are redone).
#[test]
fn coherent_packets_break_ties_as_single_rays() {
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: the packet walk does not run here");
        return;
    }
    let side = 40;
    let mut positions = Vec::new();
    for y in 0..=side {
        for x in 0..=side {
            positions.push(Vec3::new(x as f32 / side as f32, y as f32 / side as f32, 0.5));
        }
    }
    let at = |x: u32, y: u32| y * (side + 1) + x;
    let mut triangles = Vec::new();
    for y in 0..side {
        for x in 0..side {
            triangles.push([at(x, y), at(x + 1, y), at(x + 1, y + 1)]);
            triangles.push([at(x, y), at(x + 1, y + 1), at(x, y + 1)]);
        }
    }
    let accel = BvhAccel::build(&tris_of(&positions, &triangles));
    let mut rng = Rng::new(0x71E5);
    let (mut redone, mut hits) = (0, 0);
    for round in 0..2000 {
        // Eight parallel rays down the z axis through lattice vertices, edge midpoints and
        // diagonals, from a shared row (coherent), or from a point above (a camera).
        let (gx, gy) = (rng.below(side - 2), rng.below(side - 2));
        let rays: Vec<Ray> = (0..PACKET as u32)
            .map(|k| {
                let x = (gx as f32 + (k % 4) as f32 * 0.5) / side as f32;
                let y = (gy as f32 + (k / 4) as f32 * 0.5) / side as f32;
                if round % 2 == 0 {
                    Ray::new(Vec3::new(x, y, 0.0), Vec3::Z)
                } else {
                    let eye = Vec3::new(0.5, 0.5, -1.0);
                    Ray::new(eye, Vec3::new(x, y, 0.5) - eye)
                }
            })
            .collect();
        let (h, r) = check(
            &accel,
            &rays,
            0.0,
            [f32::INFINITY; PACKET],
            &format!("tie round {round}"),
        );
        hits += h;
        redone += r;
    }
    assert!(hits > 2000 * PACKET * 9 / 10, "the rays hit the plane: {hits}");
    assert!(
        redone > 0,
        "some rays met exact ties (and were redone by the single walk)"
    );
}

/// The queries take the packet route where a group looks coherent (camera rays do, random
/// rays do not) and answer as the single walk: the batch queries on a camera's rays in image
/// order and on random rays, and the packet queries without counters.
#[test]
fn batches_and_packets_take_the_coherent_walk_with_single_ray_answers() {
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: the packet walk does not run here");
        return;
    }
    let mut rng = Rng::new(0xBA7C);
    let (positions, triangles) = random_mesh(&mut rng, 3000);
    let accel = BvhAccel::build(&tris_of(&positions, &triangles));
    let eye = Vec3::new(0.3, -0.2, -4.0);
    let (w, h) = (96, 64);
    let camera: Vec<Ray> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32 / w as f32 - 0.5, (i / w) as f32 / h as f32 - 0.5);
            Ray::new(eye, Vec3::new(x * 0.8, y * 0.6, 1.0))
        })
        .collect();
    let random: Vec<Ray> = (0..4000)
        .map(|_| {
            Ray::new(
                Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0)),
                unit(&mut rng),
            )
        })
        .collect();
    let extent = accel.extent();
    let coherent_groups = camera.chunks(PACKET).filter(|g| coherent(g, extent)).count();
    assert_eq!(
        coherent_groups,
        camera.len() / PACKET,
        "a camera's rows are coherent groups"
    );
    let random_groups = random.chunks(PACKET).filter(|g| coherent(g, extent)).count();
    assert_eq!(random_groups, 0, "random rays are not");
    for (rays, what) in [(&camera, "camera"), (&random, "random")] {
        for (t_min, t_max) in [(0.0, f32::INFINITY), (3.5, 4.5)] {
            let mut got = vec![Hit::MISS; rays.len()];
            accel.intersect_batch(&crate::testing::within(rays, t_min, t_max), &mut got);
            let mut blocked = vec![false; rays.len()];
            accel.occluded_batch(&crate::testing::within(rays, t_min, t_max), &mut blocked);
            let mut each = vec![(Hit::MISS, Vec3::NAN); rays.len()];
            accel.intersect_batch_each(&crate::testing::within(rays, t_min, t_max), |i, hit, normal| {
                each[i] = (hit, normal)
            });
            for (i, ray) in rays.iter().enumerate() {
                let want = accel.intersect(&crate::testing::within(ray, t_min, t_max), &mut NoCounters);
                assert_eq!(bits(&got[i]), bits(&want), "{what} batch ray {i}");
                assert_eq!(bits(&each[i].0), bits(&want), "{what} batch_each ray {i}");
                assert_eq!(
                    blocked[i],
                    accel.occluded(&crate::testing::within(ray, t_min, t_max), &mut NoCounters),
                    "{what} any ray {i}"
                );
            }
            let hit = got.iter().filter(|h| h.is_hit()).count();
            assert!(
                hit > 0 && hit < rays.len(),
                "{what} [{t_min}, {t_max}]: {hit} of {} hit",
                rays.len()
            );
        }
        for (p, packet) in rays.chunks(PACKET).enumerate() {
            let mut none = vec![NoCounters; packet.len()];
            let got = accel.intersect_packet(packet, &mut none);
            let t_max: [f32; PACKET] = std::array::from_fn(|k| 3.0 + k as f32 * 0.25);
            let blocked = accel.occluded_packet(&crate::testing::within_each(packet, 0.0, &t_max), &mut none);
            for (k, ray) in packet.iter().enumerate() {
                let want = accel.intersect(ray, &mut NoCounters);
                assert_eq!(bits(&got[k]), bits(&want), "{what} packet {p} ray {k}");
                assert_eq!(
                    blocked[k],
                    accel.occluded(&crate::testing::within(ray, 0.0, t_max[k]), &mut NoCounters),
                    "{what} packet {p} any {k}"
                );
            }
        }
    }
}

/// The packet's interval box test lets in every box any of its rays' own tests lets in, at
/// an entry distance no later than that ray's: random nodes (flat, point and empty boxes),
/// packets of rays near one ray (same direction signs, some components tiny or zero), every
/// ray's own search distance.
#[test]
fn interval_test_is_conservative_ray_by_ray() {
    use super::box_test::BoxRay;
    use super::interval::Interval;
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: the packet walk does not run here");
        return;
    }
    let mut rng = Rng::new(0x1A7E);
    let (mut entered, mut checked) = (0, 0);
    for round in 0..20_000 {
        let (node, ray, t_min, t_max) = super::tests::random_node_and_ray(&mut rng, round);
        let spread = [1e-4, 1e-2, 0.3][round % 3];
        let rays: Vec<Ray> = (0..PACKET)
            .map(|k| {
                let jitter =
                    |rng: &mut Rng| Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
                let o = ray.origin + jitter(&mut rng) * spread * (k > 0) as u32 as f32;
                let mut d = ray.dir + jitter(&mut rng) * spread * (k > 0) as u32 as f32;
                if round % 7 == 0 {
                    d[k % 3] = 0.0;
                }
                Ray::new(o, d)
            })
            .collect();
        let boxes: Vec<BoxRay> = rays.iter().map(BoxRay::new).collect();
        let Some(iv) = Interval::new(&boxes) else { continue };
        let reach: [f32; PACKET] = std::array::from_fn(|k| if k % 2 == 0 { t_max } else { t_max * 0.5 });
        let widest = reach.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        // SAFETY: the CPU runs the eight-lane build, checked above.
        let (t_iv, m_iv) = unsafe { iv.enter_for_test(&node, t_min, widest) };
        for (k, b) in boxes.iter().enumerate() {
            // SAFETY: as above.
            let (t, m) = unsafe { b.enter_wide_arrays(&node, t_min, reach[k]) };
            assert_eq!(m & !m_iv, 0, "round {round}, ray {k}: a box the ray enters is culled");
            for slot in super::coherent::bit_iter(m) {
                assert!(t_iv[slot] <= t[slot], "round {round}, ray {k}, box {slot}: later entry");
            }
            entered += m.count_ones();
            checked += 1;
        }
    }
    assert!(
        checked > 50_000 && entered > 50_000,
        "{checked} rays, {entered} boxes entered"
    );
}

/// The near-miss family (`testing::near_miss_rays`) as a pinhole's packets through the packet
/// walk, which then takes the shared-frame route (`triangle::SharedFrame`): eight rays from one
/// origin 1 or 1e4 units above or below the unit triangle, each aimed at a point 1e-6 to 1e-3
/// outside an edge (all must miss) or as far inside (all must hit); and rays starting on the
/// triangle, a packet per origin (hit at `t = 0`). Every answer is also the single walk's, bit
/// for bit.
#[test]
fn pinhole_packets_near_edges_miss_and_hit_as_aimed() {
    if !has_wide() {
        eprintln!("no eight-lane build on this CPU: the packet walk does not run here");
        return;
    }
    let unit = crate::testing::unit_triangle();
    // The unit triangle among two others, so that the walk has a leaf of several triangles.
    let moved = |by: Vec3| {
        let [a, b, c] = unit.vertices();
        TriAccel::new(a + by, b + by, c + by)
    };
    let accel = BvhAccel::build(&[moved(Vec3::new(3.0, 0.0, 0.0)), unit, moved(Vec3::new(0.0, 3.0, 0.0))]);
    let unit_id = 1;
    let rays = crate::testing::near_miss_rays();
    // Head-on rays name their aim point (x, y on the plane) and their side and distance.
    let mut groups: std::collections::BTreeMap<(bool, i32, bool), Vec<Vec3>> = Default::default();
    for m in rays
        .iter()
        .filter(|m| m.t.is_none() && m.ray.dir.x == 0.0 && m.ray.dir.y == 0.0)
    {
        let o = m.ray.origin;
        groups
            .entry((m.hits, o.z as i32, o.z > 0.0))
            .or_default()
            .push(Vec3::new(o.x, o.y, 0.0));
    }
    let (mut packets, mut rays_in) = (0, 0);
    for ((hits, z, _), targets) in &groups {
        let origin = Vec3::new(0.3, 0.3, *z as f32);
        for aims in targets.chunks(PACKET) {
            let packet: Vec<Ray> = aims.iter().map(|&t| Ray::new(origin, t - origin)).collect();
            let (got, blocked, _) = forced(&accel, &packet, 0.0, [f32::INFINITY; PACKET]);
            for (k, ray) in packet.iter().enumerate() {
                assert_eq!(got[k].is_hit(), *hits, "ray {ray:?} (aimed {}): {:?}", aims[k], got[k]);
                assert_eq!(blocked[k], *hits, "ray {ray:?}: any hit");
                if *hits {
                    assert_eq!(got[k].tri, unit_id, "ray {ray:?}");
                }
            }
            check(&accel, &packet, 0.0, [f32::INFINITY; PACKET], "near-miss packet");
            packets += 1;
            rays_in += packet.len();
        }
    }
    // Rays starting on the triangle: one packet per origin, each ray hitting at +0.
    let mut starts: std::collections::BTreeMap<[u32; 3], Vec<Ray>> = Default::default();
    for m in rays.iter().filter(|m| m.t.is_some()) {
        starts
            .entry(m.ray.origin.to_array().map(f32::to_bits))
            .or_default()
            .push(m.ray);
    }
    for packet in starts.values() {
        let (got, _, _) = forced(&accel, packet, 0.0, [f32::INFINITY; PACKET]);
        for (k, h) in got.iter().enumerate() {
            assert_eq!((h.tri, h.t.to_bits()), (unit_id, 0), "ray {:?}", packet[k]);
        }
        check(&accel, packet, 0.0, [f32::INFINITY; PACKET], "start packet");
        packets += 1;
    }
    assert!(
        packets > 100 && rays_in > 1000,
        "{packets} packets, {rays_in} head-on rays"
    );
}

/// The packet route's second test (`footprint::narrow`): a camera near the mesh keeps its
/// packets, the same camera far away (its rows within `coherent`'s cone, its pixels many
/// leaves apart at the mesh) walks them singly, and a camera inside the scene's box keeps
/// them; the batch answers are the single walks' every time.
#[test]
fn far_cameras_walk_singly_with_single_ray_answers() {
    let mut rng = Rng::new(0xFA12);
    let (positions, triangles) = random_mesh(&mut rng, 3000);
    let accel = BvhAccel::build(&tris_of(&positions, &triangles));
    let root = &accel.bvh.nodes[0];
    let (lo, hi) = (Vec3::from(root.min), Vec3::from(root.max));
    assert!(accel.leaf_size > 0.0 && accel.leaf_size < (hi - lo).length());
    let (w, h) = (64, 48);
    // A pinhole at `eye` looking along +z, `fov` the image's width over its distance.
    let camera = |eye: Vec3, fov: f32| -> Vec<Ray> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 / w as f32 - 0.5, (i / w) as f32 / h as f32 - 0.5);
                Ray::new(eye, Vec3::new(x * fov, y * fov * 0.75, 1.0))
            })
            .collect()
    };
    let centre = (lo + hi) * 0.5;
    let extent = accel.extent();
    // Far: a packet's eight pixels (seven steps of `fov / w`) three times the allowed
    // footprint apart where they reach the box (the mesh then spans about four pixels).
    let (far_fov, step) = (0.05, 7.0 * 0.05 / w as f32);
    let far = 3.0 * super::footprint::FOOTPRINT_LEAVES * accel.leaf_size / step + extent;
    for (eye, fov, want_narrow) in [
        (centre - Vec3::Z * extent, 0.8, true),
        (centre - Vec3::Z * far, far_fov, false),
        (centre, 0.8, true),
    ] {
        let rays = camera(eye, fov);
        let groups: Vec<&[Ray; PACKET]> = rays.chunks(PACKET).map(|g| g.try_into().unwrap()).collect();
        assert!(
            groups.iter().all(|g| coherent(&g[..], extent)),
            "eye {eye}: in the cone"
        );
        let cos_sq = super::footprint::cone_cos_sq(eye, lo, hi, accel.leaf_size);
        let narrow = groups
            .iter()
            .filter(|g| super::coherent::coherent_within(&g[..], extent, cos_sq))
            .count();
        let want = if want_narrow { groups.len() } else { 0 };
        assert_eq!(narrow, want, "eye {eye}, fov {fov}: narrow packets");
        let mut got = vec![Hit::MISS; rays.len()];
        accel.intersect_batch(&rays, &mut got);
        let mut blocked = vec![false; rays.len()];
        accel.occluded_batch(&rays, &mut blocked);
        for (i, ray) in rays.iter().enumerate() {
            let want = accel.intersect(ray, &mut NoCounters);
            assert_eq!(bits(&got[i]), bits(&want), "eye {eye} ray {i}");
            assert_eq!(blocked[i], want.is_hit(), "eye {eye} any ray {i}");
        }
        let hit = got.iter().filter(|h| h.is_hit()).count();
        assert!(hit > 0, "eye {eye}: {hit} hit");
    }
}
