//! `brute`: no structure at all, every triangle tested against every ray. The oracle the other
//! structures are checked against, and a way to check a result on a small mesh
//! (`--accel brute`): its cost per ray is the triangle count.
//!
//! It is also the proof of the structure contract: it was added as this file, one registry
//! entry (`registry.rs`) and one arm of `Structure`; its GPU side is its walk file
//! (`gpu/walks/brute/brute.wgsl`) and `gpu/walks/brute/mod.rs` with one entry of `WALKS`.

use crate::Result;
use crate::accel::AccelParams;
use crate::accel::contract::{AccelStructure, Walks};
use crate::accel::{Counters, Hit, Ray, TriAccel};

/// Nothing is built: the walk is the triangle list.
#[derive(Debug, Clone, Default)]
pub struct Brute {
    /// Triangles when built, so `summary` can say what a ray costs.
    pub triangles: usize,
}

impl AccelStructure for Brute {
    fn build(tris: &[TriAccel], params: &AccelParams) -> Result<Brute> {
        params.read("brute", &[], |_, _| Ok(()))?;
        Ok(Brute { triangles: tris.len() })
    }

    fn memory(&self) -> Vec<(&'static str, usize)> {
        Vec::new()
    }

    fn summary(&self) -> String {
        format!("brute force: {} triangle tests per ray", self.triangles)
    }
}

impl Walks for Brute {
    /// The closest of every triangle's hit, the first in triangle order on equal `t` (as every
    /// structure's walk, which tests a cell's references in ascending order).
    #[inline]
    fn intersect<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> Hit {
        let mut best = Hit {
            t: ray.t_max,
            ..Hit::MISS
        };
        for (i, tri) in tris.iter().enumerate() {
            counters.tri_test();
            if let Some(h) = tri.intersect(ray.origin, ray.dir, ray.t_min, best.t) {
                best = h.on(i as u32);
            }
        }
        if best.is_hit() { best } else { Hit::MISS }
    }

    #[inline]
    fn occluded<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> bool {
        tris.iter().any(|tri| {
            counters.tri_test();
            tri.intersect(ray.origin, ray.dir, ray.t_min, ray.t_max).is_some()
        })
    }
}
