//! glTF / GLB from memory (`parse_slice`): a mesh that keeps the loader invariants, or an error.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = gridtrace::io::gltf::parse_slice(data, Path::new("fuzz.glb")) {
        let n = m.positions.len();
        assert!(!m.triangles.is_empty());
        assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < n));
        assert!(m.positions.iter().all(|p| p.is_finite()));
    }
});
