//! What the CPU walks share about the machine: whether AVX2 is there, the prefetch hint, and how
//! many rays a packet holds. Every structure takes these from here, none from another.

/// Whether this CPU runs the AVX2 build of the traversal (the BVH's `walk_avx2` and
/// `BoxRay::enter_avx2`, the irregular grid's eight-lane packets: the features those enable). The standard library caches the answer.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// Without x86-64 there is no AVX2 build to choose.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
pub(crate) fn has_avx2() -> bool {
    false
}

/// Asks for the cache line at `p` (a hint: any address will do).
#[inline(always)]
pub(crate) fn prefetch(p: *const i8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is only a hint; it never faults, whatever the address.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Rays in a packet: the lanes of an AVX register (the renderer's 4x2 blocks of pixels).
pub const PACKET: usize = 8;
