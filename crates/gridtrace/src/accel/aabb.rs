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

    /// Clips the ray `origin + t * dir` against the box: returns the parametric interval
    /// `[t_enter, t_exit]` intersected with `[t_min, t_max]`, or `None` if it is empty.
    ///
    /// `inv_dir` is `1 / dir` per component; a zero component gives +-inf, and the slab test then
    /// yields +-inf or NaN. NaN arises only when the origin lies exactly on a slab plane of a
    /// parallel axis (0 * inf); `f32::max`/`min` ignore NaN, which treats that slab as "no
    /// constraint" - the right answer for a ray lying in the boundary plane (the box is closed).
    #[inline]
    pub fn clip(&self, origin: Vec3, inv_dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
        let t0 = (self.min - origin) * inv_dir;
        let t1 = (self.max - origin) * inv_dir;
        let near = t0.min(t1);
        let far = t0.max(t1);
        let t_enter = t_min.max(near.x).max(near.y).max(near.z);
        let t_exit = t_max.min(far.x).min(far.y).min(far.z);
        (t_enter <= t_exit).then_some((t_enter, t_exit))
    }
}
