//! Tests of the batch queries beside the ray walks: the counting walk and the interleaved
//! nearest-point searches, against the single-ray (single-point) walks and brute force.

use super::tests::{random_mesh, tris_of};
use super::*;

/// The counting walk (`count_hits_batch`, rays interleaved) gives each ray the number of hits
/// brute force finds (`all_hits_brute`) and the listing walk lists, in its AVX2 build and its
/// baseline build, for whole and clipped `t` intervals, on a mesh where rays cross many
/// triangles (so that counts above one are common).
#[test]
fn counting_equals_listing_and_brute_force() {
    use crate::accel::contract::all_hits_brute;
    let mut rng = crate::util::Rng::new(0xC0_047);
    let (positions, triangles) = random_mesh(&mut rng, 8000);
    let tris = tris_of(&positions, &triangles);
    let accel = BvhAccel::build(&tris);
    let rays: Vec<Ray> = (0..3000)
        .map(|_| {
            let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
            let mut d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            if rng.below(6) == 0 {
                d[rng.below(3) as usize] = 0.0;
            }
            Ray::new(o, if d == Vec3::ZERO { Vec3::Z } else { d })
        })
        .collect();
    let (mut many, mut hits) = (0, Vec::new());
    for (t_min, t_max) in [(0.0, f32::INFINITY), (0.5, 2.5)] {
        let mut counted = vec![u32::MAX; rays.len()];
        accel.count_hits_batch(&crate::testing::within(&rays, t_min, t_max), &mut counted);
        let mut baseline = vec![u32::MAX; rays.len()];
        accel.count_hits_body::<false>(&crate::testing::within(&rays, t_min, t_max), &mut baseline);
        for (i, r) in rays.iter().enumerate() {
            hits.clear();
            all_hits_brute(&tris, &crate::testing::within(r, t_min, t_max), &mut hits);
            let want = hits.len() as u32;
            hits.clear();
            accel.all_hits(&crate::testing::within(r, t_min, t_max), &mut hits);
            assert_eq!(hits.len() as u32, want, "ray {i}: listed");
            assert_eq!(counted[i], want, "ray {i} in ({t_min}, {t_max}): counted");
            assert_eq!(baseline[i], want, "ray {i} in ({t_min}, {t_max}): counted (baseline)");
            many += (want > 1) as usize;
        }
    }
    assert!(many > 500, "only {many} rays cross more than one triangle");
    // An empty batch counts nothing and touches nothing.
    accel.count_hits_batch(&[], &mut []);
}

/// The interleaved nearest-point searches (`closest_points_batch`) give each point the answer
/// of its own search (`closest_point`) and of brute force, bit for bit: points near and far,
/// inside the mesh's box and outside, and points that are not finite (answered `INVALID` in
/// place, the searches around them unaffected).
#[test]
fn closest_point_batches_equal_single_searches_and_brute_force() {
    use crate::accel::closest::closest_point_brute;
    let mut rng = crate::util::Rng::new(0xC105E);
    let (positions, triangles) = random_mesh(&mut rng, 2000);
    let tris = tris_of(&positions, &triangles);
    let accel = BvhAccel::build(&tris);
    let mut points: Vec<[f32; 3]> = (0..1500)
        .map(|i| {
            let s = if i % 3 == 0 { 4.0 } else { 1.2 };
            [rng.range(-s, s), rng.range(-s, s), rng.range(-s, s)]
        })
        .collect();
    points[7] = [f32::NAN, 0.0, 0.0];
    points[8] = [0.0, f32::INFINITY, 0.0];
    let (got, interleaved) = both_batches(&accel, &points);
    for (i, (p, g)) in points.iter().zip(&got).enumerate() {
        let p = Vec3::from(*p);
        assert_eq!(
            bits(g),
            bits(&accel.closest_point(p)),
            "point {i}: batch against single"
        );
        assert_eq!(bits(g), bits(&interleaved[i]), "point {i}: packets against interleaved");
        let truth = closest_point_brute(&tris, p);
        assert_eq!(
            (g.tri, g.dist_sq.to_bits()),
            (truth.tri, truth.dist_sq.to_bits()),
            "point {i}: against brute force"
        );
    }
    assert!(
        got[7].dist_sq.is_nan() && got[8].tri == u32::MAX,
        "non-finite points are INVALID"
    );
}

/// A batch's searches bounded by their neighbours' answers (`PointWalk::seed`) where the bound
/// is tightest: points on the mesh (its vertices, points inside faces), each twice in a row
/// (a bound of 0: no seed), and the same points moved by a few ulps, so that a neighbour's
/// answer is within rounding of the point's own. Every answer is the lone search's and brute
/// force's, bit for bit: a bound that rounding put just short finds nothing and is searched
/// again.
#[test]
fn closest_point_batches_bounded_by_neighbours_at_the_surface() {
    use crate::accel::closest::{ClosestPoint, closest_point_brute};
    let mut rng = crate::util::Rng::new(0x5EED);
    let (positions, triangles) = random_mesh(&mut rng, 1500);
    let tris = tris_of(&positions, &triangles);
    let accel = BvhAccel::build(&tris);
    let mut points: Vec<[f32; 3]> = Vec::new();
    for (k, t) in tris.iter().enumerate().take(400) {
        let (u, v) = (rng.range(0.0, 0.5), rng.range(0.0, 0.5));
        let on_face =
            Vec3::from(t.v0) + (Vec3::from(t.v1) - Vec3::from(t.v0)) * u + (Vec3::from(t.v2) - Vec3::from(t.v0)) * v;
        let nudge = |p: Vec3, k: usize| {
            p.to_array()
                .map(|x| f32::from_bits(x.to_bits().wrapping_add(k as u32 % 5)))
        };
        for p in [Vec3::from(t.v0), on_face] {
            points.extend([p.to_array(), p.to_array(), nudge(p, k + 1), nudge(p, k + 3)]);
        }
    }
    let mut got = vec![ClosestPoint::NONE; points.len()];
    accel.closest_points_batch(&points, &mut got);
    for (i, (p, g)) in points.iter().zip(&got).enumerate() {
        let p = Vec3::from(*p);
        let lone = accel.closest_point(p);
        assert_eq!(
            (g.tri, g.dist_sq.to_bits(), g.u.to_bits(), g.v.to_bits()),
            (lone.tri, lone.dist_sq.to_bits(), lone.u.to_bits(), lone.v.to_bits()),
            "point {i}: batch against single"
        );
        let truth = closest_point_brute(&tris, p);
        assert_eq!(
            (g.tri, g.dist_sq.to_bits()),
            (truth.tri, truth.dist_sq.to_bits()),
            "point {i}: brute force"
        );
    }
}

/// Packets of nearest-point searches (`closest_packet.rs`) at degenerate triangles: zero-area
/// ones (a point, a segment, three collinear vertices) and slivers among ordinary ones, with
/// points around and on them. Every answer is the lone search's and the interleaved batch's,
/// bit for bit.
#[test]
fn closest_point_packets_at_degenerate_triangles() {
    let mut rng = crate::util::Rng::new(0xDE6E);
    let (positions, triangles) = random_mesh(&mut rng, 600);
    let mut tris = tris_of(&positions, &triangles);
    for _ in 0..200 {
        let a = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let d = Vec3::new(rng.range(-0.1, 0.1), rng.range(-0.1, 0.1), rng.range(-0.1, 0.1));
        let off = Vec3::splat(rng.range(-1e-7, 1e-7));
        tris.extend([
            TriAccel::new(a, a, a),
            TriAccel::new(a, a + d, a + d),
            TriAccel::new(a, a + d, a + d * 2.0),
            TriAccel::new(a, a + d, a + d * 0.5 + off),
        ]);
    }
    let accel = BvhAccel::build(&tris);
    let mut points: Vec<[f32; 3]> = (0..800)
        .map(|_| [rng.range(-1.3, 1.3), rng.range(-1.3, 1.3), rng.range(-1.3, 1.3)])
        .collect();
    points.extend(tris.iter().rev().take(200).map(|t| t.v1));
    let (got, interleaved) = both_batches(&accel, &points);
    for (i, p) in points.iter().enumerate() {
        let lone = accel.closest_point(Vec3::from(*p));
        assert_eq!(bits(&got[i]), bits(&lone), "point {i}: batch against single");
        assert_eq!(
            bits(&interleaved[i]),
            bits(&lone),
            "point {i}: interleaved against single"
        );
    }
}

/// The nearest points of `points` by `closest_points_batch` (packets where the CPU has AVX2)
/// and by the interleaved per-point batch.
fn both_batches(
    accel: &BvhAccel,
    points: &[[f32; 3]],
) -> (
    Vec<crate::accel::closest::ClosestPoint>,
    Vec<crate::accel::closest::ClosestPoint>,
) {
    use crate::accel::closest::ClosestPoint;
    let mut got = vec![ClosestPoint::NONE; points.len()];
    accel.closest_points_batch(points, &mut got);
    let mut interleaved = vec![ClosestPoint::NONE; points.len()];
    accel.closest_points_interleaved(points, &mut interleaved);
    (got, interleaved)
}

/// Every field of a nearest point as bits, for answers that must be equal bit for bit.
fn bits(c: &crate::accel::closest::ClosestPoint) -> ([u32; 3], u32, u32, u32, u32) {
    (
        c.point.to_array().map(f32::to_bits),
        c.dist_sq.to_bits(),
        c.tri,
        c.u.to_bits(),
        c.v.to_bits(),
    )
}
