//! What the CPU walks share about the machine: the eight-lane vector types their hot paths are
//! written in once (`F8`, `M8`, `U8`), whether this CPU runs those paths, the prefetch hint, and
//! how many rays a packet holds. Every structure takes these from here, none from another.
//!
//! One backend is compiled per target: AVX2 on x86-64 (one 256-bit register a value, chosen at
//! run time: `has_wide`), NEON on aarch64 (two 128-bit registers a value; NEON is part of the
//! aarch64 baseline, so no check), and plain arrays elsewhere (where `has_wide` is false and
//! the callers take their scalar paths; the arrays keep the code compiling and testable).
//! Every backend gives the same bits: the operations are IEEE arithmetic lane by lane and the
//! comparisons, `min` and `max` follow SSE's rules (`lanes.rs`), which the NEON backend
//! builds from compares and selects where its own `fmin` would treat NaN differently.
//!
//! The code written over these types runs inside functions marked
//! `#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]` and entered only
//! after `has_wide()`: the types' operations are `#[inline(always)]` functions whose
//! intrinsics become single instructions only once inlined there. Helpers over them must be
//! `#[inline(always)]` functions too, never closures: a closure does not inherit the
//! enclosing function's `target_feature`, so its intrinsics would be calls.

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "aarch64")]
mod neon;
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
mod scalar;

#[cfg(target_arch = "x86_64")]
pub(crate) use avx2::{F8, M8, U8};
#[cfg(target_arch = "aarch64")]
pub(crate) use neon::{F8, M8, U8};
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
pub(crate) use scalar::{F8, M8, U8};

/// The instruction set the eight-lane paths are compiled for on this target, in words
/// (`build_info`): the paths run only where `has_wide()` says so.
pub(crate) const WIDE_ISA: &str = if cfg!(target_arch = "x86_64") {
    "AVX2"
} else if cfg!(target_arch = "aarch64") {
    "NEON"
} else {
    "none"
};

/// Whether this CPU runs the eight-lane build of the traversal (the BVH's walks, box tests and
/// packets, the irregular grid's and the winding tree's eight-lane packets). On x86-64 that is
/// whether it has AVX2 and FMA (every AVX2 CPU has both; the lanes' `mul_add` is one FMA
/// instruction, and a function that calls it enables `fma` beside `avx2`; the standard
/// library caches the answers); on aarch64 always (NEON is baseline there); elsewhere never.
#[inline(always)]
pub(crate) fn has_wide() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma");
    #[cfg(target_arch = "aarch64")]
    return true;
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    return false;
}

/// Asks for the cache line at `p` (a hint: any address will do).
#[inline(always)]
pub(crate) fn prefetch(p: *const i8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is only a hint; it never faults, whatever the address.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p)
    };
    #[cfg(target_arch = "aarch64")]
    // SAFETY: `prfm` is only a hint; it never faults, whatever the address, and touches no
    // register but its operand.
    unsafe {
        std::arch::asm!("prfm pldl1keep, [{0}]", in(reg) p, options(nostack, preserves_flags, readonly));
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let _ = p;
}

/// Rays in a packet: the eight lanes of `F8` (the renderer's 4x2 blocks of pixels).
pub const PACKET: usize = 8;

/// The mask of `U8::blend` for one layer of a bitonic sorting network on eight lanes (Batcher
/// 1968): lanes `i` and `i ^ j` compare, in blocks of `k` that sort up where `i & k` is 0 and
/// down elsewhere; bit `i` set where lane `i` keeps the larger value.
pub(crate) const fn bitonic_mask(k: usize, j: usize) -> i32 {
    let mut mask = 0;
    let mut i = 0;
    while i < 8 {
        if ((i & j) == 0) != ((i & k) == 0) {
            mask |= 1 << i;
        }
        i += 1;
    }
    mask
}

/// Sorts eight u32s, ascending, without a branch: the six layers of the bitonic network, each
/// a lane shuffle (partner `i ^ 1`, `i ^ 2` or `i ^ 4`), a min, a max and a blend.
#[inline(always)]
pub(crate) fn sort8(v: U8) -> U8 {
    macro_rules! layer {
        ($v:expr, $partner:ident, $k:literal, $j:literal) => {{
            let v = $v;
            let p = v.$partner();
            U8::blend::<{ bitonic_mask($k, $j) }>(v.min_u32(p), v.max_u32(p))
        }};
    }
    let v = layer!(v, swap1, 2, 1);
    let v = layer!(v, swap2, 4, 2);
    let v = layer!(v, swap1, 4, 1);
    let v = layer!(v, swap4, 8, 4);
    let v = layer!(v, swap2, 8, 2);
    layer!(v, swap1, 8, 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::lanes::{Lanes, Mask};

    /// The eight-lane integer operations, the sort, the permutes and the interleaved store
    /// against their scalar meaning, lane by lane, on whichever backend this target compiles
    /// (AVX2 only where the CPU has it).
    #[test]
    fn integer_lanes_sort_and_permute_as_scalar() {
        if !has_wide() {
            eprintln!("no eight-lane path on this CPU");
            return;
        }
        // SAFETY: `has_wide()` said the CPU runs the eight-lane build.
        unsafe { check_u8() };
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    unsafe fn check_u8() {
        let mut seed = 0x9E37_79B9u32;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed
        };
        for round in 0..500 {
            let a: [u32; 8] = std::array::from_fn(|_| next());
            let b: [u32; 8] = std::array::from_fn(|_| if round % 3 == 0 { next() & 15 } else { next() });
            let (x, y) = (U8::from_array(a), U8::from_array(b));
            let m = next() & 0xFF;
            let order: [u32; 8] = std::array::from_fn(|_| next() & 7);
            let ord = U8::from_array(order);
            let f: [f32; 8] = a.map(f32::from_bits);
            let mut sorted = a;
            sorted.sort_unstable();
            let mut pairs = [0u32; 16];
            // SAFETY: `pairs` holds sixteen u32s.
            unsafe { U8::store_pairs(x, y, pairs.as_mut_ptr()) };
            for k in 0..8 {
                assert_eq!(x.min_u32(y).to_array()[k], a[k].min(b[k]), "{round}: min_u32");
                assert_eq!(x.max_u32(y).to_array()[k], a[k].max(b[k]), "{round}: max_u32");
                assert_eq!(
                    x.max_i32(y).to_array()[k],
                    (a[k] as i32).max(b[k] as i32) as u32,
                    "max_i32"
                );
                assert_eq!(x.wrapping_sub(y).to_array()[k], a[k].wrapping_sub(b[k]), "sub");
                assert_eq!(x.and(y).to_array()[k], a[k] & b[k], "and");
                assert_eq!(x.or(y).to_array()[k], a[k] | b[k], "or");
                let pick = if m >> k & 1 != 0 { a[k] } else { b[k] };
                assert_eq!(U8::select(M8::from_bits(m), x, y).to_array()[k], pick, "select");
                assert_eq!(x.swap1().to_array()[k], a[k ^ 1], "swap1");
                assert_eq!(x.swap2().to_array()[k], a[k ^ 2], "swap2");
                assert_eq!(x.swap4().to_array()[k], a[k ^ 4], "swap4");
                assert_eq!(x.permute(ord).to_array()[k], a[order[k] as usize], "permute");
                let fp = F8::from_array(f).permute(ord).to_array()[k];
                assert_eq!(fp.to_bits(), a[order[k] as usize], "F8::permute");
                assert_eq!(F8::from_array(f).to_bits().to_array()[k], a[k], "to_bits");
                assert_eq!(F8::from_u8_bits(x).to_array()[k].to_bits(), a[k], "from_u8_bits");
                assert_eq!(pairs[2 * k..2 * k + 2], [a[k], b[k]], "store_pairs");
            }
            let signs = (0..8).fold(0, |s, k| s | (a[k] >> 31) << k);
            assert_eq!(F8::from_array(f).sign_bits(), signs, "sign_bits");
            assert_eq!(sort8(x).to_array(), sorted, "{round}: sort8");
            assert_eq!(
                U8::blend::<0b1010_0110>(x, y).to_array(),
                std::array::from_fn(|k| { if 0b1010_0110 >> k & 1 != 0 { b[k] } else { a[k] } })
            );
            assert_eq!(F8::load(&f).to_bits().to_array(), a, "F8::load");
            assert_eq!(U8::load(&a).to_array(), a, "U8::load");
            assert_eq!(U8::splat(a[0]).to_array(), [a[0]; 8], "splat");
        }
    }
}
