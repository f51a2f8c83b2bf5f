//! The eight-lane types as plain arrays, for targets with neither AVX2 nor NEON. There
//! `has_wide()` is false and the callers take their scalar paths; these keep the eight-lane
//! code compiling (and its tests running) with the same rules as the other backends.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

use crate::accel::lanes::{Lanes, Mask};

/// Eight lanes of `f32`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct F8([f32; 8]);

/// A mask of eight lanes: all bits set or clear per lane.
#[derive(Debug, Clone, Copy)]
pub(crate) struct M8([u32; 8]);

/// Eight lanes of `u32`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct U8([u32; 8]);

macro_rules! lanewise {
    ($t:ident, $trait:ident, $f:ident, $op:tt) => {
        impl $trait for $t {
            type Output = $t;
            #[inline(always)]
            fn $f(self, b: $t) -> $t {
                $t(std::array::from_fn(|k| self.0[k] $op b.0[k]))
            }
        }
    };
}
lanewise!(F8, Add, add, +);
lanewise!(F8, Sub, sub, -);
lanewise!(F8, Mul, mul, *);
lanewise!(F8, Div, div, /);
lanewise!(M8, BitAnd, bitand, &);
lanewise!(M8, BitOr, bitor, |);

impl Not for M8 {
    type Output = M8;
    #[inline(always)]
    fn not(self) -> M8 {
        M8(self.0.map(|x| !x))
    }
}

impl Mask for M8 {
    #[inline(always)]
    fn from_bits(bits: u32) -> Self {
        M8(std::array::from_fn(|k| if bits >> k & 1 != 0 { !0 } else { 0 }))
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        (0..8).fold(0, |m, k| m | (self.0[k] >> 31) << k)
    }
}

#[inline(always)]
fn mask(f: impl Fn(usize) -> bool) -> M8 {
    M8(std::array::from_fn(|k| if f(k) { !0 } else { 0 }))
}

impl Lanes<8> for F8 {
    type Mask = M8;
    const ZERO: Self = F8([0.0; 8]);
    const ONE: Self = F8([1.0; 8]);
    const INFINITY: Self = F8([f32::INFINITY; 8]);
    fn splat(x: f32) -> Self {
        F8([x; 8])
    }
    fn from_array(a: [f32; 8]) -> Self {
        F8(a)
    }
    fn to_array(self) -> [f32; 8] {
        self.0
    }
    fn select(m: M8, a: Self, b: Self) -> Self {
        F8(std::array::from_fn(|k| if m.0[k] != 0 { a.0[k] } else { b.0[k] }))
    }
    fn lt(self, b: Self) -> M8 {
        mask(|k| self.0[k] < b.0[k])
    }
    fn le(self, b: Self) -> M8 {
        mask(|k| self.0[k] <= b.0[k])
    }
    fn gt(self, b: Self) -> M8 {
        mask(|k| self.0[k] > b.0[k])
    }
    fn ge(self, b: Self) -> M8 {
        mask(|k| self.0[k] >= b.0[k])
    }
    fn ne(self, b: Self) -> M8 {
        mask(|k| self.0[k] != b.0[k])
    }
    fn is_nan(self) -> M8 {
        mask(|k| self.0[k].is_nan())
    }
    fn min(self, b: Self) -> Self {
        F8(std::array::from_fn(
            |k| if self.0[k] < b.0[k] { self.0[k] } else { b.0[k] },
        ))
    }
    fn max(self, b: Self) -> Self {
        F8(std::array::from_fn(
            |k| if self.0[k] > b.0[k] { self.0[k] } else { b.0[k] },
        ))
    }
    fn abs(self) -> Self {
        F8(self.0.map(f32::abs))
    }
    fn sqrt(self) -> Self {
        F8(self.0.map(f32::sqrt))
    }
    fn trunc_small(self) -> Self {
        F8(self.0.map(f32::trunc))
    }
}

impl F8 {
    pub(crate) fn store(self, out: &mut [f32; 8]) {
        *out = self.0;
    }
    pub(crate) fn load(a: &[f32; 8]) -> F8 {
        F8(*a)
    }
    pub(crate) fn to_bits(self) -> U8 {
        U8(self.0.map(f32::to_bits))
    }
    pub(crate) fn from_u8_bits(v: U8) -> F8 {
        F8(v.0.map(f32::from_bits))
    }
    pub(crate) fn sign_bits(self) -> u32 {
        (0..8).fold(0, |m, k| m | (self.0[k].to_bits() >> 31) << k)
    }
    pub(crate) fn permute(self, order: U8) -> F8 {
        F8(std::array::from_fn(|k| self.0[order.0[k] as usize & 7]))
    }
}

impl U8 {
    pub(crate) fn splat(x: u32) -> U8 {
        U8([x; 8])
    }
    pub(crate) fn from_array(a: [u32; 8]) -> U8 {
        U8(a)
    }
    pub(crate) fn load(a: &[u32; 8]) -> U8 {
        U8(*a)
    }
    pub(crate) fn to_array(self) -> [u32; 8] {
        self.0
    }
    pub(crate) fn store(self, out: &mut [u32; 8]) {
        *out = self.0;
    }
    fn zip(self, b: U8, f: impl Fn(u32, u32) -> u32) -> U8 {
        U8(std::array::from_fn(|k| f(self.0[k], b.0[k])))
    }
    pub(crate) fn and(self, b: U8) -> U8 {
        self.zip(b, |x, y| x & y)
    }
    pub(crate) fn or(self, b: U8) -> U8 {
        self.zip(b, |x, y| x | y)
    }
    pub(crate) fn wrapping_sub(self, b: U8) -> U8 {
        self.zip(b, u32::wrapping_sub)
    }
    pub(crate) fn max_i32(self, b: U8) -> U8 {
        self.zip(b, |x, y| (x as i32).max(y as i32) as u32)
    }
    pub(crate) fn min_u32(self, b: U8) -> U8 {
        self.zip(b, u32::min)
    }
    pub(crate) fn max_u32(self, b: U8) -> U8 {
        self.zip(b, u32::max)
    }
    pub(crate) fn select(m: M8, a: U8, b: U8) -> U8 {
        U8(std::array::from_fn(|k| if m.0[k] != 0 { a.0[k] } else { b.0[k] }))
    }
    pub(crate) fn blend<const MASK: i32>(a: U8, b: U8) -> U8 {
        U8(std::array::from_fn(
            |k| if MASK >> k & 1 != 0 { b.0[k] } else { a.0[k] },
        ))
    }
    pub(crate) fn swap1(self) -> U8 {
        U8(std::array::from_fn(|k| self.0[k ^ 1]))
    }
    pub(crate) fn swap2(self) -> U8 {
        U8(std::array::from_fn(|k| self.0[k ^ 2]))
    }
    pub(crate) fn swap4(self) -> U8 {
        U8(std::array::from_fn(|k| self.0[k ^ 4]))
    }
    pub(crate) fn permute(self, order: U8) -> U8 {
        U8(std::array::from_fn(|k| self.0[order.0[k] as usize & 7]))
    }
    /// Writes `a[0], b[0], ..., a[7], b[7]` at `out`.
    ///
    /// # Safety
    /// `out` must be valid for writing sixteen `u32`s (no alignment needed).
    pub(crate) unsafe fn store_pairs(a: U8, b: U8, out: *mut u32) {
        for k in 0..8 {
            // SAFETY: within the sixteen `u32`s (the contract).
            unsafe {
                out.add(2 * k).write_unaligned(a.0[k]);
                out.add(2 * k + 1).write_unaligned(b.0[k]);
            }
        }
    }
}
