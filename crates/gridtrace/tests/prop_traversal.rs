//! Property tests: for any triangle soup and any ray, grid and proximity-cloud traversal give
//! the brute-force closest hit (same hit/miss, same t), and any-hit agrees with it.

use glam::Vec3;
use gridtrace::accel::{AccelKind, NoCounters, Ray, Resolution, TriAccel, brute_force_intersect};
use gridtrace::testing::AllAccels;
use proptest::prelude::*;

/// Coordinates either on a 1/8 lattice (exact ties with cell boundaries and shared edges) or
/// arbitrary floats, at one of several scales.
fn coord() -> impl Strategy<Value = f32> {
    prop_oneof![(-16i32..=16).prop_map(|i| i as f32 / 8.0), -2.0f32..2.0, -1e-3f32..1e-3]
}

fn vec3() -> impl Strategy<Value = Vec3> {
    (coord(), coord(), coord()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn resolution() -> impl Strategy<Value = Resolution> {
    prop_oneof![
        Just(Resolution::default()),
        (1u32..12, 1u32..12, 1u32..12).prop_map(|(a, b, c)| Resolution::Fixed([a, b, c])),
    ]
}

/// A soup over a shared vertex pool, so edges and vertices are shared exactly; rays either
/// random or aimed exactly at a pool vertex.
/// Vertex pool, triangles (pool indices), grid resolution, rays (origin, direction, aim).
type Case = (Vec<Vec3>, Vec<[usize; 3]>, Resolution, Vec<(Vec3, Vec3, Option<usize>)>);

fn case() -> impl Strategy<Value = Case> {
    (
        prop::collection::vec(vec3(), 3..12),
        prop::collection::vec((0usize..64, 0usize..64, 0usize..64), 1..24),
        resolution(),
        prop::collection::vec(
            (vec3().prop_map(|v| v * 4.0), vec3(), prop::option::of(0usize..64)),
            1..16,
        ),
    )
        .prop_map(|(pool, idx, res, rays)| {
            let n = pool.len();
            let tris = idx.into_iter().map(|(a, b, c)| [a % n, b % n, c % n]).collect();
            (pool, tris, res, rays)
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]
    #[test]
    fn traversal_equals_brute_force((pool, idx, res, rays) in case()) {
        let tris: Vec<TriAccel> = idx
            .iter()
            .map(|t| TriAccel::new(pool[t[0]], pool[t[1]], pool[t[2]]))
            .filter(|t| t.normal().length_squared() > 0.0)
            .collect();
        prop_assume!(!tris.is_empty());
        let all = AllAccels::build(tris, res).unwrap();
        for (o, d, aim) in rays {
            let d = match aim {
                Some(i) => pool[i % pool.len()] - o,
                None => d,
            };
            if d.length_squared() == 0.0 {
                continue;
            }
            let r = Ray::new(o, d);
            let want = brute_force_intersect(&all.grid.tris, &r);
            for kind in AccelKind::ALL {
                let got = all.get(kind).intersect(&r, &mut NoCounters);
                prop_assert_eq!(got.is_hit(), want.is_hit(), "{:?} {:?}: got {:?} want {:?}", kind, r, got, want);
                if want.is_hit() {
                    prop_assert!((got.t - want.t).abs() <= 1e-6 * want.t.abs().max(1e-30),
                        "{:?} {:?}: got {:?} want {:?}", kind, r, got, want);
                }
                let occ = all.get(kind).occluded(&r, &mut NoCounters);
                prop_assert_eq!(occ, want.is_hit(), "{:?} {:?}", kind, r);
            }
        }
    }
}
