//! Inputs that fuzzing found to panic: each must now give an error naming the file.

use std::path::Path;

#[test]
fn ply_face_list_index_on_other_element() {
    let data = include_bytes!("fuzz/ply-face-list-index.ply");
    let e = gridtrace::io::ply::parse(data, Path::new("f.ply"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("f.ply"), "{e}");
}

#[test]
fn gltf_accessor_index_out_of_range() {
    let data = include_bytes!("fuzz/gltf-accessor-index.gltf");
    let e = gridtrace::io::gltf::parse_slice(data, Path::new("f.gltf"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("f.gltf"), "{e}");
}

/// A relative buffer URI whose `%AA` escape decodes to invalid UTF-8: gltf 1.4.1 unwrapped the
/// decoding and panicked (found by the gltf fuzz target, session 2).
#[test]
fn gltf_buffer_uri_invalid_utf8() {
    let data = include_bytes!("fuzz/gltf-uri-invalid-utf8.gltf");
    let e = gridtrace::io::gltf::parse_slice(data, Path::new("f.gltf"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("f.gltf") && e.contains("percent-encoded"), "{e}");
}

/// Every input of the committed fuzz corpora (`fuzz/corpus/`, reduced by coverage) replayed
/// through the loaders: a mesh that keeps the loader invariants or an error naming the file,
/// never a panic. Cheap insurance that a change to a parser does not reopen what fuzzing closed,
/// without a nightly toolchain.
#[test]
fn fuzz_corpora_replay() {
    use gridtrace::Mesh;
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fuzz/corpus"));
    let check = |m: &Mesh| {
        let n = m.positions.len();
        assert!(!m.triangles.is_empty());
        assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < n));
        assert!(m.positions.iter().all(|p| p.is_finite()));
    };
    let mut replayed = 0;
    for target in ["obj", "ply", "gltf", "scene_file"] {
        let mut files: Vec<_> = std::fs::read_dir(root.join(target))
            .unwrap_or_else(|e| panic!("fuzz/corpus/{target}: {e}"))
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        for f in &files {
            let data = std::fs::read(f).unwrap();
            let name = Path::new("corpus.input");
            let result = std::panic::catch_unwind(|| match target {
                "obj" => {
                    // As the fuzz target: the input doubles as the MTL text after a NUL.
                    let (obj, mtl) = match data.iter().position(|&b| b == 0) {
                        Some(i) => (&data[..i], data[i + 1..].to_vec()),
                        None => (&data[..], b"newmtl m\nKd 1 0 0\n".to_vec()),
                    };
                    let resolve = move |_: &str| Some(mtl.clone());
                    gridtrace::io::obj::parse(obj, name, &resolve).map(|m| check(&m))
                }
                "ply" => gridtrace::io::ply::parse(&data, name).map(|m| check(&m)),
                "gltf" => gridtrace::io::gltf::parse_slice(&data, name).map(|m| check(&m)),
                _ => gridtrace::scene::file::parse_scene(&data, Path::new("/nonexistent-fuzz/s.toml")).map(|_| ()),
            });
            match result {
                Ok(Ok(())) => {}
                Ok(Err(e)) => {
                    let e = e.to_string();
                    assert!(
                        e.contains("corpus.input") || e.contains("s.toml"),
                        "{}: error without the file: {e}",
                        f.display()
                    );
                }
                Err(_) => panic!("{} panicked", f.display()),
            }
            replayed += 1;
        }
    }
    assert!(replayed > 1000, "only {replayed} corpus inputs found");
}
