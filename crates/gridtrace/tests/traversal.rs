//! Traversal equals brute force: closest t and triangle id for 100,000 adversarial rays per
//! scene, for the plain grid, proximity clouds and the BVH; any-hit agrees with closest hit, and
//! the batch queries and packets of one to eight rays agree with the per-ray ones.

use glam::Vec3;
use gridtrace::Ray;
use gridtrace::accel::{
    Accel, AccelKind, Grid, Hit, NoCounters, PACKET, Resolution, TraversalCounters, TriAccel, brute_force_intersect,
    brute_force_occluded,
};
use gridtrace::scene::builtin;
use gridtrace::testing::{AllAccels, flat_scene, ray_set, triangle_soup};
use rayon::prelude::*;

const RAYS: usize = 100_000;

/// Two hits agree if both miss, or both hit at the same t (relative 1e-6) and on the same
/// triangle, or on different triangles at the same t (an exact tie: a ray through a shared edge
/// or vertex, or coplanar overlapping triangles).
fn agree(a: &Hit, b: &Hit) -> bool {
    if a.is_hit() != b.is_hit() {
        return false;
    }
    if !a.is_hit() {
        return true;
    }
    (a.t - b.t).abs() <= 1e-6 * b.t.abs().max(1e-30)
}

fn check(name: &str, tris: Vec<TriAccel>, res: Resolution) {
    let all = AllAccels::build(tris, res).unwrap();
    let rays = ray_set(&all.grid, RAYS, 0xC0FFEE ^ name.len() as u64);
    let truth: Vec<Hit> = rays
        .par_iter()
        .map(|r| brute_force_intersect(&all.grid.tris, r))
        .collect();
    let hits = truth.iter().filter(|h| h.is_hit()).count();
    assert!(
        hits > RAYS / 10 && hits < RAYS * 95 / 100,
        "{name}: ray set is not varied enough ({hits} hits)"
    );
    for kind in AccelKind::ALL {
        let bad: Vec<String> = rays
            .par_iter()
            .zip(&truth)
            .filter_map(|(r, want)| {
                let got = all.get(kind).intersect(r, &mut NoCounters);
                let mut errs = Vec::new();
                if !agree(&got, want) {
                    errs.push(format!("closest {got:?} want {want:?}"));
                }
                if got.is_hit() && got.tri != want.tri {
                    // A tie must really be a tie: the other triangle is hit at the same t.
                    let alt = all.grid.tris[want.tri as usize].intersect(r.origin, r.dir, 0.0, f32::INFINITY);
                    if alt.is_none() {
                        errs.push("tie partner not hit".into());
                    }
                }
                let occ = all.get(kind).occluded(r, &mut NoCounters);
                if occ != want.is_hit() {
                    errs.push(format!("occluded {occ} but closest {want:?}"));
                }
                if want.is_hit() {
                    // Nothing strictly before the closest hit; something just past it.
                    let before = all
                        .get(kind)
                        .occluded(&r.within(0.0, want.t * (1.0 - 1e-5)), &mut NoCounters);
                    let past = all
                        .get(kind)
                        .occluded(&r.within(0.0, want.t * (1.0 + 1e-5)), &mut NoCounters);
                    if before != brute_force_occluded(&all.grid.tris, &r.within(0.0, want.t * (1.0 - 1e-5))) || !past {
                        errs.push(format!("occluded window wrong: before {before} past {past}"));
                    }
                }
                (!errs.is_empty()).then(|| format!("{r:?}: {}", errs.join("; ")))
            })
            .collect();
        // The batch queries (interleaved rays for the BVH) give exactly the per-ray answers.
        let mut batch = vec![Hit::MISS; rays.len()];
        all.get(kind).intersect_batch(&rays, &mut batch);
        let mut occ_batch = vec![false; rays.len()];
        all.get(kind).occluded_batch(&rays, &mut occ_batch);
        // With normals (the BVH takes them from the triangle it hits): the same hits, and each
        // normal the hit triangle's.
        let mut with_normals = vec![Hit::MISS; rays.len()];
        let mut normals = vec![Vec3::NAN; rays.len()];
        all.get(kind).intersect_batch_each(&rays, |i, hit, normal| {
            with_normals[i] = hit;
            normals[i] = normal;
        });
        assert_eq!(with_normals, batch, "{name} {}: batch with normals", kind.name());
        for (h, n) in batch.iter().zip(&normals) {
            let want = if h.is_hit() {
                all.grid.tris[h.tri as usize].normal()
            } else {
                Vec3::ZERO
            };
            assert_eq!(*n, want, "{name} {}: normal of {h:?}", kind.name());
        }
        for (i, r) in rays.iter().enumerate() {
            assert_eq!(
                batch[i],
                all.get(kind).intersect(r, &mut NoCounters),
                "{name} {} batch {r:?}",
                kind.name()
            );
            assert_eq!(
                occ_batch[i],
                batch[i].is_hit(),
                "{name} {} occluded batch {r:?}",
                kind.name()
            );
        }
        // Packets of one to eight of these rays (what the renderer hands every structure, as
        // 4x2 blocks; here incoherent ones): each ray's hit, any-hit answer up to its own
        // limit, and counts are its single-ray walk's, bit for bit.
        let accel = all.get(kind);
        // A few rays with NaN, infinite, zero and huge components among them.
        let odd = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0, 1e30, 1e-40];
        let mut rays = rays.clone();
        for (i, r) in rays.iter_mut().enumerate().step_by(97) {
            let v = odd[(i / 97) % odd.len()];
            if i % 2 == 0 {
                r.dir[(i / 194) % 3] = v;
            } else {
                r.origin[(i / 194) % 3] = v;
            }
        }
        let (mut at, mut len) = (0, 1);
        while at < rays.len() {
            let packet = &rays[at..(at + len).min(rays.len())];
            let n = packet.len();
            let mut counted = vec![TraversalCounters::default(); n];
            let got = accel.intersect_packet(packet, &mut counted);
            let limits: [f32; PACKET] = std::array::from_fn(|k| [f32::INFINITY, 1.0, 0.25][(at + k) % 3]);
            let mut counted_any = vec![TraversalCounters::default(); n];
            let blocked =
                accel.occluded_packet(&gridtrace::testing::within_each(packet, 0.0, &limits), &mut counted_any);
            for (k, r) in packet.iter().enumerate() {
                let mut c = TraversalCounters::default();
                let want = accel.intersect(r, &mut c);
                assert_eq!(
                    (
                        got[k].t.to_bits(),
                        got[k].tri,
                        got[k].u.to_bits(),
                        got[k].v.to_bits(),
                        counted[k]
                    ),
                    (want.t.to_bits(), want.tri, want.u.to_bits(), want.v.to_bits(), c),
                    "{name} {}: ray {k} of a packet of {n}, {r:?}",
                    kind.name()
                );
                let mut c = TraversalCounters::default();
                let want = accel.occluded(&gridtrace::testing::within(r, 0.0, limits[k]), &mut c);
                assert_eq!(
                    (blocked[k], counted_any[k]),
                    (want, c),
                    "{name} {}: any hit of ray {k} of a packet of {n} before {}, {r:?}",
                    kind.name(),
                    limits[k]
                );
            }
            assert!(got[n..].iter().all(|h| !h.is_hit()) && !blocked[n..].iter().any(|&b| b));
            at += n;
            len = len % PACKET + 1;
        }
        // Coherent packets (a ray and seven companions from its origin, directions a little
        // apart: the route of camera rays, the BVH's packet walk), nothing counted, and the same
        // rays as a batch (whose groups of eight then look coherent): the single walk's
        // answers, bit for bit.
        let coherent: Vec<Ray> = rays
            .iter()
            .step_by(8)
            .filter(|r| r.origin.is_finite() && r.dir.is_finite() && r.dir != Vec3::ZERO)
            .flat_map(|r| {
                let side = r.dir.any_orthonormal_vector() * r.dir.length() * 2e-3;
                (0..PACKET).map(move |j| Ray::new(r.origin, r.dir + side * j as f32))
            })
            .collect();
        let bits = |h: &Hit| (h.t.to_bits(), h.tri, h.u.to_bits(), h.v.to_bits());
        let mut batch = vec![Hit::MISS; coherent.len()];
        accel.intersect_batch(&coherent, &mut batch);
        let mut occ_batch = vec![false; coherent.len()];
        accel.occluded_batch(&gridtrace::testing::within(&coherent, 0.0, 1.0), &mut occ_batch);
        for (p, packet) in coherent.chunks(PACKET).enumerate() {
            let mut none = [NoCounters; PACKET];
            let got = accel.intersect_packet(packet, &mut none);
            let blocked = accel.occluded_packet(&gridtrace::testing::within(packet, 0.0, 1.0), &mut none);
            for (k, r) in packet.iter().enumerate() {
                let want = accel.intersect(r, &mut NoCounters);
                let what = format!("{name} {}: coherent packet {p}, ray {k}, {r:?}", kind.name());
                assert_eq!(bits(&got[k]), bits(&want), "{what}");
                assert_eq!(bits(&batch[PACKET * p + k]), bits(&want), "{what} (batch)");
                let want = accel.occluded(&gridtrace::testing::within(r, 0.0, 1.0), &mut NoCounters);
                assert_eq!(blocked[k], want, "{what}: any hit");
                assert_eq!(occ_batch[PACKET * p + k], want, "{what}: any hit (batch)");
            }
        }
        assert!(
            bad.is_empty(),
            "{name} {}: {} of {RAYS} rays disagree, first: {:#?}",
            kind.name(),
            bad.len(),
            &bad[..bad.len().min(5)]
        );
    }
}

fn scene_tris(name: &str) -> Vec<TriAccel> {
    builtin::scene(name)
        .unwrap()
        .prepare(Resolution::Fixed([1, 1, 1]))
        .unwrap()
        .accel
        .tris
}

#[test]
fn knot_box_auto_grid() {
    check("knot-box", scene_tris("knot-box"), Resolution::default());
}

#[test]
fn knot_box_paper_grid() {
    // The paper's hand-tuned 16^3 grid for this scene.
    check("knot-box-16", scene_tris("knot-box"), Resolution::Fixed([16, 16, 16]));
}

#[test]
fn triangle_soup_auto_and_fine() {
    check("soup", triangle_soup(3000, 1), Resolution::default());
    check("soup-fine", triangle_soup(3000, 2), Resolution::Fixed([40, 7, 23]));
}

#[test]
fn flat_scene_auto() {
    check("flat", flat_scene(5), Resolution::default());
}

#[test]
fn sparse_room_proximity_jumps() {
    check(
        "sparse-room",
        scene_tris("sparse-room"),
        Resolution::Fixed([48, 48, 48]),
    );
}

#[test]
fn mirror_spheres_auto() {
    check("mirror-spheres", scene_tris("mirror-spheres"), Resolution::default());
}

/// Proximity clouds must actually skip: fewer cells visited on a sparse scene, same answers.
#[test]
fn proximity_cloud_visits_fewer_cells() {
    use gridtrace::accel::TraversalCounters;
    let tris = scene_tris("sparse-room");
    let grid = Grid::build(&tris, Resolution::Fixed([48, 48, 48])).unwrap();
    let accel = Accel::from_grid(grid, tris);
    assert_eq!(accel.kind(), AccelKind::Grid);
    let pc = accel.clone().with_traversal(AccelKind::ProximityCloud).unwrap();
    let rays = ray_set(&accel, 20_000, 9);
    let (mut g, mut p) = (TraversalCounters::default(), TraversalCounters::default());
    for r in &rays {
        accel.intersect(r, &mut g);
        pc.intersect(r, &mut p);
    }
    assert_eq!(g.jumps, 0);
    assert!(p.jumps > 0);
    assert!(p.cells * 2 < g.cells, "pc visited {} cells, grid {}", p.cells, g.cells);
    // The same non-empty cells are visited either way, up to extra cells at exact corner ties.
    assert!(
        p.tri_tests.abs_diff(g.tri_tests) * 1000 <= g.tri_tests,
        "pc {} vs grid {} triangle tests",
        p.tri_tests,
        g.tri_tests
    );
}
