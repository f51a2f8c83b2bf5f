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
