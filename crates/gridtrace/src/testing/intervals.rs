//! Rays given an interval for tests (`Ray::within` on one ray or on every ray of a batch), so
//! that tests written against walks that took `t_min, t_max` beside the ray read as they did.

use crate::accel::Ray;

/// Rays asking `t_min <= t < t_max`: a ray, or a batch as a new vector (`Ray::within` on each).
pub fn within<R: WithInterval + ?Sized>(rays: &R, t_min: f32, t_max: f32) -> R::Out {
    rays.with_interval(t_min, t_max)
}

/// Rays `rays[k]` asking `t_min <= t < t_max[k]` (a packet's shadow rays, each with its own
/// distance).
pub fn within_each(rays: &[Ray], t_min: f32, t_max: &[f32]) -> Vec<Ray> {
    rays.iter().zip(t_max).map(|(r, &t)| r.within(t_min, t)).collect()
}

/// What `within` takes: a ray or a batch of rays.
pub trait WithInterval {
    type Out;
    fn with_interval(&self, t_min: f32, t_max: f32) -> Self::Out;
}

impl WithInterval for Ray {
    type Out = Ray;
    fn with_interval(&self, t_min: f32, t_max: f32) -> Ray {
        self.within(t_min, t_max)
    }
}

impl WithInterval for [Ray] {
    type Out = Vec<Ray>;
    fn with_interval(&self, t_min: f32, t_max: f32) -> Vec<Ray> {
        self.iter().map(|r| r.within(t_min, t_max)).collect()
    }
}

impl<T: WithInterval + ?Sized> WithInterval for &T {
    type Out = T::Out;
    fn with_interval(&self, t_min: f32, t_max: f32) -> T::Out {
        (**self).with_interval(t_min, t_max)
    }
}

impl WithInterval for Vec<Ray> {
    type Out = Vec<Ray>;
    fn with_interval(&self, t_min: f32, t_max: f32) -> Vec<Ray> {
        self.as_slice().with_interval(t_min, t_max)
    }
}
