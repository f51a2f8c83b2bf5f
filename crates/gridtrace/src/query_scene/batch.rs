//! A ray batch as Open3D passes it (`[ox, oy, oz, dx, dy, dz]` per ray) and its closest hits:
//! what the GPU path (`rays.rs`), the CPU path (`cpu_rays.rs`) and the all-hits walk share.

use glam::Vec3;
use rayon::prelude::*;

use super::INVALID_ID;
use crate::accel::Ray;
use crate::accel::huge::advise_huge_pages_within;
use crate::{Error, Result};

/// A chunk of `RayHits`' outputs: t, geometry ids, primitive ids, uvs, normals.
pub(super) type HitsChunk<'a> = (
    &'a mut [f32],
    &'a mut [u32],
    &'a mut [u32],
    &'a mut [[f32; 2]],
    &'a mut [[f32; 3]],
);

/// One row of `RayHits`' outputs, as `HitsChunk`.
pub(super) type HitsRow<'a> = (
    &'a mut f32,
    &'a mut u32,
    &'a mut u32,
    &'a mut [f32; 2],
    &'a mut [f32; 3],
);

/// How a ray query names a hit: its geometry, face, uv and world-space unit normal written
/// into one row (`rays::write_hit` for the merged mesh; the two levels' `TwoLevel::name`).
pub(super) type NameHit<'a> =
    dyn Fn(&crate::accel::Hit, &mut f32, &mut u32, &mut u32, &mut [f32; 2], &mut [f32; 3]) + Sync + 'a;

/// A GPU batch's chunk of hits with barycentrics (`ChunkAnswers::HitsUv`, from row `first`)
/// into `out`: a hit whose row `valid` accepts is named by `name`, anything else is a miss
/// (`t = inf`, ids `INVALID_ID`; its uv and normal left as they are). The GPU paths of
/// `cast_rays` (merged mesh and two levels) and of scans share it.
pub(super) fn write_gpu_hits(
    out: &mut RayHits,
    first: usize,
    hits: &[crate::gpu::layout::GpuHit],
    valid: impl Fn(usize) -> bool + Sync,
    name: &NameHit,
) {
    let end = first + hits.len();
    out.par_rows_mut(first..end)
        .zip((hits, first..end))
        .with_min_len(1024)
        .for_each(|((t, g, p, uv, n), (h, row))| {
            let h = crate::gpu::gpu_hit(*h);
            if h.is_hit() && valid(row) {
                name(&h, t, g, p, uv, n);
            } else {
                (*t, *g, *p) = (f32::INFINITY, INVALID_ID, INVALID_ID);
            }
        });
}

/// Closest hits, one entry per ray (Open3D's `cast_rays` keys). A miss: `t_hit = inf`, ids
/// `INVALID_ID`, uv and normal zero.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RayHits {
    pub t_hit: Vec<f32>,
    pub geometry_ids: Vec<u32>,
    /// The face's index in its geometry's faces.
    pub primitive_ids: Vec<u32>,
    /// Barycentric weights of the face's second and third vertex at the hit.
    pub primitive_uvs: Vec<[f32; 2]>,
    /// Unit geometric normal of the face in world space (input winding).
    pub primitive_normals: Vec<[f32; 3]>,
}

impl RayHits {
    pub(super) fn misses(n: usize) -> RayHits {
        RayHits {
            t_hit: vec![f32::INFINITY; n],
            geometry_ids: vec![INVALID_ID; n],
            primitive_ids: vec![INVALID_ID; n],
            primitive_uvs: vec![[0.0; 2]; n],
            primitive_normals: vec![[0.0; 3]; n],
        }
    }

    /// Zeros, for a query that writes every entry (misses included; a miss's uv and normal
    /// are the zeros already there). Zeroed memory comes from the allocator as fresh pages,
    /// not written here: `misses` writes 32 bytes a ray on one thread (a tenth of a
    /// million-ray `cast_rays`), while these pages are faulted in by the threads that fill
    /// them, in huge pages where the system allows.
    pub(super) fn zeroed(n: usize) -> RayHits {
        let mut h = RayHits {
            t_hit: vec![0.0; n],
            geometry_ids: vec![0; n],
            primitive_ids: vec![0; n],
            primitive_uvs: vec![[0.0; 2]; n],
            primitive_normals: vec![[0.0; 3]; n],
        };
        advise_huge_pages_within(&mut h.t_hit);
        advise_huge_pages_within(&mut h.geometry_ids);
        advise_huge_pages_within(&mut h.primitive_ids);
        advise_huge_pages_within(&mut h.primitive_uvs);
        advise_huge_pages_within(&mut h.primitive_normals);
        h
    }

    pub fn len(&self) -> usize {
        self.t_hit.len()
    }

    /// The five outputs cut into chunks of `n` rows, a chunk's five side by side: what the
    /// paths that fill them on all cores split.
    pub(super) fn par_chunks_mut(&mut self, n: usize) -> impl IndexedParallelIterator<Item = HitsChunk<'_>> {
        (
            self.t_hit.par_chunks_mut(n),
            self.geometry_ids.par_chunks_mut(n),
            self.primitive_ids.par_chunks_mut(n),
            self.primitive_uvs.par_chunks_mut(n),
            self.primitive_normals.par_chunks_mut(n),
        )
            .into_par_iter()
    }

    /// Rows `rows` of the five outputs, a row's five entries side by side: what the GPU's
    /// answers, a chunk at a time, are written into.
    pub(super) fn par_rows_mut(
        &mut self,
        rows: std::ops::Range<usize>,
    ) -> impl IndexedParallelIterator<Item = HitsRow<'_>> {
        (
            &mut self.t_hit[rows.clone()],
            &mut self.geometry_ids[rows.clone()],
            &mut self.primitive_ids[rows.clone()],
            &mut self.primitive_uvs[rows.clone()],
            &mut self.primitive_normals[rows],
        )
            .into_par_iter()
    }

    pub fn is_empty(&self) -> bool {
        self.t_hit.is_empty()
    }
}

/// A ray's origin and direction, `None` when it cannot hit anything: a non-finite component
/// or a zero direction.
#[inline(always)]
pub(crate) fn ray_of(r: &[f32; 6]) -> Option<Ray> {
    let o = Vec3::new(r[0], r[1], r[2]);
    let d = Vec3::new(r[3], r[4], r[5]);
    (o.is_finite() && d.is_finite() && d != Vec3::ZERO).then(|| Ray::new(o, d))
}

/// A ray that stands in for one that cannot hit anything, so that the batch stays whole; its
/// answer is replaced by a miss.
pub(crate) const STAND_IN: Ray = Ray::new(Vec3::ZERO, Vec3::X);

/// One value for every ray of a batch, or one each.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PerRay<'a, T> {
    All(T),
    Each(&'a [T]),
}

impl<T: Copy> PerRay<'_, T> {
    #[inline(always)]
    fn at(&self, i: usize) -> T {
        match self {
            PerRay::All(v) => *v,
            PerRay::Each(v) => v[i],
        }
    }
}

/// What each ray of a query sees: hits with `t_near < t < t_far`, of geometries whose mask
/// shares a bit with the ray's (`ray_mask & geometry_mask != 0`: Embree's, OptiX's and
/// Vulkan's rule). A ray with `t_near > t_far` sees nothing (Embree's rule). The default is
/// what the queries without options see: `0 < t < inf`, every geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayOptions<'a> {
    pub t_near: PerRay<'a, f32>,
    pub t_far: PerRay<'a, f32>,
    pub mask: PerRay<'a, u32>,
}

impl Default for RayOptions<'_> {
    fn default() -> Self {
        RayOptions {
            t_near: PerRay::All(0.0),
            t_far: PerRay::All(f32::INFINITY),
            mask: PerRay::All(u32::MAX),
        }
    }
}

impl RayOptions<'_> {
    /// An error naming the argument (and the ray) for arrays of another length than `rays`,
    /// a NaN bound or a negative `t_near` (the walks count `t` from the origin on).
    pub fn check(&self, rays: usize) -> Result<()> {
        fn len<T>(p: &PerRay<'_, T>, rays: usize, what: &str) -> Result<()> {
            match p {
                PerRay::Each(v) if v.len() != rays => Err(Error::InvalidInput(format!(
                    "{what} has {} entries for {rays} rays",
                    v.len()
                ))),
                _ => Ok(()),
            }
        }
        len(&self.t_near, rays, "tnear")?;
        len(&self.t_far, rays, "tfar")?;
        len(&self.mask, rays, "mask")?;
        let bad = |p: &PerRay<'_, f32>, ok: fn(f32) -> bool, what: &str, want: &str| -> Result<()> {
            let at = match p {
                PerRay::All(v) => (!ok(*v)).then(|| (what.to_string(), *v)),
                PerRay::Each(v) => v.iter().position(|&x| !ok(x)).map(|i| (format!("{what}[{i}]"), v[i])),
            };
            match at {
                Some((name, v)) => Err(Error::InvalidInput(format!("{name} = {v}: {want}"))),
                None => Ok(()),
            }
        };
        bad(&self.t_near, |x| x >= 0.0, "tnear", "need a number >= 0")?;
        bad(&self.t_far, |x| !x.is_nan(), "tfar", "need a number (inf for no bound)")
    }

    /// `(t_near, t_far, mask)` of ray `i`.
    #[inline(always)]
    pub fn of(&self, i: usize) -> (f32, f32, u32) {
        (self.t_near.at(i), self.t_far.at(i), self.mask.at(i))
    }

    /// `ray` asking ray `i`'s interval and mask.
    #[inline(always)]
    pub fn on(&self, i: usize, ray: Ray) -> Ray {
        let (t_near, t_far, mask) = self.of(i);
        ray.within(t_near, t_far).with_mask(mask)
    }

    /// `(t_near, t_far, mask)` when every ray has the same.
    pub fn uniform(&self) -> Option<(f32, f32, u32)> {
        match (self.t_near, self.t_far, self.mask) {
            (PerRay::All(n), PerRay::All(f), PerRay::All(m)) => Some((n, f, m)),
            _ => None,
        }
    }
}
