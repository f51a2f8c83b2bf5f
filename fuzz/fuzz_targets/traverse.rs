//! Traversal equals brute force on small triangle soups: grid and proximity-cloud closest hits
//! agree with testing every triangle (same hit/miss, same t), and any-hit agrees with closest
//! hit. Vertices come from a small pool so edges and vertices are shared exactly; coordinates
//! are either on a coarse lattice (exact ties with cell boundaries) or arbitrary finite floats.
#![no_main]
use glam::Vec3;
use gridtrace::accel::{AccelKind, NoCounters, Ray, Resolution, TriAccel, brute_force_intersect};
use gridtrace::testing::AllAccels;
use libfuzzer_sys::fuzz_target;

struct Bytes<'a>(&'a [u8]);
impl Bytes<'_> {
    fn u8(&mut self) -> Option<u8> {
        let (&b, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(b)
    }
    fn f32_raw(&mut self) -> Option<f32> {
        let b: [u8; 4] = self.0.get(..4)?.try_into().ok()?;
        self.0 = &self.0[4..];
        Some(f32::from_le_bytes(b))
    }
    /// A coordinate: on a 1/8 lattice in [-16, 16), or (flag) a raw float bounded to 1e4.
    fn coord(&mut self, raw: bool) -> Option<f32> {
        if raw {
            let x = self.f32_raw()?;
            Some(if x.is_finite() { x.clamp(-1e4, 1e4) } else { 0.0 })
        } else {
            Some(self.u8()? as i8 as f32 / 8.0)
        }
    }
    fn vec(&mut self, raw: bool) -> Option<Vec3> {
        Some(Vec3::new(self.coord(raw)?, self.coord(raw)?, self.coord(raw)?))
    }
}

fuzz_target!(|data: &[u8]| {
    let _ = run(&mut Bytes(data));
});

fn run(b: &mut Bytes) -> Option<()> {
    let flags = b.u8()?;
    let raw = flags & 1 != 0;
    let res = match flags >> 1 & 3 {
        0 => Resolution::default(),
        _ => Resolution::Fixed([
            1 + b.u8()? as u32 % 12,
            1 + b.u8()? as u32 % 12,
            1 + b.u8()? as u32 % 12,
        ]),
    };
    let n_verts = 3 + b.u8()? as usize % 10;
    let pool: Vec<Vec3> = (0..n_verts).map(|_| b.vec(raw)).collect::<Option<_>>()?;
    let n_tris = 1 + b.u8()? as usize % 16;
    let mut tris = Vec::new();
    for _ in 0..n_tris {
        let [i, j, k] = [b.u8()?, b.u8()?, b.u8()?].map(|x| pool[x as usize % n_verts]);
        let t = TriAccel::new(i, j, k);
        if t.normal().length_squared() > 0.0 && t.normal().is_finite() {
            tris.push(t);
        }
    }
    if tris.is_empty() {
        return None;
    }
    let all = AllAccels::build(tris, res).ok()?;
    // Rays: origin and either a direction or a pool vertex to aim at (exactly through it).
    while let Some(sel) = b.u8() {
        let o = b.vec(raw)?;
        let d = if sel & 1 == 0 {
            b.vec(raw)?
        } else {
            pool[sel as usize / 2 % n_verts] - o
        };
        if d.length_squared() == 0.0 || !d.is_finite() {
            continue;
        }
        let r = Ray::new(o, d);
        let want = brute_force_intersect(&all.grid.tris, &r, 0.0, f32::INFINITY);
        if want.is_hit() && all.grid.tris[want.tri as usize].grazing_cos(r.dir) < 1e-4 {
            // A graze this close can put the hit outside the padded boxes (`TriAccel::grazing_cos`).
            continue;
        }
        for kind in AccelKind::ALL {
            let got = all.get(kind).intersect(&r, 0.0, f32::INFINITY, kind, &mut NoCounters);
            assert_eq!(got.is_hit(), want.is_hit(), "{kind:?} {r:?}: got {got:?} want {want:?}");
            if want.is_hit() {
                assert!(
                    (got.t - want.t).abs() <= 1e-6 * want.t.abs().max(1e-30),
                    "{kind:?} {r:?}: got {got:?} want {want:?}"
                );
            }
            let occ = all.get(kind).occluded(&r, 0.0, f32::INFINITY, kind, &mut NoCounters);
            assert_eq!(occ, want.is_hit(), "{kind:?} {r:?}: occluded {occ}, closest {want:?}");
        }
    }
    Some(())
}
