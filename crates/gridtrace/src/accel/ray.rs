//! What every structure's traversal shares: rays, hits and the counters of traversal work.

use glam::Vec3;

/// A ray `origin + t * dir` and what it asks: hits with `t_min <= t < t_max`, in the instances
/// whose mask shares a bit with `mask` (`ray.mask & instance.mask != 0`: Embree's, OptiX's and
/// Vulkan's rule). `dir` need not be normalised: `t` is in units of its length. An interval
/// with `t_min > t_max` (or NaN) is empty, so the ray misses (Embree's rule). A structure over
/// one mesh reads the interval and ignores the mask; the top level of a scene applies the
/// mask (`query_scene/top_level/`).
///
/// The 24 bytes the GPU's wire and ray files take are the origin and direction alone
/// (`Ray::wire`): a batch's interval and mask travel once per batch, not once per ray.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub t_min: f32,
    pub t_max: f32,
    pub mask: u32,
}

impl Ray {
    /// Every hit in front of the origin (`0 <= t < INFINITY`), every instance seen.
    #[inline]
    pub const fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray {
            origin,
            dir,
            t_min: 0.0,
            t_max: f32::INFINITY,
            mask: u32::MAX,
        }
    }

    /// This ray with hits asked for in `t_min <= t < t_max`.
    #[inline]
    pub const fn within(self, t_min: f32, t_max: f32) -> Ray {
        Ray { t_min, t_max, ..self }
    }

    /// This ray up to `t_max` (the interval's start kept).
    #[inline]
    pub const fn upto(self, t_max: f32) -> Ray {
        Ray { t_max, ..self }
    }

    /// This ray seeing only the instances whose mask shares a bit with `mask`.
    #[inline]
    pub const fn with_mask(self, mask: u32) -> Ray {
        Ray { mask, ..self }
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// The origin and direction as the GPU's wire and ray files lay them out: six floats.
    #[inline]
    pub fn wire(&self) -> [f32; 6] {
        let (o, d) = (self.origin, self.dir);
        [o.x, o.y, o.z, d.x, d.y, d.z]
    }
}

/// Closest hit. A miss is explicit: `t = INFINITY`, `tri = u32::MAX`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub tri: u32,
    pub u: f32,
    pub v: f32,
}

impl Hit {
    pub const MISS: Hit = Hit {
        t: f32::INFINITY,
        tri: u32::MAX,
        u: 0.0,
        v: 0.0,
    };
    pub fn is_hit(&self) -> bool {
        self.tri != u32::MAX
    }
}

/// Traversal counters. The no-op implementation compiles to nothing, so the hot loop pays for
/// statistics only when they are asked for.
pub trait Counters {
    /// Whether these counters count: a walk that counts must visit what the single-ray walk
    /// visits (the counts are compared), one that does not may take another route to the same
    /// answers (the BVH's coherent packets).
    const COUNTS: bool = true;
    fn cell(&mut self) {}
    fn jump(&mut self) {}
    fn tri_test(&mut self) {}
}

/// Counters that cost nothing.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoCounters;
impl Counters for NoCounters {
    const COUNTS: bool = false;
}

/// Counters that count.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct TraversalCounters {
    /// Cells visited (DDA steps plus landing cells of jumps).
    pub cells: u64,
    /// Proximity-cloud jumps taken.
    pub jumps: u64,
    /// Ray/triangle tests.
    pub tri_tests: u64,
}

impl Counters for TraversalCounters {
    #[inline(always)]
    fn cell(&mut self) {
        self.cells += 1;
    }
    #[inline(always)]
    fn jump(&mut self) {
        self.jumps += 1;
    }
    #[inline(always)]
    fn tri_test(&mut self) {
        self.tri_tests += 1;
    }
}

impl std::ops::AddAssign for TraversalCounters {
    fn add_assign(&mut self, o: Self) {
        self.cells += o.cells;
        self.jumps += o.jumps;
        self.tri_tests += o.tri_tests;
    }
}
