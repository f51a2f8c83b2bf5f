//! Scene files (TOML): a scene or a located error. A parsed scene is also prepared on a small
//! grid, since a scene file can describe geometry (huge subdivisions, NaN transforms) that only
//! preparation rejects.
#![no_main]
use gridtrace::Resolution;
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    // Mesh references resolve against a folder that does not exist: an error, never a read.
    if let Ok(scene) = gridtrace::scene::file::parse_scene(data, Path::new("/nonexistent-fuzz/s.toml")) {
        if scene.mesh.triangles.len() <= 200_000 {
            let _ = scene.prepare(Resolution::Fixed([4, 4, 4]));
        }
    }
});
