//! Lanes of `f32`: the SIMD vocabulary that the packet triangle test (`triangle/packed.rs`) and the
//! irregular grid's packet walk (`irregular/packet.rs`) are written in, once, for four lanes
//! (glam's `Vec4`: SSE on x86-64, NEON on aarch64) and for eight (`F8`, `simd`'s: AVX2 or NEON,
//! only in code compiled for the eight-lane path; without it a packet of eight runs as two
//! packets of four).
//!
//! Every operation is IEEE arithmetic lane by lane, so a lane rounds exactly as the scalar code
//! does (Rust never fuses multiply-adds on its own): the packet code's bit-for-bit agreement
//! with the single-ray code rests on that. Comparisons and `min` follow the SSE rules that the
//! callers rely on: an ordered comparison is false when either side is NaN, and `min(a, b)` is
//! `a < b ? a : b` (NaN in either gives `b`).

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

use glam::{BVec4A, Vec4};

/// A lane mask: all bits set (true) or clear (false) per lane.
pub trait Mask: Copy + BitAnd<Output = Self> + BitOr<Output = Self> + Not<Output = Self> {
    /// Lane `i` true where bit `i` of `bits` is set.
    fn from_bits(bits: u32) -> Self;
    /// Bit `i` set where lane `i` is true.
    fn bits(self) -> u32;
}

/// `N` lanes of `f32`.
pub trait Lanes<const N: usize>:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    type Mask: Mask;
    const ZERO: Self;
    const ONE: Self;
    const INFINITY: Self;
    fn splat(x: f32) -> Self;
    fn from_array(a: [f32; N]) -> Self;
    fn to_array(self) -> [f32; N];
    /// Lane by lane `mask ? a : b`.
    fn select(mask: Self::Mask, a: Self, b: Self) -> Self;
    fn lt(self, b: Self) -> Self::Mask;
    fn le(self, b: Self) -> Self::Mask;
    fn gt(self, b: Self) -> Self::Mask;
    fn ge(self, b: Self) -> Self::Mask;
    fn ne(self, b: Self) -> Self::Mask;
    fn is_nan(self) -> Self::Mask;
    /// `self < b ? self : b`, as SSE's `min` (NaN in either: `b`).
    fn min(self, b: Self) -> Self;
    /// `self > b ? self : b`, as SSE's `max` (NaN in either: `b`).
    fn max(self, b: Self) -> Self;
    fn abs(self) -> Self;
    /// The correctly rounded square root (IEEE, as `f32::sqrt`), lane by lane.
    fn sqrt(self) -> Self;
    /// Truncation of values in `0..2^24` (voxel coordinates): exact through `i32`.
    fn trunc_small(self) -> Self;
    /// `self * b + c`, in one rounding where the lanes have a fused multiply-add (AVX2's
    /// builds enable FMA, which every AVX2 CPU has: `simd::has_wide`; NEON), else two.
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        self * b + c
    }
    /// `1 / sqrt(self)` to within a few units of `f32`'s last place (relative error below
    /// `1e-6`), for positive normal lanes (a subnormal may give infinity or NaN: AVX's
    /// estimate flushes it to 0); where lanes have an estimate instruction (AVX's `rsqrt`, 12
    /// bits) it is that and one Newton step, which costs a fraction of a division and a root
    /// in sequence (the dividing unit is not pipelined).
    #[inline(always)]
    fn rsqrt(self) -> Self {
        Self::ONE / self.sqrt()
    }
}

/// `[x, y, z]` each in every lane. (A function, not a closure passed to `map`: closures do not
/// inherit `#[target_feature]`, so there an AVX intrinsic would become a call.)
#[inline(always)]
pub fn splat3<const N: usize, L: Lanes<N>>(a: [f32; 3]) -> [L; 3] {
    [L::splat(a[0]), L::splat(a[1]), L::splat(a[2])]
}

/// Three arrays of lanes (`[x, y, z]`, a lane each) as lanes.
#[inline(always)]
pub fn load3<const N: usize, L: Lanes<N>>(a: [[f32; N]; 3]) -> [L; 3] {
    [L::from_array(a[0]), L::from_array(a[1]), L::from_array(a[2])]
}

impl Mask for BVec4A {
    #[inline(always)]
    fn from_bits(bits: u32) -> Self {
        BVec4A::new(bits & 1 != 0, bits & 2 != 0, bits & 4 != 0, bits & 8 != 0)
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        self.bitmask()
    }
}

impl Lanes<4> for Vec4 {
    type Mask = BVec4A;
    const ZERO: Self = Vec4::ZERO;
    const ONE: Self = Vec4::ONE;
    const INFINITY: Self = Vec4::INFINITY;
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Vec4::splat(x)
    }
    #[inline(always)]
    fn from_array(a: [f32; 4]) -> Self {
        Vec4::from_array(a)
    }
    #[inline(always)]
    fn to_array(self) -> [f32; 4] {
        Vec4::to_array(&self)
    }
    #[inline(always)]
    fn select(mask: BVec4A, a: Self, b: Self) -> Self {
        Vec4::select(mask, a, b)
    }
    #[inline(always)]
    fn lt(self, b: Self) -> BVec4A {
        self.cmplt(b)
    }
    #[inline(always)]
    fn le(self, b: Self) -> BVec4A {
        self.cmple(b)
    }
    #[inline(always)]
    fn gt(self, b: Self) -> BVec4A {
        self.cmpgt(b)
    }
    #[inline(always)]
    fn ge(self, b: Self) -> BVec4A {
        self.cmpge(b)
    }
    #[inline(always)]
    fn ne(self, b: Self) -> BVec4A {
        self.cmpne(b)
    }
    #[inline(always)]
    fn is_nan(self) -> BVec4A {
        self.is_nan_mask()
    }
    #[inline(always)]
    fn min(self, b: Self) -> Self {
        // On x86-64 glam's `Vec4::min` is SSE's `minps(self, b)`: `self < b ? self : b`.
        // Elsewhere (NEON's `fmin`: NaN from either side) the rule is written out.
        #[cfg(target_arch = "x86_64")]
        return Vec4::min(self, b);
        #[cfg(not(target_arch = "x86_64"))]
        Vec4::select(self.cmplt(b), self, b)
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        #[cfg(target_arch = "x86_64")]
        return Vec4::max(self, b);
        #[cfg(not(target_arch = "x86_64"))]
        Vec4::select(self.cmpgt(b), self, b)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Vec4::abs(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: SSE is part of x86-64; `Vec4` is an `__m128` there.
        return Vec4::from(unsafe { std::arch::x86_64::_mm_sqrt_ps(self.into()) });
        #[cfg(not(target_arch = "x86_64"))]
        Vec4::from_array(self.to_array().map(f32::sqrt))
    }
    #[inline(always)]
    fn trunc_small(self) -> Self {
        Vec4::trunc(self)
    }
}

/// Eight lanes (`simd`: one AVX register on x86-64, two NEON registers on aarch64), only in
/// code compiled for the eight-lane path and entered after `simd::has_wide()`.
pub(crate) use super::simd::{F8, M8};

#[cfg(test)]
mod tests {
    use super::*;

    /// The four lanes' (and where the CPU runs them, the eight lanes': AVX2 or NEON) operations agree with the
    /// scalar rules lane by lane, NaN, infinities, signed zeros and subnormals included.
    #[test]
    fn lanes_follow_the_scalar_rules() {
        check::<4, Vec4>();
        if crate::accel::simd::has_wide() {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            unsafe { check_f8() };
        }
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2,fma"))]
    unsafe fn check_f8() {
        check::<8, F8>();
    }

    #[inline(always)]
    fn check<const N: usize, L: Lanes<N>>() {
        let vals = [0.0, -0.0, 1.5, -2.25, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 3e-39];
        let all = (1u32 << N) - 1;
        for (i, &a) in vals.iter().enumerate() {
            for &b in &vals {
                let (x, y) = (L::splat(a), L::splat(b));
                let lane = i % N;
                let min = if a < b { a } else { b };
                let max = if a > b { a } else { b };
                for (got, want) in [
                    (x.min(y), min),
                    (x.max(y), max),
                    (x / y, a / b),
                    (x - y, a - b),
                    (x + y, a + b),
                    (x * y, a * b),
                    (x.abs(), a.abs()),
                    (x.sqrt(), a.sqrt()),
                ] {
                    assert_eq!(got.to_array()[lane].to_bits(), want.to_bits(), "{N} lanes: {a} {b}");
                }
                let whole = |want: bool| if want { all } else { 0 };
                for (got, want) in [
                    (x.lt(y), a < b),
                    (x.le(y), a <= b),
                    (x.gt(y), a > b),
                    (x.ge(y), a >= b),
                    (x.ne(y), a != b),
                    (x.is_nan(), a.is_nan()),
                ] {
                    assert_eq!(got.bits(), whole(want), "{N} lanes: {a} {b}");
                }
            }
        }
        // A different pair in every lane (the values above, shifted against each other): each
        // lane's result is its own pair's, so no lane reads a neighbour's operands.
        for shift in 0..vals.len() {
            let (mut a, mut b) = ([0.0; N], [0.0; N]);
            for k in 0..N {
                a[k] = vals[k % vals.len()];
                b[k] = vals[(k + shift) % vals.len()];
            }
            let (x, y) = (L::from_array(a), L::from_array(b));
            let sums = [x.min(y), x.max(y), x / y, x - y, x + y, x * y, x.abs(), x.sqrt()].map(L::to_array);
            let masks = [x.lt(y), x.le(y), x.gt(y), x.ge(y), x.ne(y), x.is_nan()].map(Mask::bits);
            for k in 0..N {
                let (a, b) = (a[k], b[k]);
                let want = [
                    if a < b { a } else { b },
                    if a > b { a } else { b },
                    a / b,
                    a - b,
                    a + b,
                    a * b,
                    a.abs(),
                    a.sqrt(),
                ];
                for (op, (got, want)) in sums.iter().zip(want).enumerate() {
                    assert_eq!(
                        got[k].to_bits(),
                        want.to_bits(),
                        "{N} lanes: op {op}, lane {k}: {a} {b}"
                    );
                }
                let want = [a < b, a <= b, a > b, a >= b, a != b, a.is_nan()];
                for (op, (got, want)) in masks.iter().zip(want).enumerate() {
                    assert_eq!(got >> k & 1 == 1, want, "{N} lanes: comparison {op}, lane {k}: {a} {b}");
                }
            }
        }
        let mut ramp = [0.0; N];
        for (k, r) in ramp.iter_mut().enumerate() {
            *r = k as f32 + 0.75;
        }
        let ramp = L::from_array(ramp);
        for bits in [0b1010_0110 & all, 1, all, 0] {
            let picked = L::select(L::Mask::from_bits(bits), L::ONE, L::ZERO);
            assert_eq!(
                picked.lt(L::splat(0.5)).bits(),
                !bits & all,
                "{N} lanes: select {bits:b}"
            );
            assert_eq!((!L::Mask::from_bits(bits)).bits(), !bits & all);
            assert_eq!(
                (L::Mask::from_bits(bits) & L::Mask::from_bits(0b11)).bits(),
                bits & 0b11
            );
            assert_eq!(
                (L::Mask::from_bits(bits) | L::Mask::from_bits(0b11)).bits(),
                (bits | 0b11) & all
            );
        }
        let truncated = ramp.trunc_small().to_array();
        for (k, t) in truncated.into_iter().enumerate() {
            assert_eq!(t, k as f32, "{N} lanes: lane order or truncation");
        }
        assert_eq!(ramp.lt(L::splat(2.0)).bits(), 0b11, "{N} lanes: lane order");
        // `mul_add`: `a b + c` rounded once or twice, so within an ulp of the product's and
        // the sum's scale; `rsqrt`: within 1e-6 of `1 / sqrt` relative, from the smallest
        // normal to huge (the estimate's 12 bits and one Newton step give about 22).
        let xs = [f32::MIN_POSITIVE, 1e-30, 0.1, 0.75, 1.0, 2.0, 3.5, 1e5, 7e20, 3e38];
        for (k, &a) in xs.iter().enumerate() {
            let (b, c) = (xs[(k + 3) % xs.len()].min(1e10), -xs[(k + 5) % xs.len()].min(1e30));
            let got = L::splat(a).mul_add(L::splat(b), L::splat(c)).to_array()[k % N];
            let want = f64::from(a) * f64::from(b) + f64::from(c);
            let scale = (f64::from(a) * f64::from(b)).abs().max(f64::from(c).abs());
            assert!(
                (f64::from(got) - want).abs() <= scale * 2.4e-7,
                "{N} lanes: mul_add {a} {b} {c}: {got}"
            );
            let got = f64::from(L::splat(a).rsqrt().to_array()[k % N]);
            let want = 1.0 / f64::from(a).sqrt();
            assert!(
                (got - want).abs() <= want * 1e-6,
                "{N} lanes: rsqrt {a}: {got} against {want}"
            );
        }
    }
}
