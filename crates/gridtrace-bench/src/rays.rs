//! The rays of a CPU render, recorded: the eye, shadow and reflection rays that `cpu::render`
//! traces, seen through the renderer's own walk (`cpu::RayObserver`), each with the `t` of its
//! hit (closest hit for eye and reflection rays, the closest occluder for shadow rays;
//! infinity on a miss).

use std::io::Write;
use std::path::Path;

use rayon::prelude::*;

use gridtrace::accel::{Hit, NoCounters, Ray};
use gridtrace::cpu::RayObserver;
use gridtrace::render::{RayCounts, RenderOptions};
use gridtrace::scene::PreparedScene;
use gridtrace::{Error, Result};

/// Which kind of ray a record is (the renderer's own).
pub use gridtrace::cpu::RayKind;

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
    let rows: Vec<Vec<RayRecord>> = (0..opts.height)
        .into_par_iter()
        .map(|y| {
            let mut recorder = Recorder {
                scene,
                out: Vec::with_capacity(opts.width as usize),
            };
            for x in 0..opts.width {
                gridtrace::cpu::trace_pixel_observed(scene, &cam, (x, y), opts, &mut recorder);
            }
            recorder.out
        })
        .collect();
    Ok(RaySet {
        records: rows.into_iter().flatten().collect(),
    })
}

/// Records the rays of the renderer's own walk (`cpu::trace_pixel_observed`), in the order it
/// traces them.
struct Recorder<'a> {
    scene: &'a PreparedScene,
    out: Vec<RayRecord>,
}

impl RayObserver for Recorder<'_> {
    fn closest(&mut self, kind: RayKind, ray: &Ray, hit: &Hit) {
        self.out.push(RayRecord {
            kind,
            ray: *ray,
            t: hit.t,
        });
    }

    /// The renderer's any-hit query decided whether the light is occluded; the record carries
    /// the closest occluder's `t` (infinity when the light is visible).
    fn shadow(&mut self, ray: &Ray, dist: f32, occluded: bool) {
        let t = if occluded {
            let h = self.scene.accel.intersect(&ray.within(0.0, dist), &mut NoCounters);
            if h.is_hit() { h.t } else { dist }
        } else {
            f32::INFINITY
        };
        self.out.push(RayRecord {
            kind: RayKind::Shadow,
            ray: *ray,
            t,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gridtrace::{AccelKind, Mode, Resolution, scene::builtin};

    #[test]
    fn same_ray_counts_as_the_renderer() {
        let prepared = builtin::mirror_spheres().prepare(Resolution::default()).unwrap();
        for mode in [Mode::Cast, Mode::Shadow, Mode::Trace] {
            for accel in [AccelKind::Grid, AccelKind::ProximityCloud] {
                let opts = RenderOptions::new(40, 30, mode);
                let set = collect_rays(&prepared, &opts).unwrap();
                let (_, stats) = gridtrace::cpu::render(&prepared, &opts, None).unwrap();
                assert_eq!(set.counts(), stats.rays, "{mode:?} {accel:?}");
            }
        }
    }

    #[test]
    fn binary_layout() {
        let prepared = builtin::knot_box().prepare(Resolution::default()).unwrap();
        let set = collect_rays(&prepared, &RenderOptions::new(8, 4, Mode::Cast)).unwrap();
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
