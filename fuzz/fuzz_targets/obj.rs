//! OBJ parser: any bytes give a mesh or a located error, never a panic or a hang. Material
//! libraries resolve to a fixed MTL body so the MTL parser is exercised too.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    // The input doubles as the MTL text: split at the first NUL if any.
    let (obj, mtl) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], data[i + 1..].to_vec()),
        None => (data, b"newmtl m\nKd 1 0 0\n".to_vec()),
    };
    let resolve = move |_: &str| Some(mtl.clone());
    if let Ok(m) = gridtrace::io::obj::parse(obj, Path::new("fuzz.obj"), &resolve) {
        gridtrace_fuzz_check(&m);
    }
});

fn gridtrace_fuzz_check(m: &gridtrace::Mesh) {
    let n = m.positions.len();
    assert!(!m.triangles.is_empty());
    assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < n));
    assert!(m.positions.iter().all(|p| p.is_finite()));
}
