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
