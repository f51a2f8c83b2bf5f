//! The rays of a CPU render, recorded instead of shaded: the same eye, shadow and reflection
//! rays that `cpu::render` traces (it follows `trace_pixel` step by step), each with the `t` of
//! its hit (closest hit for eye and reflection rays, any hit for shadow rays; infinity on a miss).

use std::io::Write;
use std::path::Path;

use rayon::prelude::*;

use crate::accel::{NoCounters, Ray};
use crate::cpu::surface_at;
use crate::render::{Mode, RayCounts, RenderOptions};
use crate::scene::PreparedScene;
use crate::{Error, Result};

/// Which kind of ray a record is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayKind {
    Eye,
    Shadow,
    Reflection,
}

/// One traced ray and the `t` of its hit (`f32::INFINITY` on a miss). Shadow rays stop at the
/// light: `t` is that of any occluder found before it, else infinity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayRecord {
    pub kind: RayKind,
    pub ray: Ray,
    pub t: f32,
}

/// All rays of a render, in pixel order (row by row), each pixel's rays in the order traced.
#[derive(Debug, Clone, Default)]
pub struct RaySet {
    pub records: Vec<RayRecord>,
}

impl RaySet {
    pub fn counts(&self) -> RayCounts {
        let mut c = RayCounts::default();
        for r in &self.records {
            match r.kind {
                RayKind::Eye => c.eye += 1,
                RayKind::Shadow => c.shadow += 1,
                RayKind::Reflection => c.reflection += 1,
            }
        }
        c
    }

    /// Rays as 6 little-endian f32 each: origin x, y, z, direction x, y, z.
    pub fn write_rays(&self, path: &Path) -> Result<()> {
        let mut buf = Vec::with_capacity(self.records.len() * 24);
        for r in &self.records {
            for v in [r.ray.origin.to_array(), r.ray.dir.to_array()].concat() {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
        write_file(path, &buf)
    }

    /// Hit `t` per ray as one little-endian f32 each (infinity for a miss).
    pub fn write_hits(&self, path: &Path) -> Result<()> {
        let mut buf = Vec::with_capacity(self.records.len() * 4);
        for r in &self.records {
            buf.extend_from_slice(&r.t.to_le_bytes());
        }
        write_file(path, &buf)
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let mut f = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    f.write_all(bytes).map_err(|e| Error::io(path, e))
}

/// Records the rays a CPU render of `scene` with `opts` traces. Heat mode records eye rays only.
pub fn collect_rays(scene: &PreparedScene, opts: &RenderOptions) -> Result<RaySet> {
    opts.validate()?;
    let cam = scene.camera.frame(opts.width, opts.height);
    let width = opts.width;
    let rows: Vec<Vec<RayRecord>> = (0..opts.height)
        .into_par_iter()
        .map(|y| {
            let mut out = Vec::with_capacity(width as usize);
            for x in 0..width {
                pixel_rays(scene, cam.ray(x, y), opts, &mut out);
            }
            out
        })
        .collect();
    Ok(RaySet {
        records: rows.into_iter().flatten().collect(),
    })
}

/// The rays of one pixel, as `cpu::render`'s `trace_pixel` traces them.
fn pixel_rays(scene: &PreparedScene, eye: Ray, opts: &RenderOptions, out: &mut Vec<RayRecord>) {
    let accel = &scene.accel;
    let mut ray = eye;
    let mut kind = RayKind::Eye;
    for depth in 0..=opts.mode.reflection_depth() {
        let hit = accel.intersect(&ray, 0.0, f32::INFINITY, opts.accel, &mut NoCounters);
        out.push(RayRecord { kind, ray, t: hit.t });
        if !hit.is_hit() || opts.mode == Mode::Heat {
            break;
        }
        let s = surface_at(scene, &ray, &hit);
        let mat = &scene.materials[scene.tri_material[hit.tri as usize] as usize];
        let reflect = if opts.mode == Mode::Trace {
            mat.reflectivity
        } else {
            0.0
        };
        let origin = s.position + s.ng * scene.ray_epsilon;
        if opts.mode.shadows() {
            for light in &scene.lights {
                let Some((_, to_light, dist)) = crate::cpu::light_contribution(&s, origin, light) else {
                    continue;
                };
                let shadow = Ray::new(origin, to_light);
                let t = first_occluder(scene, &shadow, dist, opts);
                out.push(RayRecord {
                    kind: RayKind::Shadow,
                    ray: shadow,
                    t,
                });
            }
        }
        if reflect > 0.0 && depth < opts.mode.reflection_depth() {
            let d = ray.dir - 2.0 * ray.dir.dot(s.ns) * s.ns;
            ray = Ray::new(origin, d.normalize());
            kind = RayKind::Reflection;
        } else {
            break;
        }
    }
}

/// `t` of an occluder of a shadow ray before the light (the renderer's any-hit query decides
/// whether there is one; the closest one's `t` is reported), infinity if the light is visible.
fn first_occluder(scene: &PreparedScene, ray: &Ray, dist: f32, opts: &RenderOptions) -> f32 {
    if !scene.accel.occluded(ray, 0.0, dist, opts.accel, &mut NoCounters) {
        return f32::INFINITY;
    }
    let h = scene.accel.intersect(ray, 0.0, dist, opts.accel, &mut NoCounters);
    if h.is_hit() { h.t } else { dist }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{AccelKind, Resolution, scene::builtin};

    #[test]
    fn same_ray_counts_as_the_renderer() {
        let prepared = builtin::mirror_spheres().prepare(Resolution::default()).unwrap();
        for mode in [Mode::Cast, Mode::Shadow, Mode::Trace] {
            for accel in [AccelKind::Grid, AccelKind::ProximityCloud] {
                let opts = RenderOptions::new(40, 30, mode, accel);
                let set = collect_rays(&prepared, &opts).unwrap();
                let (_, stats) = crate::cpu::render(&prepared, &opts, None).unwrap();
                assert_eq!(set.counts(), stats.rays, "{mode:?} {accel:?}");
            }
        }
    }

    #[test]
    fn binary_layout() {
        let prepared = builtin::knot_box().prepare(Resolution::default()).unwrap();
        let set = collect_rays(&prepared, &RenderOptions::new(8, 4, Mode::Cast, AccelKind::Grid)).unwrap();
        let dir = std::env::temp_dir().join(format!("gridtrace-rays-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        set.write_rays(&dir.join("r.bin")).unwrap();
        set.write_hits(&dir.join("h.bin")).unwrap();
        let r = std::fs::read(dir.join("r.bin")).unwrap();
        let h = std::fs::read(dir.join("h.bin")).unwrap();
        assert_eq!(r.len(), 32 * 24);
        assert_eq!(h.len(), 32 * 4);
        let f = |b: &[u8], i: usize| f32::from_le_bytes(b[i * 4..i * 4 + 4].try_into().unwrap());
        assert_eq!(f(&r, 0), set.records[0].ray.origin.x);
        // Camera inside the box: every eye ray hits something.
        assert!((0..32).all(|i| f(&h, i).is_finite() && f(&h, i) > 0.0));
    }
}
