//! Every ray asks its own interval (`Ray::t_min <= t < Ray::t_max`): each structure's single,
//! packet and batch walks answer as brute force over the same interval, ray by ray. Intervals are
//! drawn per ray: whole, cut at both ends, empty (`t_min > t_max`: a miss, Embree's rule), a point,
//! and NaN at either end (a miss); half the packets share their start (the packet walks' lanes
//! run from one `t_min`) and half do not (those rays walk singly, `contract::same_start`).

use gridtrace::Ray;
use gridtrace::accel::contract::all_hits_brute;
use gridtrace::accel::{
    AccelKind, Hit, PACKET, Resolution, TraversalCounters, brute_force_intersect, brute_force_occluded,
};
use gridtrace::testing::{AllAccels, flat_scene, ray_set, triangle_soup};
use gridtrace::util::Rng;

const RAYS: usize = 4_000;

fn bits(h: &Hit) -> (u32, u32, u32, u32) {
    (h.t.to_bits(), h.tri, h.u.to_bits(), h.v.to_bits())
}

/// The ray set's rays, each given an interval: packets (runs of `PACKET`) alternate between one
/// start for all their rays and a start each.
fn with_intervals(rays: &[Ray], far: f32, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed);
    let mut out = Vec::with_capacity(rays.len());
    for (p, packet) in rays.chunks(PACKET).enumerate() {
        let shared_start = rng.range(0.0, 0.5 * far);
        for r in packet {
            let a = if p % 2 == 0 { shared_start } else { rng.range(0.0, far) };
            let (t_min, t_max) = match rng.below(8) {
                0 => (0.0, f32::INFINITY),
                1 => (a, a * 0.5),
                2 => (a, a),
                3 if p % 2 == 1 => (f32::NAN, far),
                4 => (a, f32::NAN),
                _ => (a, a + rng.range(0.0, far)),
            };
            out.push(r.within(t_min, t_max));
        }
    }
    out
}

fn check(name: &str, tris: Vec<gridtrace::accel::TriAccel>) {
    let all = AllAccels::build(tris, Resolution::default()).unwrap();
    let far = all.grid.bounds().diagonal();
    let rays = with_intervals(&ray_set(&all.grid, RAYS, 0x1E7 ^ name.len() as u64), far, 7);
    let truth: Vec<Hit> = rays.iter().map(|r| brute_force_intersect(&all.grid.tris, r)).collect();
    let any: Vec<bool> = rays.iter().map(|r| brute_force_occluded(&all.grid.tris, r)).collect();
    let hits = truth.iter().filter(|h| h.is_hit()).count();
    assert!(
        hits > RAYS / 20 && hits < RAYS * 9 / 10,
        "{name}: a varied set ({hits} hits)"
    );
    let mut list = Vec::new();
    for kind in AccelKind::ALL {
        let accel = all.get(kind);
        let what = format!("{name}, {}", kind.name());
        // Single rays against brute force over the same interval.
        let single: Vec<Hit> = rays
            .iter()
            .map(|r| accel.intersect(r, &mut gridtrace::accel::NoCounters))
            .collect();
        for (i, r) in rays.iter().enumerate() {
            let (got, want) = (single[i], truth[i]);
            assert_eq!(
                got.is_hit(),
                want.is_hit(),
                "{what}, ray {i} {r:?}: {got:?} against {want:?}"
            );
            if want.is_hit() {
                assert!(
                    got.t >= r.t_min && got.t < r.t_max,
                    "{what}, ray {i}: t outside the interval"
                );
                assert!(
                    (got.t - want.t).abs() <= 1e-6 * want.t.abs(),
                    "{what}, ray {i}: {got:?} {want:?}"
                );
            }
            let occluded = accel.occluded(r, &mut gridtrace::accel::NoCounters);
            assert_eq!(occluded, any[i], "{what}, ray {i} {r:?}: any hit");
            list.clear();
            accel.all_hits(r, &mut list);
            let mut want_list = Vec::new();
            all_hits_brute(&all.grid.tris, r, &mut want_list);
            assert_eq!(list.len(), want_list.len(), "{what}, ray {i} {r:?}: all hits");
        }
        // Batches: the single walk's bits.
        let mut batch = vec![Hit::MISS; rays.len()];
        accel.intersect_batch(&rays, &mut batch);
        let mut blocked = vec![false; rays.len()];
        accel.occluded_batch(&rays, &mut blocked);
        let mut counts = vec![0u32; rays.len()];
        accel.count_hits_batch(&rays, &mut counts);
        for i in 0..rays.len() {
            assert_eq!(bits(&batch[i]), bits(&single[i]), "{what}, batch ray {i} {:?}", rays[i]);
            assert_eq!(blocked[i], any[i], "{what}, batch any hit, ray {i}");
            let mut want_list = Vec::new();
            all_hits_brute(&all.grid.tris, &rays[i], &mut want_list);
            assert_eq!(counts[i] as usize, want_list.len(), "{what}, count, ray {i}");
        }
        // Packets: the single walk's bits and counts.
        for (p, packet) in rays.chunks(PACKET).enumerate() {
            let mut counted = vec![TraversalCounters::default(); packet.len()];
            let got = accel.intersect_packet(packet, &mut counted);
            let mut counted_any = vec![TraversalCounters::default(); packet.len()];
            let got_any = accel.occluded_packet(packet, &mut counted_any);
            for (k, r) in packet.iter().enumerate() {
                let mut alone = TraversalCounters::default();
                let want = accel.intersect(r, &mut alone);
                assert_eq!(bits(&got[k]), bits(&want), "{what}, packet {p} ray {k} {r:?}");
                assert_eq!(counted[k], alone, "{what}, packet {p} ray {k}: counts");
                let mut alone_any = TraversalCounters::default();
                assert_eq!(
                    got_any[k],
                    accel.occluded(r, &mut alone_any),
                    "{what}, packet {p} ray {k}: any"
                );
                assert_eq!(counted_any[k], alone_any, "{what}, packet {p} ray {k}: any-hit counts");
            }
        }
    }
}

#[test]
fn intervals_per_ray_on_a_soup() {
    check("soup", triangle_soup(2_000, 3));
}

#[test]
fn intervals_per_ray_on_a_flat_scene() {
    check("flat", flat_scene(5));
}

/// On the GPU a batch of prepared rays shares one interval (24 bytes a ray on the wire, the
/// interval once a batch): rays that share a cut interval answer as the CPU does, and a batch
/// whose rays ask different ones is refused with an error naming the first that differs.
#[test]
fn gpu_batches_take_one_interval_and_name_a_ray_that_differs() {
    if gridtrace::testing::skip_gpu() {
        return;
    }
    let tris = triangle_soup(500, 11);
    let (vertices, faces) = gridtrace::testing::soup_arrays(&tris);
    let mesh = gridtrace::testing::gpu_mesh(&vertices, &faces, AccelKind::Bvh);
    let all = AllAccels::build(tris, Resolution::default()).unwrap();
    let far = all.grid.bounds().diagonal();
    let rays: Vec<Ray> = ray_set(&all.grid, 2_000, 21)
        .iter()
        .map(|r| r.within(0.1 * far, 0.6 * far))
        .collect();
    let gpu = mesh.intersect_rays_with(gridtrace::Backend::Gpu, &rays).unwrap();
    let cpu = mesh.intersect_rays_with(gridtrace::Backend::Cpu, &rays).unwrap();
    let (mut hits, mut apart) = (0, 0);
    for (i, (g, c)) in gpu.iter().zip(&cpu).enumerate() {
        hits += c.is_hit() as usize;
        if g.is_hit() != c.is_hit() || (c.is_hit() && (g.t - c.t).abs() > 1e-5 * c.t) {
            apart += 1;
            assert!(apart <= 2, "ray {i}: GPU {g:?}, CPU {c:?}");
        }
        if g.is_hit() {
            assert!(
                g.t >= rays[i].t_min && g.t < rays[i].t_max,
                "ray {i}: t outside the interval"
            );
        }
    }
    assert!(hits > 100 && hits < 1_900, "a varied set ({hits} hits)");
    let occ = mesh.occluded_rays_with(gridtrace::Backend::Gpu, &rays).unwrap();
    let occ_cpu = mesh.occluded_rays_with(gridtrace::Backend::Cpu, &rays).unwrap();
    let differ = occ.iter().zip(&occ_cpu).filter(|(a, b)| a != b).count();
    assert!(differ <= 2, "{differ} any-hit answers apart");
    let mut mixed = rays.clone();
    mixed[5] = mixed[5].within(0.0, f32::INFINITY);
    let e = mesh
        .intersect_rays_with(gridtrace::Backend::Gpu, &mixed)
        .unwrap_err()
        .to_string();
    assert!(e.contains("ray 5") && e.contains("one interval"), "{e}");
    let e = mesh
        .occluded_rays_with(gridtrace::Backend::Gpu, &mixed)
        .unwrap_err()
        .to_string();
    assert!(e.contains("ray 5"), "{e}");
    // On the CPU each ray keeps its own.
    let cpu_mixed = mesh.intersect_rays_with(gridtrace::Backend::Cpu, &mixed).unwrap();
    assert_eq!(cpu_mixed[6].t.to_bits(), cpu[6].t.to_bits());
}
