//! What every structure's traversal shares: rays, hits and the counters of traversal work.

use glam::Vec3;

/// A ray `origin + t * dir`. `dir` need not be normalised: `t` is in units of its length.
/// `repr(C)`: six floats, origin then direction, the layout of ray files and Open3D's rows, so
/// that a slice of rays goes to the GPU as it is (`gpu::queries`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray { origin, dir }
    }
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
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
