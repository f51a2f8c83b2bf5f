//! Bad input gets a clear error, never a panic or a hang: a corpus of malformed files, written to
//! a temp folder and loaded through `io::load_mesh` (or `scene::file::load_scene`) and
//! `Scene::prepare`. Each error names the file and, where the problem has one, its line or byte.

use gridtrace::Resolution;
use gridtrace::testing::bad_input_corpus;

#[test]
fn corpus_gives_located_errors() {
    let dir = std::env::temp_dir().join(format!("gridtrace-bad-input-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut failures = Vec::new();
    let corpus = bad_input_corpus();
    for f in &corpus {
        let path = dir.join(f.name);
        std::fs::write(&path, &f.bytes).unwrap();
        let result = std::panic::catch_unwind(|| {
            let scene = if f.name.ends_with(".toml") {
                gridtrace::scene::file::load_scene(&path)
            } else {
                gridtrace::io::load_mesh(&path).map(|m| gridtrace::scene::builtin::mesh_scene(m, false))
            }?;
            scene.prepare(Resolution::default()).map(|_| ())
        });
        match result {
            Err(_) => failures.push(format!("{}: panicked", f.name)),
            Ok(Ok(())) => failures.push(format!("{}: accepted", f.name)),
            Ok(Err(e)) => {
                let msg = e.to_string();
                if !msg.contains(f.name) || !msg.contains(f.location) {
                    failures.push(format!("{}: want the name and '{}', got: {msg}", f.name, f.location));
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        failures.is_empty(),
        "{} of {} files:\n{}",
        failures.len(),
        corpus.len(),
        failures.join("\n")
    );
}

/// A path whose format cannot be told from its name says what is wrong with it (a directory, no
/// extension, an unknown one), names it and lists the formats, instead of "unsupported mesh
/// format '.'".
#[test]
fn unusable_mesh_paths_say_why() {
    let dir = std::env::temp_dir().join(format!("gridtrace-bad-path-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let formats = "OBJ (.obj), PLY (.ply), glTF/GLB (.gltf, .glb), STL (.stl), OFF (.off)";
    let e = gridtrace::io::load_mesh(&dir).unwrap_err().to_string();
    assert!(
        e.contains(dir.to_str().unwrap()) && e.contains("is a directory") && e.contains(formats),
        "{e}"
    );
    let bare = dir.join("mesh");
    std::fs::write(&bare, "v 0 0 0\n").unwrap();
    let e = gridtrace::io::load_mesh(&bare).unwrap_err().to_string();
    assert!(e.contains("mesh: has no extension") && e.contains(formats), "{e}");
    // Missing and extensionless: missing is the problem to report.
    let e = gridtrace::io::load_mesh(&dir.join("nope")).unwrap_err();
    assert!(matches!(e, gridtrace::Error::Io { .. }), "{e}");
    let e = gridtrace::io::load_mesh(&dir.join("m.fbx")).unwrap_err().to_string();
    assert!(
        e.contains("m.fbx: unsupported mesh format '.fbx'") && e.contains(formats),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
