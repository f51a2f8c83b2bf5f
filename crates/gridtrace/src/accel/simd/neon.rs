//! The eight-lane types in NEON: two 128-bit registers each (`lo` lanes 0-3, `hi` 4-7).
//!
//! NEON's own `fmin`/`fmax` return NaN when either operand is NaN, where the callers rely on
//! SSE's `a < b ? a : b` (NaN in either: `b`): `min` and `max` are a compare and a select here
//! (two instructions a half), the same bits as the AVX2 backend. Comparisons are ordered
//! (false with a NaN) as SSE's; `ne` is the complement of `==` (true with a NaN). Subnormals
//! are kept (Linux runs aarch64 user code with FPCR.FZ clear), as on x86-64.
//!
//! SAFETY (every `unsafe` block in this file): each is one NEON intrinsic on values in
//! registers, or a load or store through an array or pointer of the right size, as each says.
//! NEON is part of the aarch64 baseline: every aarch64 CPU has the instructions.

use std::arch::aarch64::*;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

use crate::accel::lanes::{Lanes, Mask};

/// Eight lanes of `f32`.
#[derive(Debug, Clone, Copy)]
#[repr(C)]
pub(crate) struct F8 {
    lo: float32x4_t,
    hi: float32x4_t,
}

/// A mask of eight lanes: all bits set or clear per lane, so that `select` is a bit select.
#[derive(Debug, Clone, Copy)]
pub(crate) struct M8 {
    lo: uint32x4_t,
    hi: uint32x4_t,
}

/// Eight lanes of `u32` (the BVH's sort keys and child references).
#[derive(Debug, Clone, Copy)]
pub(crate) struct U8 {
    lo: uint32x4_t,
    hi: uint32x4_t,
}

macro_rules! halves {
    ($t:ident, $trait:ident, $f:ident, $intr:ident) => {
        impl $trait for $t {
            type Output = $t;
            #[inline(always)]
            fn $f(self, b: $t) -> $t {
                unsafe {
                    $t {
                        lo: $intr(self.lo, b.lo),
                        hi: $intr(self.hi, b.hi),
                    }
                }
            }
        }
    };
}
halves!(F8, Add, add, vaddq_f32);
halves!(F8, Sub, sub, vsubq_f32);
halves!(F8, Mul, mul, vmulq_f32);
halves!(F8, Div, div, vdivq_f32);
halves!(M8, BitAnd, bitand, vandq_u32);
halves!(M8, BitOr, bitor, vorrq_u32);

impl Not for M8 {
    type Output = M8;
    #[inline(always)]
    fn not(self) -> M8 {
        unsafe {
            M8 {
                lo: vmvnq_u32(self.lo),
                hi: vmvnq_u32(self.hi),
            }
        }
    }
}

/// Bit `i` set where lane `i`'s top bit is set (SSE's `movemask`).
#[inline(always)]
fn top_bits(lo: uint32x4_t, hi: uint32x4_t) -> u32 {
    unsafe {
        let weight = vld1q_u32([1u32, 2, 4, 8].as_ptr());
        let lo = vaddvq_u32(vmulq_u32(vshrq_n_u32::<31>(lo), weight));
        let hi = vaddvq_u32(vmulq_u32(vshrq_n_u32::<31>(hi), weight));
        lo | hi << 4
    }
}

impl Mask for M8 {
    #[inline(always)]
    fn from_bits(bits: u32) -> Self {
        unsafe {
            let b = vdupq_n_u32(bits);
            M8 {
                lo: vtstq_u32(b, vld1q_u32([1u32, 2, 4, 8].as_ptr())),
                hi: vtstq_u32(b, vld1q_u32([16u32, 32, 64, 128].as_ptr())),
            }
        }
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        top_bits(self.lo, self.hi)
    }
}

macro_rules! cmp {
    ($f:ident, $intr:ident) => {
        #[inline(always)]
        fn $f(self, b: Self) -> M8 {
            unsafe {
                M8 {
                    lo: $intr(self.lo, b.lo),
                    hi: $intr(self.hi, b.hi),
                }
            }
        }
    };
}

/// Lanes from an array: a const-friendly transmute (same size, any bits are valid).
const fn from_f32s(a: [f32; 8]) -> F8 {
    // SAFETY: `[f32; 8]` and `F8` (two `float32x4_t`, `repr(C)`) are both 32 bytes of plain
    // floats, lane 0 first.
    unsafe { std::mem::transmute::<[f32; 8], F8>(a) }
}

impl Lanes<8> for F8 {
    type Mask = M8;
    const ZERO: Self = from_f32s([0.0; 8]);
    const ONE: Self = from_f32s([1.0; 8]);
    const INFINITY: Self = from_f32s([f32::INFINITY; 8]);
    #[inline(always)]
    fn splat(x: f32) -> Self {
        unsafe {
            let v = vdupq_n_f32(x);
            F8 { lo: v, hi: v }
        }
    }
    #[inline(always)]
    fn from_array(a: [f32; 8]) -> Self {
        F8::load(&a)
    }
    #[inline(always)]
    fn to_array(self) -> [f32; 8] {
        let mut a = [0.0; 8];
        unsafe {
            vst1q_f32(a.as_mut_ptr(), self.lo);
            vst1q_f32(a.as_mut_ptr().add(4), self.hi);
        }
        a
    }
    #[inline(always)]
    fn select(mask: M8, a: Self, b: Self) -> Self {
        unsafe {
            F8 {
                lo: vbslq_f32(mask.lo, a.lo, b.lo),
                hi: vbslq_f32(mask.hi, a.hi, b.hi),
            }
        }
    }
    cmp!(lt, vcltq_f32);
    cmp!(le, vcleq_f32);
    cmp!(gt, vcgtq_f32);
    cmp!(ge, vcgeq_f32);
    #[inline(always)]
    fn ne(self, b: Self) -> M8 {
        !cmp_eq(self, b)
    }
    #[inline(always)]
    fn is_nan(self) -> M8 {
        !cmp_eq(self, self)
    }
    #[inline(always)]
    fn min(self, b: Self) -> Self {
        F8::select(self.lt(b), self, b)
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        F8::select(self.gt(b), self, b)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        unsafe {
            F8 {
                lo: vabsq_f32(self.lo),
                hi: vabsq_f32(self.hi),
            }
        }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        unsafe {
            F8 {
                lo: vsqrtq_f32(self.lo),
                hi: vsqrtq_f32(self.hi),
            }
        }
    }
    #[inline(always)]
    fn trunc_small(self) -> Self {
        unsafe {
            F8 {
                lo: vrndq_f32(self.lo),
                hi: vrndq_f32(self.hi),
            }
        }
    }
}

#[inline(always)]
fn cmp_eq(a: F8, b: F8) -> M8 {
    unsafe {
        M8 {
            lo: vceqq_f32(a.lo, b.lo),
            hi: vceqq_f32(a.hi, b.hi),
        }
    }
}

impl F8 {
    /// The lanes into `out`.
    #[inline(always)]
    pub(crate) fn store(self, out: &mut [f32; 8]) {
        unsafe {
            vst1q_f32(out.as_mut_ptr(), self.lo);
            vst1q_f32(out.as_mut_ptr().add(4), self.hi);
        }
    }
    /// Eight floats from memory.
    #[inline(always)]
    pub(crate) fn load(a: &[f32; 8]) -> F8 {
        unsafe {
            F8 {
                lo: vld1q_f32(a.as_ptr()),
                hi: vld1q_f32(a.as_ptr().add(4)),
            }
        }
    }
    /// The lanes' bits as integers.
    #[inline(always)]
    pub(crate) fn to_bits(self) -> U8 {
        unsafe {
            U8 {
                lo: vreinterpretq_u32_f32(self.lo),
                hi: vreinterpretq_u32_f32(self.hi),
            }
        }
    }
    /// Integers' bits as floats.
    #[inline(always)]
    pub(crate) fn from_u8_bits(v: U8) -> F8 {
        unsafe {
            F8 {
                lo: vreinterpretq_f32_u32(v.lo),
                hi: vreinterpretq_f32_u32(v.hi),
            }
        }
    }
    /// Bit `i` set where lane `i`'s sign bit is (NaN and -0.0 included).
    #[inline(always)]
    pub(crate) fn sign_bits(self) -> u32 {
        let b = self.to_bits();
        top_bits(b.lo, b.hi)
    }
    /// Lane `i` is lane `order[i]` of `self` (`order`'s lanes in `0..8`).
    #[inline(always)]
    pub(crate) fn permute(self, order: U8) -> F8 {
        F8::from_u8_bits(self.to_bits().permute(order))
    }
}

macro_rules! u8_halves {
    ($f:ident, $intr:ident) => {
        #[inline(always)]
        pub(crate) fn $f(self, b: U8) -> U8 {
            unsafe {
                U8 {
                    lo: $intr(self.lo, b.lo),
                    hi: $intr(self.hi, b.hi),
                }
            }
        }
    };
}

impl U8 {
    #[inline(always)]
    pub(crate) fn splat(x: u32) -> U8 {
        unsafe {
            let v = vdupq_n_u32(x);
            U8 { lo: v, hi: v }
        }
    }
    #[inline(always)]
    pub(crate) fn from_array(a: [u32; 8]) -> U8 {
        U8::load(&a)
    }
    #[inline(always)]
    pub(crate) fn load(a: &[u32; 8]) -> U8 {
        unsafe {
            U8 {
                lo: vld1q_u32(a.as_ptr()),
                hi: vld1q_u32(a.as_ptr().add(4)),
            }
        }
    }
    #[inline(always)]
    pub(crate) fn to_array(self) -> [u32; 8] {
        let mut a = [0; 8];
        self.store(&mut a);
        a
    }
    /// The lanes into `out`.
    #[inline(always)]
    pub(crate) fn store(self, out: &mut [u32; 8]) {
        unsafe {
            vst1q_u32(out.as_mut_ptr(), self.lo);
            vst1q_u32(out.as_mut_ptr().add(4), self.hi);
        }
    }
    u8_halves!(and, vandq_u32);
    u8_halves!(or, vorrq_u32);
    u8_halves!(wrapping_sub, vsubq_u32);
    /// The larger as signed integers.
    #[inline(always)]
    pub(crate) fn max_i32(self, b: U8) -> U8 {
        unsafe {
            let m = |x: uint32x4_t, y: uint32x4_t| {
                vreinterpretq_u32_s32(vmaxq_s32(vreinterpretq_s32_u32(x), vreinterpretq_s32_u32(y)))
            };
            U8 {
                lo: m(self.lo, b.lo),
                hi: m(self.hi, b.hi),
            }
        }
    }
    u8_halves!(min_u32, vminq_u32);
    u8_halves!(max_u32, vmaxq_u32);
    /// Lane by lane `mask ? a : b`.
    #[inline(always)]
    pub(crate) fn select(mask: M8, a: U8, b: U8) -> U8 {
        unsafe {
            U8 {
                lo: vbslq_u32(mask.lo, a.lo, b.lo),
                hi: vbslq_u32(mask.hi, a.hi, b.hi),
            }
        }
    }
    /// Lane `i` from `b` where bit `i` of `MASK` is set, else from `a`.
    #[inline(always)]
    pub(crate) fn blend<const MASK: i32>(a: U8, b: U8) -> U8 {
        U8::select(M8::from_bits(MASK as u32), b, a)
    }
    /// Lane `i` is lane `i ^ 1`.
    #[inline(always)]
    pub(crate) fn swap1(self) -> U8 {
        unsafe {
            U8 {
                lo: vrev64q_u32(self.lo),
                hi: vrev64q_u32(self.hi),
            }
        }
    }
    /// Lane `i` is lane `i ^ 2`.
    #[inline(always)]
    pub(crate) fn swap2(self) -> U8 {
        unsafe {
            U8 {
                lo: vextq_u32::<2>(self.lo, self.lo),
                hi: vextq_u32::<2>(self.hi, self.hi),
            }
        }
    }
    /// Lane `i` is lane `i ^ 4` (the halves swapped: no instruction).
    #[inline(always)]
    pub(crate) fn swap4(self) -> U8 {
        U8 {
            lo: self.hi,
            hi: self.lo,
        }
    }
    /// Lane `i` is lane `order[i]` of `self` (`order`'s lanes in `0..8`): a table lookup over
    /// the 32 bytes, the byte indices `4 * order + (0, 1, 2, 3)` of each lane.
    #[inline(always)]
    pub(crate) fn permute(self, order: U8) -> U8 {
        unsafe {
            let table = uint8x16x2_t(vreinterpretq_u8_u32(self.lo), vreinterpretq_u8_u32(self.hi));
            let (base, scale) = (vdupq_n_u32(0x0302_0100), vdupq_n_u32(0x0404_0404));
            let pick = |o: uint32x4_t| {
                vreinterpretq_u32_u8(vqtbl2q_u8(table, vreinterpretq_u8_u32(vmlaq_u32(base, o, scale))))
            };
            U8 {
                lo: pick(order.lo),
                hi: pick(order.hi),
            }
        }
    }
    /// Writes `a[0], b[0], a[1], b[1], ..., a[7], b[7]` at `out` (pairs of a `u32` and its
    /// partner: the layout of a stack entry).
    ///
    /// # Safety
    /// `out` must be valid for writing sixteen `u32`s (no alignment needed).
    #[inline(always)]
    pub(crate) unsafe fn store_pairs(a: U8, b: U8, out: *mut u32) {
        unsafe {
            vst2q_u32(out, uint32x4x2_t(a.lo, b.lo));
            vst2q_u32(out.add(8), uint32x4x2_t(a.hi, b.hi));
        }
    }
}
