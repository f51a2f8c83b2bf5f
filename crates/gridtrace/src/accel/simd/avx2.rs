//! The eight-lane types in AVX2: one 256-bit register each.
//!
//! SAFETY (every `unsafe` block in this file): each is one AVX, AVX2 or FMA intrinsic on
//! values in registers (loads and stores go through arrays or pointers of the right size, as
//! each says). The types are used only inside functions compiled with `target_feature(enable
//! = "avx2")` (and `"avx2,fma"` where they call `mul_add`) and entered after `has_wide()` said
//! the CPU has both (`simd`), so the CPU has the instructions.

use std::arch::x86_64::*;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

use crate::accel::lanes::{Lanes, Mask};

/// Eight lanes of `f32`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct F8(__m256);

/// A mask of eight lanes: all bits set or clear per lane, so that `select` is a blend.
#[derive(Debug, Clone, Copy)]
pub(crate) struct M8(__m256);

/// Eight lanes of `u32` (the BVH's sort keys and child references).
#[derive(Debug, Clone, Copy)]
pub(crate) struct U8(__m256i);

macro_rules! lanewise {
    ($t:ident, $trait:ident, $f:ident, $intr:ident) => {
        impl $trait for $t {
            type Output = $t;
            #[inline(always)]
            fn $f(self, b: $t) -> $t {
                $t(unsafe { $intr(self.0, b.0) })
            }
        }
    };
}
lanewise!(F8, Add, add, _mm256_add_ps);
lanewise!(F8, Sub, sub, _mm256_sub_ps);
lanewise!(F8, Mul, mul, _mm256_mul_ps);
lanewise!(F8, Div, div, _mm256_div_ps);
lanewise!(M8, BitAnd, bitand, _mm256_and_ps);
lanewise!(M8, BitOr, bitor, _mm256_or_ps);

#[inline(always)]
fn all_ones() -> __m256 {
    unsafe { _mm256_castsi256_ps(_mm256_set1_epi32(-1)) }
}

impl Not for M8 {
    type Output = M8;
    #[inline(always)]
    fn not(self) -> M8 {
        M8(unsafe { _mm256_xor_ps(self.0, all_ones()) })
    }
}

impl Mask for M8 {
    #[inline(always)]
    fn from_bits(bits: u32) -> Self {
        unsafe {
            let lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane_bit);
            M8(_mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lane_bit)))
        }
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        unsafe { _mm256_movemask_ps(self.0) as u32 }
    }
}

macro_rules! cmp {
    ($f:ident, $pred:ident) => {
        #[inline(always)]
        fn $f(self, b: Self) -> M8 {
            M8(unsafe { _mm256_cmp_ps::<$pred>(self.0, b.0) })
        }
    };
}

/// Lanes from an array: a const-friendly transmute (same size, any bits are valid).
const fn from_f32s(a: [f32; 8]) -> F8 {
    // SAFETY: `[f32; 8]` and `__m256` are both 32 bytes of plain floats.
    F8(unsafe { std::mem::transmute::<[f32; 8], __m256>(a) })
}

impl Lanes<8> for F8 {
    type Mask = M8;
    const ZERO: Self = from_f32s([0.0; 8]);
    const ONE: Self = from_f32s([1.0; 8]);
    const INFINITY: Self = from_f32s([f32::INFINITY; 8]);
    #[inline(always)]
    fn splat(x: f32) -> Self {
        F8(unsafe { _mm256_set1_ps(x) })
    }
    #[inline(always)]
    fn from_array(a: [f32; 8]) -> Self {
        F8(unsafe { _mm256_loadu_ps(a.as_ptr()) })
    }
    #[inline(always)]
    fn to_array(self) -> [f32; 8] {
        let mut a = [0.0; 8];
        unsafe { _mm256_storeu_ps(a.as_mut_ptr(), self.0) };
        a
    }
    #[inline(always)]
    fn select(mask: M8, a: Self, b: Self) -> Self {
        // `blendv` takes the second operand where the mask's sign bit is set.
        F8(unsafe { _mm256_blendv_ps(b.0, a.0, mask.0) })
    }
    // Ordered comparisons (false with a NaN) as SSE's `cmplt` & co.; `ne` unordered, as
    // SSE's `cmpneq` and Rust's `!=`.
    cmp!(lt, _CMP_LT_OQ);
    cmp!(le, _CMP_LE_OQ);
    cmp!(gt, _CMP_GT_OQ);
    cmp!(ge, _CMP_GE_OQ);
    cmp!(ne, _CMP_NEQ_UQ);
    #[inline(always)]
    fn is_nan(self) -> M8 {
        M8(unsafe { _mm256_cmp_ps::<_CMP_UNORD_Q>(self.0, self.0) })
    }
    #[inline(always)]
    fn min(self, b: Self) -> Self {
        F8(unsafe { _mm256_min_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        F8(unsafe { _mm256_max_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn abs(self) -> Self {
        F8(unsafe { _mm256_and_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX))) })
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        F8(unsafe { _mm256_sqrt_ps(self.0) })
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        F8(unsafe { _mm256_fmadd_ps(self.0, b.0, c.0) })
    }
    #[inline(always)]
    fn rsqrt(self) -> Self {
        // `y (1.5 - 0.5 x y^2)`: Newton's step for `1 / y^2 = x` from the estimate.
        let y = F8(unsafe { _mm256_rsqrt_ps(self.0) });
        let half_x = self * F8::splat(0.5);
        y * (half_x * y).mul_add(F8::splat(0.0) - y, F8::splat(1.5))
    }
    #[inline(always)]
    fn trunc_small(self) -> Self {
        F8(unsafe { _mm256_round_ps::<{ _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC }>(self.0) })
    }
}

impl F8 {
    /// The lanes into `out` (in place: an array returned by value was copied once more).
    #[inline(always)]
    pub(crate) fn store(self, out: &mut [f32; 8]) {
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) };
    }
    /// Eight floats from memory (a load the arithmetic can take as its operand).
    #[inline(always)]
    pub(crate) fn load(a: &[f32; 8]) -> F8 {
        F8(unsafe { _mm256_loadu_ps(a.as_ptr()) })
    }
    /// The lanes' bits as integers.
    #[inline(always)]
    pub(crate) fn to_bits(self) -> U8 {
        U8(unsafe { _mm256_castps_si256(self.0) })
    }
    /// Integers' bits as floats.
    #[inline(always)]
    pub(crate) fn from_u8_bits(v: U8) -> F8 {
        F8(unsafe { _mm256_castsi256_ps(v.0) })
    }
    /// Bit `i` set where lane `i`'s sign bit is (NaN and -0.0 included).
    #[inline(always)]
    pub(crate) fn sign_bits(self) -> u32 {
        unsafe { _mm256_movemask_ps(self.0) as u32 }
    }
    /// Lane `i` is lane `order[i]` of `self` (`order`'s lanes in `0..8`).
    #[inline(always)]
    pub(crate) fn permute(self, order: U8) -> F8 {
        F8(unsafe { _mm256_permutevar8x32_ps(self.0, order.0) })
    }
}

impl U8 {
    #[inline(always)]
    pub(crate) fn splat(x: u32) -> U8 {
        U8(unsafe { _mm256_set1_epi32(x as i32) })
    }
    #[inline(always)]
    pub(crate) fn from_array(a: [u32; 8]) -> U8 {
        U8(unsafe { _mm256_loadu_si256(a.as_ptr() as *const __m256i) })
    }
    #[inline(always)]
    pub(crate) fn load(a: &[u32; 8]) -> U8 {
        U8(unsafe { _mm256_loadu_si256(a.as_ptr() as *const __m256i) })
    }
    #[inline(always)]
    pub(crate) fn to_array(self) -> [u32; 8] {
        let mut a = [0; 8];
        self.store(&mut a);
        a
    }
    /// The lanes into `out` (in place: an array returned by value was copied once more).
    #[inline(always)]
    pub(crate) fn store(self, out: &mut [u32; 8]) {
        unsafe { _mm256_storeu_si256(out.as_mut_ptr() as *mut __m256i, self.0) };
    }
    #[inline(always)]
    pub(crate) fn and(self, b: U8) -> U8 {
        U8(unsafe { _mm256_and_si256(self.0, b.0) })
    }
    #[inline(always)]
    pub(crate) fn or(self, b: U8) -> U8 {
        U8(unsafe { _mm256_or_si256(self.0, b.0) })
    }
    #[inline(always)]
    pub(crate) fn wrapping_sub(self, b: U8) -> U8 {
        U8(unsafe { _mm256_sub_epi32(self.0, b.0) })
    }
    /// The larger as signed integers.
    #[inline(always)]
    pub(crate) fn max_i32(self, b: U8) -> U8 {
        U8(unsafe { _mm256_max_epi32(self.0, b.0) })
    }
    #[inline(always)]
    pub(crate) fn min_u32(self, b: U8) -> U8 {
        U8(unsafe { _mm256_min_epu32(self.0, b.0) })
    }
    #[inline(always)]
    pub(crate) fn max_u32(self, b: U8) -> U8 {
        U8(unsafe { _mm256_max_epu32(self.0, b.0) })
    }
    /// Lane by lane `mask ? a : b`.
    #[inline(always)]
    pub(crate) fn select(mask: M8, a: U8, b: U8) -> U8 {
        U8(unsafe { _mm256_blendv_epi8(b.0, a.0, _mm256_castps_si256(mask.0)) })
    }
    /// Lane `i` from `b` where bit `i` of `MASK` is set, else from `a`.
    #[inline(always)]
    pub(crate) fn blend<const MASK: i32>(a: U8, b: U8) -> U8 {
        U8(unsafe { _mm256_blend_epi32::<MASK>(a.0, b.0) })
    }
    /// Lane `i` is lane `i ^ 1`.
    #[inline(always)]
    pub(crate) fn swap1(self) -> U8 {
        U8(unsafe { _mm256_shuffle_epi32::<0b10_11_00_01>(self.0) })
    }
    /// Lane `i` is lane `i ^ 2`.
    #[inline(always)]
    pub(crate) fn swap2(self) -> U8 {
        U8(unsafe { _mm256_shuffle_epi32::<0b01_00_11_10>(self.0) })
    }
    /// Lane `i` is lane `i ^ 4` (the halves swapped).
    #[inline(always)]
    pub(crate) fn swap4(self) -> U8 {
        U8(unsafe { _mm256_permute4x64_epi64::<0b01_00_11_10>(self.0) })
    }
    /// Lane `i` is lane `order[i]` of `self` (`order`'s lanes in `0..8`).
    #[inline(always)]
    pub(crate) fn permute(self, order: U8) -> U8 {
        U8(unsafe { _mm256_permutevar8x32_epi32(self.0, order.0) })
    }
    /// Writes `a[0], b[0], a[1], b[1], ..., a[7], b[7]` at `out` (pairs of a `u32` and its
    /// partner: the layout of a stack entry).
    ///
    /// # Safety
    /// `out` must be valid for writing sixteen `u32`s (no alignment needed).
    #[inline(always)]
    pub(crate) unsafe fn store_pairs(a: U8, b: U8, out: *mut u32) {
        // `lo` holds pairs 0, 1 | 4, 5 and `hi` 2, 3 | 6, 7: stored a 16-byte quarter at a
        // time, not regrouped by `vperm2i128` first (a single instruction on Intel, eight
        // micro-ops on AMD's Zen 1, where 256-bit shuffles across the halves are split in two
        // and recombined).
        unsafe {
            let lo = _mm256_unpacklo_epi32(a.0, b.0);
            let hi = _mm256_unpackhi_epi32(a.0, b.0);
            let at = out as *mut __m128i;
            _mm256_storeu2_m128i(at.add(2), at, lo);
            _mm256_storeu2_m128i(at.add(3), at.add(1), hi);
        }
    }
}
