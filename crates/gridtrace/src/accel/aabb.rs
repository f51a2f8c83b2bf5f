//! Axis-aligned boxes and the ray/box slab clip that enters the grid.

use glam::Vec3;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a Vec3>) -> Aabb {
        points.into_iter().fold(Aabb::EMPTY, |b, p| b.grow(*p))
    }

    pub fn grow(self, p: Vec3) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    pub fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        !(self.min.cmple(self.max).all())
    }

    pub fn extent(&self) -> Vec3 {
        (self.max - self.min).max(Vec3::ZERO)
    }

    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    pub fn diagonal(&self) -> f32 {
        self.extent().length()
    }

    /// Clips the ray `origin + t * dir` against the closed box: returns the parametric interval
    /// `[t_enter, t_exit]` intersected with `[t_min, t_max]`, or `None` if it is empty.
    ///
    /// An axis with `dir == 0` constrains nothing if the origin lies within that slab (boundary
    /// included) and empties the interval otherwise; it is handled apart because the slab
    /// formula would give `0 * inf = NaN` for an origin on the slab plane. The GPU kernels do
    /// the same (`clip_box` in common.wgsl).
    #[inline]
    pub fn clip(&self, origin: Vec3, inv_dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
        let mut t_enter = t_min;
        let mut t_exit = t_max;
        for a in 0..3 {
            if inv_dir[a].is_infinite() {
                if origin[a] < self.min[a] || origin[a] > self.max[a] {
                    return None;
                }
            } else {
                let t0 = (self.min[a] - origin[a]) * inv_dir[a];
                let t1 = (self.max[a] - origin[a]) * inv_dir[a];
                t_enter = t_enter.max(t0.min(t1));
                t_exit = t_exit.min(t0.max(t1));
            }
        }
        (t_enter <= t_exit).then_some((t_enter, t_exit))
    }
}
