//! What this build of the library uses of the CPU it runs on, for `gridtrace --version` and for
//! bug reports.

/// The CPU features the library's fast paths pick at run time on this machine, in words.
///
/// The BVH's box tests and walks, the triangle tests and the packets run eight lanes wide where
/// `simd::has_wide()` says so: on x86-64 with AVX2 (checked at run time), on aarch64 always
/// (NEON is baseline there); elsewhere, or on an x86-64 CPU without AVX2, they take the scalar
/// paths (the answers are the same). The check is the one those paths make, once per call.
pub fn cpu_features() -> String {
    use crate::accel::simd::{WIDE_ISA, has_wide};
    let arch = std::env::consts::ARCH;
    if has_wide() {
        format!("{arch} with {WIDE_ISA} (the 8-wide BVH, triangle and packet paths)")
    } else if cfg!(target_arch = "x86_64") {
        format!("{arch} without AVX2 (the scalar paths)")
    } else {
        format!("{arch} (the scalar paths; the 8-wide paths are built for x86_64 with AVX2 and aarch64)")
    }
}

#[cfg(test)]
mod tests {
    /// The line names the instruction set the eight-lane paths take here, and the dispatch
    /// takes them where it should: on aarch64 always NEON (no run-time check), on x86-64 AVX2
    /// exactly where the CPU has it.
    #[test]
    fn cpu_features_names_the_arch_and_the_simd_path_taken() {
        let s = super::cpu_features();
        assert!(s.starts_with(std::env::consts::ARCH), "{s}");
        let wide = crate::accel::simd::has_wide();
        #[cfg(target_arch = "x86_64")]
        {
            let avx2 = std::arch::is_x86_feature_detected!("avx2");
            assert_eq!(wide, avx2, "the eight-lane paths run exactly where AVX2 is");
            assert_eq!(s.contains("with AVX2"), avx2, "{s}");
            assert_eq!(s.contains("without AVX2"), !avx2, "{s}");
        }
        #[cfg(target_arch = "aarch64")]
        {
            assert!(wide, "aarch64: the NEON paths are the ones taken");
            assert_eq!(crate::accel::simd::WIDE_ISA, "NEON");
            assert!(s.contains("with NEON"), "{s}");
        }
        #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
        assert!(!wide && s.contains("scalar"), "{s}");
    }
}
