//! The build's invariants, checked exhaustively on small random scenes, and traversal against
//! brute force (the integration tests in tests/traversal.rs run it on every scene too).

use glam::{UVec3, Vec3};

use super::{IrregularGrid, IrregularParams};
use crate::accel::tri_box::triangle_overlaps_box;
use crate::accel::{Hit, NoCounters, Ray, TriAccel, brute_force_intersect, brute_force_occluded};
use crate::util::Rng;

/// Clustered triangles in a large empty box: dense spots, empty space, shared references.
fn clusters(n: usize, seed: u64) -> Vec<TriAccel> {
    let mut rng = Rng::new(seed);
    let centres: Vec<Vec3> = (0..4)
        .map(|_| Vec3::new(rng.range(0.0, 10.0), rng.range(0.0, 10.0), rng.range(0.0, 10.0)))
        .collect();
    let mut tris: Vec<TriAccel> = (0..n)
        .map(|i| {
            let c = centres[i % centres.len()];
            let p = c + Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), rng.range(-0.5, 0.5));
            let mut q = || p + Vec3::new(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2), rng.range(-0.2, 0.2));
            TriAccel::new(p, q(), q())
        })
        .collect();
    // Two far corners and a long sliver, so the grid is large and mostly empty.
    tris.push(TriAccel::new(
        Vec3::ZERO,
        Vec3::new(0.1, 0.0, 0.0),
        Vec3::new(0.0, 0.1, 0.0),
    ));
    tris.push(TriAccel::new(
        Vec3::splat(10.0),
        Vec3::new(9.9, 10.0, 10.0),
        Vec3::new(10.0, 9.9, 10.0),
    ));
    tris.push(TriAccel::new(
        Vec3::new(0.0, 5.0, 5.0),
        Vec3::new(10.0, 5.0, 5.05),
        Vec3::new(10.0, 5.02, 5.0),
    ));
    tris
}

fn params() -> [IrregularParams; 3] {
    let d = IrregularParams::default();
    [
        d,
        // No merging or expansion: the plain two-level grid.
        IrregularParams {
            merge_passes: 0,
            expand_passes: 0,
            ..d
        },
        // Fine cells, merging of different sets.
        IrregularParams {
            top_density: 0.5,
            cell_density: 8.0,
            merge_alpha: 1.5,
            ..d
        },
    ]
}

fn voxel_box(g: &IrregularGrid, b: [UVec3; 2], grow: Vec3) -> (Vec3, Vec3) {
    let lo = g.bounds.min + b[0].as_vec3() * g.voxel_size;
    let hi = g.bounds.min + b[1].as_vec3() * g.voxel_size;
    ((lo + hi) * 0.5, (hi - lo) * 0.5 + grow)
}

#[test]
fn build_invariants() {
    for (k, p) in params().into_iter().enumerate() {
        let tris = clusters(400, 11 + k as u64);
        let g = IrregularGrid::build(&tris, p).unwrap();
        let dims = g.voxel_dims();
        assert_eq!(g.cell_count(), g.partition.len());
        assert_eq!(
            g.cells.last().map(|c| c.start as usize),
            Some(g.refs.len()),
            "the sentinel"
        );
        let grown = (0..g.cell_count() as u32)
            .map(|c| g.cell(c))
            .zip(&g.partition)
            .filter(|(c, b)| UVec3::from(c.max) - UVec3::from(c.min) != b[1] - b[0])
            .count();
        eprintln!("params {k}: {:?}, {grown} cells grown", g.stats);
        assert!(grown > 0 || p.expand_passes == 0);
        assert!(
            g.stats.cells < g.stats.initial_cells || p.merge_passes == 0,
            "{:?}",
            g.stats
        );
        // The cells' own boxes partition the virtual grid: every voxel's cell holds it, and the
        // volumes add up to the grid's.
        let volume: u64 = g
            .partition
            .iter()
            .map(|b| (b[1] - b[0]).as_u64vec3().element_product())
            .sum();
        assert_eq!(volume, dims.as_u64vec3().element_product(), "params {k}");
        for z in 0..dims.z {
            for y in 0..dims.y {
                for x in 0..dims.x {
                    let v = UVec3::new(x, y, z);
                    let c = g.cell_at(v.to_array()) as usize;
                    let [lo, hi] = g.partition[c];
                    assert!(v.cmpge(lo).all() && v.cmplt(hi).all(), "voxel {v} not in its cell {c}");
                    // The grown box holds the cell's own.
                    let cell = g.cell(c as u32);
                    assert!(
                        UVec3::from(cell.min).cmple(lo).all() && UVec3::from(cell.max).cmpge(hi).all(),
                        "cell {c}"
                    );
                }
            }
        }
        for (i, cell) in (0..g.cell_count() as u32).map(|c| g.cell(c)).enumerate() {
            let (gmin, gmax) = (UVec3::from(cell.min), UVec3::from(cell.max));
            for z in gmin.z..gmax.z {
                for y in gmin.y..gmax.y {
                    for x in gmin.x..gmax.x {
                        let other = g.cell_at([x, y, z]) as usize;
                        assert!(
                            other == i || g.cell(other as u32).count == 0,
                            "params {k}: cell {i} grown over non-empty cell {other}"
                        );
                    }
                }
            }
        }
        // Every triangle that overlaps a cell's own box (exact test, no margin) is in its list.
        for (i, b) in g.partition.iter().enumerate() {
            let refs = g.cell_refs(i as u32);
            assert!(refs.windows(2).all(|w| w[0] < w[1]));
            let (centre, half) = voxel_box(&g, *b, Vec3::ZERO);
            for (t, tri) in tris.iter().enumerate() {
                let [a, bb, c] = tri.vertices();
                if triangle_overlaps_box(centre, half, a, bb, c) {
                    assert!(refs.contains(&(t as u32)), "params {k}: cell {i} misses triangle {t}");
                }
            }
        }
    }
}

#[test]
fn traversal_equals_brute_force() {
    let tris = clusters(2000, 5);
    let mut rng = Rng::new(99);
    for p in params() {
        let g = IrregularGrid::build(&tris, p).unwrap();
        for i in 0..20_000 {
            // Rays from outside and inside, towards the clusters or anywhere; some axis-aligned.
            let o = Vec3::new(rng.range(-3.0, 13.0), rng.range(-3.0, 13.0), rng.range(-3.0, 13.0));
            let mut d = if i % 2 == 0 {
                tris[rng.below(tris.len() as u32) as usize].vertices()[0] - o
            } else {
                Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0))
            };
            if i % 7 == 0 {
                d.x = 0.0;
            }
            if i % 11 == 0 {
                d.y = 0.0;
            }
            let r = Ray::new(o, d);
            let want = brute_force_intersect(&tris, &r);
            let got: Hit = g.intersect(&tris, &r, &mut NoCounters);
            assert_eq!(got.is_hit(), want.is_hit(), "{r:?} got {got:?} want {want:?}");
            if want.is_hit() {
                assert!(
                    (got.t - want.t).abs() <= 1e-6 * want.t,
                    "{r:?} got {got:?} want {want:?}"
                );
                let t_max = want.t * 0.999;
                assert_eq!(
                    g.occluded(&tris, &crate::testing::within(&r, 0.0, t_max), &mut NoCounters),
                    brute_force_occluded(&tris, &crate::testing::within(&r, 0.0, t_max))
                );
            }
            assert_eq!(g.occluded(&tris, &r, &mut NoCounters), want.is_hit());
        }
    }
}

/// Packets give each ray exactly what its single-ray walk gives (the same closest hit, bit for
/// bit, or the same any-hit answer, and the same cells and triangle tests): coherent 4x2
/// blocks of camera rays from inside and outside the grid, with t limits; incoherent packets;
/// axis-aligned and zero components; rays that miss the grid; packets of one to eight rays;
/// eight lanes (AVX2, where the CPU has it) and two packets of four (the fallback) alike.
#[test]
fn packets_equal_single_rays() {
    use crate::accel::{PACKET, TraversalCounters};
    let tris = clusters(2000, 17);
    let mut rng = Rng::new(4242);
    let mut multi_hit = 0;
    for p in params() {
        let g = IrregularGrid::build(&tris, p).unwrap();
        for i in 0..6_000 {
            let n = 1 + i % PACKET;
            let eye = Vec3::new(rng.range(-3.0, 13.0), rng.range(-3.0, 13.0), rng.range(-3.0, 13.0));
            let target = tris[rng.below(tris.len() as u32) as usize].vertices()[0];
            let pixel = [0.0, 1e-3, 2e-2][i % 3];
            let rays: Vec<Ray> = (0..n)
                .map(|k| {
                    // By `i / PACKET`, not `i`: incoherent packets of every length, one to eight.
                    let mut d = match (i / PACKET) % 4 {
                        // Incoherent: each ray its own origin and direction.
                        3 => Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)),
                        // A 4x2 block of a camera: the same eye, directions a pixel apart.
                        _ => (target - eye).normalize() + Vec3::new((k % 4) as f32, (k / 4) as f32, 0.0) * pixel,
                    };
                    if (i + k) % 7 == 0 {
                        d.x = 0.0;
                    }
                    if (i + k) % 13 == 0 {
                        d.y = 0.0;
                        d.z = 0.0;
                    }
                    let o = if (i / PACKET) % 4 == 3 {
                        Vec3::new(rng.range(-3.0, 13.0), rng.range(-3.0, 13.0), rng.range(-3.0, 13.0))
                    } else {
                        eye
                    };
                    Ray::new(o, d)
                })
                .collect();
            let (t_min, t_max) = [(0.0, f32::INFINITY), (0.5, 6.0), (0.0, 1.0)][i % 3];
            let mut counted = vec![TraversalCounters::default(); n];
            let got = g.intersect_packet(&tris, &crate::testing::within(&rays, t_min, t_max), &mut counted);
            let mut counted_fours = vec![TraversalCounters::default(); n];
            let fours =
                g.packet_in_fours::<false, _>(&tris, &crate::testing::within(&rays, t_min, t_max), &mut counted_fours);
            assert_eq!(
                (fours.map(|h| (h.t.to_bits(), h.tri)), &counted_fours),
                (got.map(|h| (h.t.to_bits(), h.tri)), &counted),
                "two packets of four differ from eight lanes: {rays:?}"
            );
            for (k, r) in rays.iter().enumerate() {
                let mut alone = TraversalCounters::default();
                let want = g.intersect(&tris, &crate::testing::within(r, t_min, t_max), &mut alone);
                assert_eq!(
                    (got[k].t.to_bits(), got[k].tri, got[k].u.to_bits(), got[k].v.to_bits()),
                    (want.t.to_bits(), want.tri, want.u.to_bits(), want.v.to_bits()),
                    "ray {k} of {rays:?}: packet {:?}, alone {want:?}",
                    got[k]
                );
                assert_eq!(counted[k], alone, "ray {k} of {rays:?}");
            }
            assert!(got[n..].iter().all(|h| !h.is_hit()), "lanes past the rays are misses");
            multi_hit += (got.iter().filter(|h| h.is_hit()).count() > 1) as u32;
            // Any hits, each ray up to its own distance (shadow rays towards a light).
            let limits: [f32; PACKET] = std::array::from_fn(|k| [t_max, 3.0, 0.7, 12.0][(i + k) % 4]);
            let mut counted = vec![TraversalCounters::default(); n];
            let shadow = crate::testing::within_each(&rays, t_min, &limits);
            let got = g.occluded_packet(&tris, &shadow, &mut counted);
            let mut counted_fours = vec![TraversalCounters::default(); n];
            let fours = g.packet_in_fours::<true, _>(&tris, &shadow, &mut counted_fours);
            assert_eq!(
                (fours.map(|h| h.is_hit()), &counted_fours),
                (got, &counted),
                "two packets of four differ from eight lanes: {rays:?} up to {limits:?}"
            );
            for (k, r) in rays.iter().enumerate() {
                let mut alone = TraversalCounters::default();
                let want = g.occluded(&tris, &crate::testing::within(r, t_min, limits[k]), &mut alone);
                assert_eq!(
                    (got[k], counted[k]),
                    (want, alone),
                    "ray {k} of {rays:?} up to {limits:?}"
                );
            }
            assert!(!got[n..].iter().any(|&h| h), "lanes past the rays are not occluded");
        }
    }
    // Many packets had several rays hitting (else this would test single rays only).
    assert!(multi_hit > 2_000, "{multi_hit} packets with two hits or more");
}

/// Batch queries take runs of quads that walk together as packets and the rest one by one
/// (`IrregularGrid::batch`): every answer is the single-ray walk's, bit for bit, whatever the
/// mix: image rows of pinhole cameras (rows end mid-quad), the shadow rays from their hits
/// towards a light (nearby origins), rays from one point in all directions, incoherent rays,
/// and all of them shuffled into each other; closest and any hits.
#[test]
fn batches_with_camera_rows_equal_single_rays() {
    let tris = clusters(2000, 23);
    let g = IrregularGrid::build(&tris, IrregularParams::default()).unwrap();
    let mut rng = Rng::new(77);
    let mut rays = Vec::new();
    let light = Vec3::new(5.0, 14.0, 5.0);
    for _ in 0..6 {
        let eye = Vec3::new(rng.range(-3.0, 13.0), rng.range(-3.0, 13.0), rng.range(-3.0, 13.0));
        let target = tris[rng.below(tris.len() as u32) as usize].vertices()[0];
        let ahead = (target - eye).normalize();
        let (right, up) = ahead.any_orthonormal_pair();
        let (right, up) = (right * 0.003, up * 0.003);
        // Rows of 37 pixels: quads straddle the ends of rows.
        let camera: Vec<Ray> = (0..20 * 37)
            .map(|p| Ray::new(eye, ahead + right * (p % 37 - 18) as f32 + up * (p / 37 - 10) as f32))
            .collect();
        // Their shadow rays, in the same order, from just off each hit towards the light.
        for r in &camera {
            let hit = g.intersect(&tris, r, &mut NoCounters);
            if hit.is_hit() {
                let p = r.at(hit.t * 0.999);
                rays.push(Ray::new(p, (light - p).normalize()));
            }
        }
        rays.extend(camera);
        // From the same point in all directions: a shared origin, no coherence.
        for _ in 0..64 {
            let d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            rays.push(Ray::new(eye, d));
        }
        for _ in 0..50 {
            let o = Vec3::new(rng.range(-3.0, 13.0), rng.range(-3.0, 13.0), rng.range(-3.0, 13.0));
            let d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            rays.push(Ray::new(o, d));
        }
    }
    let ordered = rays.len();
    let mut shuffled = rays.clone();
    for i in (1..shuffled.len()).rev() {
        shuffled.swap(i, rng.below(i as u32 + 1) as usize);
    }
    rays.extend(shuffled);
    let (t_min, t_max) = (0.0, 14.0);
    let mut closest = vec![None; rays.len()];
    let rays = crate::testing::within(&rays, t_min, t_max);
    g.batch::<false>(&tris, &rays, |i, hit| {
        assert!(closest[i].replace(hit).is_none(), "ray {i} answered twice");
    });
    let mut any = vec![None; rays.len()];
    g.batch::<true>(&tris, &rays, |i, hit| {
        assert!(any[i].replace(hit.is_hit()).is_none(), "ray {i} answered twice");
    });
    let (mut hits, mut occluded) = (0, 0);
    for (i, r) in rays.iter().enumerate() {
        let want = g.intersect(&tris, &crate::testing::within(r, t_min, t_max), &mut NoCounters);
        let got = closest[i].unwrap_or_else(|| panic!("ray {i} not answered"));
        assert_eq!(
            (got.t.to_bits(), got.tri, got.u.to_bits(), got.v.to_bits()),
            (want.t.to_bits(), want.tri, want.u.to_bits(), want.v.to_bits()),
            "ray {i}: {r:?}"
        );
        let want_any = g.occluded(&tris, &crate::testing::within(r, t_min, t_max), &mut NoCounters);
        assert_eq!(any[i], Some(want_any), "ray {i}: {r:?}");
        hits += want.is_hit() as usize;
        occluded += want_any as usize;
    }
    assert!(
        hits > ordered / 3,
        "{hits} hits of {ordered}: the cameras must see the clusters"
    );
    assert_eq!(hits, occluded, "a ray with a closest hit is occluded and no other");
}

#[test]
fn bad_parameters_are_errors() {
    let tris = clusters(10, 1);
    for s in [
        "top=0",
        "cell=-1",
        "top=nan",
        "cell=1e9",
        "alpha=-2",
        "merge=1000",
        "bogus=1",
        "top",
    ] {
        let parsed = s.parse::<IrregularParams>();
        assert!(parsed.is_err(), "{s} accepted");
    }
    let p = IrregularParams {
        top_density: f32::INFINITY,
        ..Default::default()
    };
    assert!(IrregularGrid::build(&tris, p).is_err());
    assert_eq!(
        "top=0.5,expand=0".parse::<IrregularParams>().unwrap(),
        IrregularParams {
            top_density: 0.5,
            expand_passes: 0,
            ..Default::default()
        }
    );
}

#[test]
fn no_triangles_and_one() {
    let g = IrregularGrid::build(&[], IrregularParams::default()).unwrap();
    let r = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X);
    assert!(!g.intersect(&[], &r, &mut NoCounters).is_hit());
    let tri = [TriAccel::new(Vec3::ZERO, Vec3::X, Vec3::Y)];
    let g = IrregularGrid::build(&tri, IrregularParams::default()).unwrap();
    let r = Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z);
    assert_eq!(g.intersect(&tri, &r, &mut NoCounters).t, 1.0);
}
