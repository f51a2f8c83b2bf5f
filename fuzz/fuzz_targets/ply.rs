//! PLY parser (ASCII and binary): a mesh that keeps the loader invariants, or an error.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = gridtrace::io::ply::parse(data, Path::new("fuzz.ply")) {
        let n = m.positions.len();
        assert!(!m.triangles.is_empty());
        assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < n));
        assert!(m.positions.iter().all(|p| p.is_finite()));
    }
});
