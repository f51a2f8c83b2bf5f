//! The box test of a whole packet (Wald et al. 2006's interval culling): one test of a node's
//! eight boxes for all the rays of a packet that go the same way along each axis, used by the
//! packet walk (`coherent.rs`).

use crate::accel::PACKET;
use crate::accel::lanes::{F8, Lanes, M8};

#[cfg(test)]
use super::box_test::BoxRay;
use super::box_test::FAR_SCALE;
use super::wide::{WIDTH, WideNode};

/// The box test of a whole packet whose rays go the same way along each axis (the same near
/// and far planes): interval arithmetic over the rays' origins and inverse directions (Wald
/// et al. 2006's interval culling, Reshetov et al. 2005's frusta). Conservative exactly, not
/// just in real numbers: the slab distance `(plane - o) * inv` is computed with one subtract
/// and one multiply, each rounding monotonically, so over the packet it is least (most) at an
/// end of the origins' range and an end of the inverse directions' range; the bounds below
/// take those ends, and every comparison after is monotone too. A box one ray's own test
/// (`BoxRay::enter`) enters is thus entered here, at no later a distance.
pub(super) struct Interval {
    /// Per axis, the near and far plane arrays (indices: `BoxRay::near` / `far` over 32).
    near: [usize; 3],
    far: [usize; 3],
    /// The origin coordinate giving the least near distance, and the greatest far one.
    o_near: [f32; 3],
    o_far: [f32; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
}

impl Interval {
    /// `None` where the rays' directions differ in sign along an axis.
    #[cfg(test)]
    pub(super) fn new(rays: &[BoxRay]) -> Option<Interval> {
        let mut origin = [[0.0; PACKET]; 3];
        let mut inv = [[0.0; PACKET]; 3];
        let mut down = [0u32; 3];
        for i in 0..PACKET {
            let r = &rays[i.min(rays.len() - 1)];
            for a in 0..3 {
                origin[a][i] = r.origin[a];
                inv[a][i] = -r.neg_inv[a];
                down[a] |= (r.goes_down(a) as u32) << i;
            }
        }
        Interval::from_lanes(&origin, &inv, down)
    }

    /// From a packet's rays in lanes (`PACKET` of them; lanes past the packet repeat a ray of
    /// it): origins, inverse directions (`1 / dir` as `BoxRay::new` takes it) and per axis the lanes going
    /// down it. `None` where the rays' directions differ in sign along an axis.
    #[inline(always)]
    pub(super) fn from_lanes(
        origin: &[[f32; PACKET]; 3],
        inv: &[[f32; PACKET]; 3],
        down: [u32; 3],
    ) -> Option<Interval> {
        const ALL: u32 = (1 << PACKET) - 1;
        if down.iter().any(|&m| m != 0 && m != ALL) {
            return None;
        }
        let lo = |v: &[f32; PACKET]| v.iter().fold(f32::INFINITY, |a, &b| a.min(b));
        let hi = |v: &[f32; PACKET]| v.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        let mut iv = Interval {
            near: [0, 1, 2],
            far: [3, 4, 5],
            o_near: [0.0; 3],
            o_far: [0.0; 3],
            inv_lo: [0.0; 3],
            inv_hi: [0.0; 3],
        };
        for a in 0..3 {
            // Going up the axis a slab distance falls as the origin rises; going down, it
            // rises with it. (As `BoxRay`: the high planes are the near ones going down.)
            let up = down[a] == 0;
            (iv.near[a], iv.far[a]) = if up { (a, 3 + a) } else { (3 + a, a) };
            let (o_lo, o_hi) = (lo(&origin[a]), hi(&origin[a]));
            (iv.o_near[a], iv.o_far[a]) = if up { (o_hi, o_lo) } else { (o_lo, o_hi) };
            (iv.inv_lo[a], iv.inv_hi[a]) = (lo(&inv[a]), hi(&inv[a]));
        }
        Some(iv)
    }

    /// Entry distances (lower bounds over the rays) into the node's boxes within
    /// `[t_min, t_max]`, `t_max` the greatest of the rays' search distances, and the entered
    /// lanes. Only in code compiled for the eight-lane build (always inlined there).
    #[inline(always)]
    pub(super) fn enter(&self, n: &WideNode, t_min: f32, t_max: f32) -> (F8, M8) {
        let mut t_enter = F8::splat(t_min);
        let mut t_exit = F8::INFINITY;
        for a in 0..3 {
            // SAFETY: `near` and `far` index the six plane arrays (as `BoxRay`'s), each eight
            // f32s.
            let (near, far) = unsafe {
                let planes = n.planes.as_ptr() as *const [f32; WIDTH];
                (
                    F8::load(&*planes.add(self.near[a])),
                    F8::load(&*planes.add(self.far[a])),
                )
            };
            let (lo, hi) = (F8::splat(self.inv_lo[a]), F8::splat(self.inv_hi[a]));
            let dn = near - F8::splat(self.o_near[a]);
            let df = far - F8::splat(self.o_far[a]);
            let t_near = (dn * lo).min(dn * hi);
            let t_far = (df * lo).max(df * hi);
            t_enter = t_enter.max(t_near);
            t_exit = t_exit.min(t_far);
        }
        let t_exit = (t_exit * F8::splat(FAR_SCALE)).min(F8::splat(t_max));
        (t_enter, t_enter.le(t_exit))
    }

    /// `enter` as arrays, for the tests.
    ///
    /// # Safety
    /// The CPU must run the eight-lane build (`simd::has_wide`).
    #[cfg(test)]
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    pub(super) unsafe fn enter_for_test(&self, n: &WideNode, t_min: f32, t_max: f32) -> ([f32; WIDTH], u32) {
        use crate::accel::lanes::Mask;
        let (t, m) = self.enter(n, t_min, t_max);
        (t.to_array(), m.bits())
    }
}
