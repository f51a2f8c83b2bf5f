//! What this build of the library uses of the CPU it runs on, for `gridtrace --version` and for
//! bug reports.

/// The CPU features the library's fast paths pick at run time on this machine, in words.
///
/// On x86-64 that is AVX2: with it the BVH's box tests and walks, the triangle tests and the
/// irregular grid's packets run eight lanes wide; without it they take the scalar paths (the
/// answers are the same). The check is the one those paths make, once per call.
///
/// On aarch64 NEON is part of the architecture: the four-lane code (the triangle tests, four
/// triangles at a time, and the irregular grid's packets, run as two packets of four) is
/// written over glam's `Vec4`, which is a NEON register there. The BVH's 8-wide box test takes
/// its portable form (plain arrays, vectorised as far as the compiler manages) and the
/// coherent-packet walk is AVX2 only. Other architectures take the scalar paths.
pub fn cpu_features() -> String {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            "x86_64 with AVX2 (the 8-wide BVH, triangle and packet paths)".to_string()
        } else {
            "x86_64 without AVX2 (the scalar paths)".to_string()
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    {
        "aarch64 with NEON (the 4-wide triangle and packet paths; the 8-wide BVH box test in \
         portable code; the AVX2 paths are x86_64 only)"
            .to_string()
    }
    #[cfg(not(any(target_arch = "x86_64", all(target_arch = "aarch64", target_feature = "neon"))))]
    {
        format!(
            "{} (the scalar paths; the AVX2 paths are x86_64 only)",
            std::env::consts::ARCH
        )
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn cpu_features_names_the_arch_and_the_simd_path() {
        let s = super::cpu_features();
        assert!(s.starts_with(std::env::consts::ARCH), "{s}");
        #[cfg(target_arch = "aarch64")]
        assert!(s.contains("with NEON"), "{s}");
        #[cfg(target_arch = "x86_64")]
        {
            let avx2 = std::arch::is_x86_feature_detected!("avx2");
            assert_eq!(s.contains("with AVX2"), avx2, "{s}");
            assert_eq!(s.contains("without AVX2"), !avx2, "{s}");
        }
    }
}
