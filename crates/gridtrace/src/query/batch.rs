//! A batch of rays as callers pass it (origins and directions, either may be one value
//! broadcast over the other), checked ray by ray and cut into chunks and work items.

use glam::Vec3;
use rayon::prelude::*;

use crate::accel::Ray;
use crate::{Error, Result};

/// Rays are processed in chunks of this many, so temporary memory stays bounded however large
/// the batch.
pub const CHUNK: usize = 1 << 20;

/// Rays per CPU work item: large enough to amortise scheduling, small enough to balance two
/// to hundreds of threads over a chunk. The CPU validates and traces each work item's rays on
/// its own and writes the results straight into the output: besides the output, a query
/// allocates nothing of the batch's size (no array of rays, no array of hits).
pub(super) const CPU_BATCH: usize = 1024;

/// Runs `f` on the CPU for every `CPU_BATCH` rays of a (possibly broadcast, checked) batch of
/// `n`, each ray asking `interval`, in parallel, each with its piece of the output (`pieces`
/// yields one per `CPU_BATCH` rays).
pub(super) fn on_cpu_batches<P: Send>(
    (origins, dirs): (&[[f32; 3]], &[[f32; 3]]),
    n: usize,
    (t_min, t_max): (f32, f32),
    pieces: impl IndexedParallelIterator<Item = P>,
    f: impl Fn(&[Ray], P) + Sync + Send,
) -> Result<()> {
    let done = pieces.enumerate().try_for_each_init(
        || Vec::with_capacity(CPU_BATCH),
        |rays, (b, piece)| {
            rays.clear();
            // The same rule as `ray_at`, without a branch per ray: a bad ray is rare, and then
            // `first_bad_ray` finds and names it.
            let mut all_good = true;
            for i in b * CPU_BATCH..((b + 1) * CPU_BATCH).min(n) {
                let (o, d) = ray_parts(origins, dirs, i);
                all_good &= is_valid_ray(o, d);
                rays.push(Ray::new(o, d).within(t_min, t_max));
            }
            if !all_good {
                return None;
            }
            f(rays, piece);
            Some(())
        },
    );
    done.ok_or_else(|| first_bad_ray(origins, dirs, 0, n))
}

pub(super) fn batch_len(origins: &[[f32; 3]], dirs: &[[f32; 3]]) -> Result<usize> {
    match (origins.len(), dirs.len()) {
        (a, b) if a == b => Ok(a),
        (1, b) => Ok(b),
        (a, 1) => Ok(a),
        (a, b) => Err(Error::InvalidInput(format!(
            "{a} origins and {b} directions: lengths must match (or one be 1)"
        ))),
    }
}

pub(super) fn check_interval(t_min: f32, t_max: f32) -> Result<()> {
    if t_min.is_nan() || t_max.is_nan() || t_min < 0.0 || t_min > t_max {
        return Err(Error::InvalidInput(format!(
            "need 0 <= t_min <= t_max, got t_min = {t_min}, t_max = {t_max}"
        )));
    }
    Ok(())
}

/// Origin and direction of ray `i` of a (possibly broadcast) batch, unchecked.
#[inline(always)]
pub(super) fn ray_parts(origins: &[[f32; 3]], dirs: &[[f32; 3]], i: usize) -> (Vec3, Vec3) {
    let o = Vec3::from(origins[if origins.len() == 1 { 0 } else { i }]);
    let d = Vec3::from(dirs[if dirs.len() == 1 { 0 } else { i }]);
    (o, d)
}

/// The rule for a ray: finite origin and direction, and a direction that is not zero.
#[inline(always)]
pub(super) fn is_valid_ray(o: Vec3, d: Vec3) -> bool {
    o.is_finite() & d.is_finite() & (d != Vec3::ZERO)
}

/// Ray `i` of a (possibly broadcast) batch; a ray that breaks `is_valid_ray` is an error naming
/// the ray and what is wrong with it.
pub(super) fn ray_at(origins: &[[f32; 3]], dirs: &[[f32; 3]], i: usize) -> Result<Ray> {
    let (o, d) = ray_parts(origins, dirs, i);
    if is_valid_ray(o, d) {
        return Ok(Ray::new(o, d));
    }
    if !o.is_finite() || !d.is_finite() {
        return Err(Error::InvalidInput(format!(
            "ray {i} has a non-finite origin {o} or direction {d}"
        )));
    }
    Err(Error::InvalidInput(format!("ray {i} has a zero direction")))
}

/// The error of the first bad ray among `start..end` (whichever thread saw one).
pub(super) fn first_bad_ray(origins: &[[f32; 3]], dirs: &[[f32; 3]], start: usize, end: usize) -> Error {
    (start..end)
        .find_map(|i| ray_at(origins, dirs, i).err())
        .unwrap_or_else(|| Error::InvalidInput("a ray failed validation".into()))
}
