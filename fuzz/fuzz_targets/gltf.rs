//! glTF / GLB from memory (`parse_slice`): a mesh that keeps the loader invariants, or an error.
//!
//! gltf-json 1.4.1 panics while validating some malformed files (an accessor index out of range);
//! `io::gltf` contains that with `catch_unwind` and returns an error. libfuzzer-sys installs a
//! panic hook that aborts on *every* panic, caught or not, which would stop the run at the first
//! such file (it did, after 3 seconds). So the hook is silenced while the loader runs: a panic
//! that escapes the loader still unwinds into libfuzzer-sys's own `catch_unwind` and aborts the
//! run as a crash; a contained one is what it is, an error.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let fuzzer_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let loaded = std::panic::catch_unwind(|| gridtrace::io::gltf::parse_slice(data, Path::new("fuzz.glb")));
    std::panic::set_hook(fuzzer_hook);
    let Ok(result) = loaded else {
        panic!("a panic escaped the glTF loader");
    };
    if let Ok(m) = result {
        let n = m.positions.len();
        assert!(!m.triangles.is_empty());
        assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < n));
        assert!(m.positions.iter().all(|p| p.is_finite()));
    }
});
