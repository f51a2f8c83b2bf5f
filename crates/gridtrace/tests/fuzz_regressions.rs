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
