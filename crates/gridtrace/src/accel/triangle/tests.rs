use super::*;
use crate::accel::lanes::{load3, splat3};
use crate::util::Rng;

/// Whether a lane's answer is the scalar test's: both misses, or both hits with the same
/// bits of t, u and v.
fn same_bits(want: Option<TriHit>, lane: Option<TriHit>) -> bool {
    match (want, lane) {
        (Some(w), Some(l)) => {
            w.t.to_bits() == l.t.to_bits() && w.u.to_bits() == l.u.to_bits() && w.v.to_bits() == l.v.to_bits()
        }
        (None, None) => true,
        _ => false,
    }
}

/// The four-lane test gives bit for bit what the scalar one gives, lane by lane: random
/// triangles (some slivers, some huge, some far away) and rays aimed at their edges, vertices
/// and interiors, from near and far, including grazing ones and limits on t.
#[test]
fn four_lanes_equal_the_scalar_test() {
    let mut rng = Rng::new(0x7E57);
    let point =
        |rng: &mut Rng, scale: f32| Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * scale;
    let (mut hits, mut edge_hits) = (0, 0);
    for round in 0..20_000 {
        let scale = [1.0, 1e-3, 1e3][round % 3];
        let offset = point(&mut rng, [0.0, 10.0, 1e4][round / 3 % 3]);
        let used = 1 + round % 4;
        let tris: Vec<TriAccel> = (0..used)
            .map(|k| {
                let a = offset + point(&mut rng, scale);
                let b = a + point(&mut rng, scale);
                // Every third triangle a sliver.
                let c = if k % 3 == 2 {
                    a + (b - a) * rng.range(0.0, 1.0) + point(&mut rng, scale * 1e-4)
                } else {
                    a + point(&mut rng, scale)
                };
                TriAccel::new(a, b, c)
            })
            .collect();
        let block = TriAccel4::pack(&tris);
        // Aim at a point of one of the triangles: inside, on an edge or at a vertex.
        let target_tri = tris[round % used].vertices();
        let (wu, wv) = match round % 4 {
            0 => (rng.range(0.0, 1.0), 0.0),
            1 => (1.0, 0.0),
            _ => (rng.range(0.0, 0.6), rng.range(0.0, 0.6)),
        };
        let target = target_tri[0] + (target_tri[1] - target_tri[0]) * wu + (target_tri[2] - target_tri[0]) * wv;
        // From 1 to 100,000 triangle sizes away: the far ones need the error-bound slack.
        let away = scale * 10f32.powf(rng.range(0.0, 5.0));
        let origin = target + point(&mut rng, 1.0).normalize_or(Vec3::X) * away;
        let dir = (target - origin) * rng.range(0.1, 10.0);
        let (t_min, t_max) = if round % 5 == 0 {
            (0.0, rng.range(0.0, 1.5))
        } else {
            (0.0, f32::INFINITY)
        };
        let o4 = origin.to_array().map(Vec4::splat);
        let d4 = dir.to_array().map(Vec4::splat);
        let got = block.intersect(&o4, &d4, t_min, t_max);
        for k in 0..4 {
            let want = tris.get(k).and_then(|t| t.intersect(origin, dir, t_min, t_max));
            let lane = (got.mask() >> k & 1 == 1).then(|| got.lane(k));
            let same = same_bits(want, lane);
            assert!(same, "round {round} lane {k}: scalar {want:?}, four lanes {lane:?}");
            hits += want.is_some() as u32;
            edge_hits += (want.is_some() && wv == 0.0) as u32;
        }
        assert_eq!(block.lane(round % used), tris[round % used]);
    }
    // The rays really exercise hits, edges included.
    assert!(hits > 10_000 && edge_hits > 3_000, "{hits} hits, {edge_hits} on edges");
}

/// The lane-parallel test as the packet walk calls it, one triangle in every lane and a
/// different ray per lane, each with its own `t_max`: every lane gives bit for bit what
/// the scalar test gives for its ray, four lanes (SSE) and, where the CPU has AVX2, eight
/// (AVX). Triangles of three sizes, near the origin and far from it; rays at edges,
/// vertices and interiors from 1 to 100,000 triangle sizes away, grazing ones included.
/// Every other round the lanes share lane 0's origin (a pinhole's packet), and where they
/// share their axes too the shared-frame test (`intersect_frame_cull`) gives the same bits.
#[test]
fn a_ray_per_lane_equals_the_scalar_test() {
    rays_per_lane::<4, Vec4>();
    if crate::accel::simd::has_wide() {
        // SAFETY: the CPU runs the eight-lane build, checked just above.
        unsafe { rays_per_lane_wide() };
    }
}

#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
unsafe fn rays_per_lane_wide() {
    rays_per_lane::<8, crate::accel::lanes::F8>();
}

#[inline(always)]
fn rays_per_lane<const N: usize, L: Lanes<N>>() {
    let mut rng = Rng::new(0x1A_7E5 + N as u64);
    let point =
        |rng: &mut Rng, scale: f32| Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * scale;
    let (mut hits, mut edge_hits, mut limited, mut framed) = (0, 0, 0, 0);
    for round in 0..10_000 {
        let scale = [1.0, 1e-3, 1e3][round % 3];
        let offset = point(&mut rng, [0.0, 10.0, 1e4][round / 3 % 3]);
        let a = offset + point(&mut rng, scale);
        let b = a + point(&mut rng, scale);
        let c = if round % 5 == 4 {
            // A sliver.
            a + (b - a) * rng.range(0.0, 1.0) + point(&mut rng, scale * 1e-4)
        } else {
            a + point(&mut rng, scale)
        };
        let tri = TriAccel::new(a, b, c);
        let (mut origin, mut dir, mut t_max, mut on_edge) = ([[0.0; N]; 3], [[0.0; N]; 3], [0.0; N], [false; N]);
        for k in 0..N {
            let (wu, wv) = match (round + k) % 4 {
                0 => (rng.range(0.0, 1.0), 0.0),
                1 => (1.0, 0.0),
                _ => (rng.range(0.0, 0.6), rng.range(0.0, 0.6)),
            };
            on_edge[k] = wv == 0.0;
            let target = a + (b - a) * wu + (c - a) * wv;
            let away = scale * 10f32.powf(rng.range(0.0, 5.0));
            let mut o = target + point(&mut rng, 1.0).normalize_or(Vec3::X) * away;
            // Every other round a pinhole's packet: every lane from lane 0's origin.
            if round % 2 == 1 && k > 0 {
                o = Vec3::new(origin[0][0], origin[1][0], origin[2][0]);
            }
            let d = (target - o) * rng.range(0.1, 10.0);
            for ax in 0..3 {
                origin[ax][k] = o[ax];
                dir[ax][k] = d[ax];
            }
            t_max[k] = if (round + k) % 5 == 0 {
                rng.range(0.0, 1.5)
            } else {
                f32::INFINITY
            };
        }
        let corners = (&splat3(tri.v0), &splat3(tri.v1), &splat3(tri.v2));
        let ray = LaneRay::new(&load3(origin), &load3(dir));
        let got = intersect_lanes::<N, L>(corners, &ray, 0.0, L::from_array(t_max));
        // Lanes sharing their frame: the translation once for all (the packet walk's route
        // for a pinhole's packets) gives the same bits.
        assert_eq!(ray.shared_frame().is_some(), round % 2 == 1 && ray.uniform.is_some());
        if let Some(frame) = ray.shared_frame() {
            let [c0, c1, c2] = frame.translate4(&TriAccel4::splat(&tri));
            // (Written out: a closure's `splat3` would not be compiled for AVX.)
            let rel = [
                splat3([c0[0][0], c0[1][0], c0[2][0]]),
                splat3([c1[0][0], c1[1][0], c1[2][0]]),
                splat3([c2[0][0], c2[1][0], c2[2][0]]),
            ];
            let framed_hits = intersect_frame_cull::<N, L, false>(rel, || tri, &ray, 0.0, L::from_array(t_max));
            for k in 0..N {
                let want = (got.mask() >> k & 1 == 1).then(|| got.lane(k));
                let lane = (framed_hits.mask() >> k & 1 == 1).then(|| framed_hits.lane(k));
                assert!(
                    same_bits(want, lane),
                    "{N} lanes, round {round} lane {k}: {want:?}, framed {lane:?}"
                );
            }
            framed += 1;
        }
        for k in 0..N {
            let o = Vec3::new(origin[0][k], origin[1][k], origin[2][k]);
            let d = Vec3::new(dir[0][k], dir[1][k], dir[2][k]);
            let want = tri.intersect(o, d, 0.0, t_max[k]);
            let lane = (got.mask() >> k & 1 == 1).then(|| got.lane(k));
            let same = same_bits(want, lane);
            assert!(
                same,
                "{N} lanes, round {round} lane {k}: scalar {want:?}, lanes {lane:?}"
            );
            hits += want.is_some() as u32;
            edge_hits += (want.is_some() && on_edge[k]) as u32;
            limited += (want.is_none() && t_max[k] < f32::INFINITY) as u32;
        }
    }
    // Hits, hits on edges and rays stopped by their own limit all occur.
    let rays = 10_000 * N as u32;
    assert!(
        hits > rays / 2 && edge_hits > rays / 8 && limited > rays / 50 && framed > 2_000,
        "{N} lanes: {hits} hits, {edge_hits} on edges, {limited} cut by t_max, of {rays}; {framed} rounds framed"
    );
}

/// No false hits, no misses inside (`testing::near_miss_rays`: head-on rays 1e-6 or more
/// beside an edge from 1 and 1e4 units, grazing ones at 1e-3 rad 1e-5 or more beside), and
/// a ray starting on the triangle hits at `t = 0`, but not with `t_min` above 0: the scalar
/// test and the four lanes alike. Möller-Trumbore with its barycentric slack hit at 1e-6
/// outside from 1 unit, and up to 1e-3 from 1e4 or grazing.
#[test]
fn near_misses_miss_and_near_hits_hit() {
    let tri = crate::testing::unit_triangle();
    let rays = crate::testing::near_miss_rays();
    for m in &rays {
        let (o, d) = (m.ray.origin, m.ray.dir);
        let scalar = tri.intersect(o, d, 0.0, f32::INFINITY);
        let four = TriAccel4::splat(&tri).intersect(
            &o.to_array().map(Vec4::splat),
            &d.to_array().map(Vec4::splat),
            0.0,
            f32::INFINITY,
        );
        assert_eq!(scalar.is_some(), m.hits, "{m:?}: {scalar:?}");
        assert_eq!(four.mask(), if m.hits { 0xf } else { 0 }, "{m:?}");
        if let Some(t) = m.t {
            // +0 exactly (never -0), in every lane too.
            assert_eq!(scalar.map(|h| h.t.to_bits()), Some(t.to_bits()), "{m:?}");
            assert!((0..4).all(|k| four.lane(k).t.to_bits() == t.to_bits()), "{m:?}");
            assert!(tri.intersect(o, d, 1e-30, f32::INFINITY).is_none(), "{m:?}");
        }
    }
    assert!(rays.len() > 1500, "{} rays", rays.len());
}

/// Watertight at shared edges and vertices, by construction: a fan of triangles around a
/// vertex (with exactly representable but irregular coordinates, seen from far away and
/// tilted), rays aimed exactly at the centre and at points of the shared edges: every ray
/// hits at least one triangle of the fan.
#[test]
fn rays_through_shared_edges_and_vertices_hit_a_neighbour() {
    let mut rng = Rng::new(0xFA7);
    for round in 0..2_000 {
        let scale = [1.0, 1e-3, 1e3][round % 3];
        let centre = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * scale * 10.0;
        let n = 5 + round % 4;
        let rim: Vec<Vec3> = (0..n)
            .map(|k| {
                let a = (k as f32 + rng.range(-0.3, 0.3)) / n as f32 * std::f32::consts::TAU;
                centre + Vec3::new(a.cos(), a.sin(), rng.range(-0.3, 0.3)) * scale * rng.range(0.5, 1.5)
            })
            .collect();
        let fan: Vec<TriAccel> = (0..n)
            .map(|k| TriAccel::new(centre, rim[k], rim[(k + 1) % n]))
            .collect();
        let k = round % n;
        // The centre, or a point of a spoke (short of the rim, where the fan ends).
        let target = if round % 2 == 0 {
            centre
        } else {
            centre + (rim[k] - centre) * rng.range(0.0, 0.95)
        };
        let away = scale * 10f32.powf(rng.range(0.0, 4.0));
        let dir = Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), -1.0);
        let origin = target - dir * away;
        let hit = fan
            .iter()
            .any(|t| t.intersect(origin, dir, 0.0, f32::INFINITY).is_some());
        assert!(
            hit,
            "round {round}: a ray at {target} from {origin} passed through the fan"
        );
    }
}
