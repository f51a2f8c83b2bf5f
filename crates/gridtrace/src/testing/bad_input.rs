//! The bad-input corpus: malformed mesh and scene files, a function per format, each with the
//! location its error must name (tests/bad_input.rs, the CLI's and Python's bad-input tests).

/// One malformed input file for the bad-input tests: its file name (the extension picks the
/// loader), its bytes, and what the error must say besides the file name: a location such as
/// `"line 3"` or `"byte "`, or `""` for whole-file errors (empty file, nothing to trace).
#[derive(Debug, Clone)]
pub struct BadFile {
    pub name: &'static str,
    pub bytes: Vec<u8>,
    pub location: &'static str,
}

/// A corpus of malformed mesh and scene files: truncated files, header counts that lie, indices
/// out of range, NaN/Inf coordinates, faces with fewer than 3 vertices, wrong types, non-UTF-8
/// bytes, empty files, meshes with only degenerate triangles, absurd header sizes.
pub fn bad_input_corpus() -> Vec<BadFile> {
    [
        obj_cases(),
        ply_cases(),
        off_cases(),
        stl_cases(),
        gltf_cases(),
        scene_cases(),
    ]
    .concat()
}

/// A corpus entry.
fn bad(name: &'static str, bytes: &[u8], location: &'static str) -> BadFile {
    BadFile {
        name,
        bytes: bytes.to_vec(),
        location,
    }
}

/// One triangle's vertices as little-endian float32 (x y z, three times).
fn tri_f32() -> Vec<u8> {
    [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .collect()
}

fn obj_cases() -> Vec<BadFile> {
    vec![
        bad("empty.obj", b"", ""),
        // A PNG renamed .obj: binary from its first line.
        bad("image.obj", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR", "line 1"),
        bad("truncated.obj", b"v 0 0 0\nv 1 0 0\nv 0 1", "line 3"),
        bad("index-range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "line 4"),
        bad("index-zero.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "line 4"),
        bad(
            "index-negative.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -7\n",
            "line 4",
        ),
        bad("nan.obj", b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "line 2"),
        bad("inf.obj", b"v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n", "line 2"),
        bad("two-vertex-face.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "line 4"),
        bad("wrong-type.obj", b"v 0 0 0\nv one 0 0\nv 0 1 0\nf 1 2 3\n", "line 2"),
        bad("non-utf8.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 \xff\xfe\n", "line 4"),
        bad("degenerate.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n", ""),
        bad(
            "huge-index.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n",
            "line 4",
        ),
    ]
}

fn ply_cases() -> Vec<BadFile> {
    let ply_head = |format: &str, nv: &str, nf: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n\
             element face {nf}\nproperty list uchar int vertex_indices\nend_header\n"
        )
        .into_bytes()
    };
    let cat = |a: Vec<u8>, b: &[u8]| [a, b.to_vec()].concat();
    let tri_f32 = tri_f32();
    vec![
        bad("empty.ply", b"", ""),
        bad("no-end-header.ply", b"ply\nformat ascii 1.0\nelement vertex 3\n", ""),
        bad(
            "count-lies.ply",
            &cat(ply_head("ascii", "5", "1"), b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
            "line ",
        ),
        bad(
            "truncated-binary.ply",
            &cat(ply_head("binary_little_endian", "3", "1"), &tri_f32[..20]),
            "byte ",
        ),
        bad(
            "absurd-count.ply",
            &cat(ply_head("binary_little_endian", "4000000000", "1"), &tri_f32),
            "byte ",
        ),
        bad(
            "index-range.ply",
            &cat(ply_head("ascii", "3", "1"), b"0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"),
            "line 13",
        ),
        bad(
            "two-vertex-face.ply",
            &cat(ply_head("ascii", "3", "1"), b"0 0 0\n1 0 0\n0 1 0\n2 0 1\n"),
            "line 13",
        ),
        bad(
            "nan.ply",
            &cat(ply_head("ascii", "3", "1"), b"0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n"),
            "line 11",
        ),
        bad(
            "wrong-type.ply",
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty quaternion x\nend_header\n",
            "line 4",
        ),
        // Whole-file errors from the PLY header check and the gltf crate (no offsets to give).
        bad(
            "non-utf8-header.ply",
            b"ply\nformat ascii 1.0\nelement vert\xffex 3\nend_header\n",
            "",
        ),
        bad("bad-format.ply", b"ply\nformat ebcdic 1.0\nend_header\n", "line 2"),
    ]
}

fn off_cases() -> Vec<BadFile> {
    vec![
        bad("empty.off", b"", ""),
        bad("count-lies.off", b"OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n", "line "),
        bad("absurd-count.off", b"OFF\n4000000000 4000000000 0\n0 0 0\n", "line "),
        bad("nan.off", b"OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", "line 4"),
        bad(
            "two-vertex-face.off",
            b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
            "line 6",
        ),
    ]
}

fn stl_cases() -> Vec<BadFile> {
    let tri_f32 = tri_f32();
    let mut stl_bin = vec![0u8; 80];
    stl_bin.extend(1_000_000_000u32.to_le_bytes());
    stl_bin.extend([0u8; 12]);
    stl_bin.extend(&tri_f32);
    stl_bin.extend([0u8; 2]);
    let mut stl_nan = vec![0u8; 80];
    stl_nan.extend(1u32.to_le_bytes());
    stl_nan.extend([0u8; 12]);
    stl_nan.extend(f32::NAN.to_le_bytes());
    stl_nan.extend(&tri_f32[4..]);
    stl_nan.extend([0u8; 2]);
    vec![
        bad("empty.stl", b"", ""),
        bad("count-lies.stl", &stl_bin, "byte "),
        bad("nan.stl", &stl_nan, "byte "),
        bad(
            "truncated-ascii.stl",
            b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0",
            "line 5",
        ),
    ]
}

fn gltf_cases() -> Vec<BadFile> {
    let glb = |json: &str, declared_len: u32| {
        let mut j = json.as_bytes().to_vec();
        while !j.len().is_multiple_of(4) {
            j.push(b' ');
        }
        let mut v = b"glTF".to_vec();
        v.extend(2u32.to_le_bytes());
        v.extend(declared_len.to_le_bytes());
        v.extend((j.len() as u32).to_le_bytes());
        v.extend(b"JSON");
        v.extend(j);
        v
    };
    vec![
        bad("empty.gltf", b"", ""),
        bad(
            "bad-json.gltf",
            b"{\n\"asset\": {\"version\": \"2.0\"},\n\"meshes\": [\n",
            "line ",
        ),
        bad("wrong-type.gltf", b"{\n\"asset\": {\"version\": 2}\n}\n", "line "),
        bad(
            "truncated.glb",
            &glb("{\"asset\":{\"version\":\"2.0\"}}", 1_000_000)[..30],
            "",
        ),
    ]
}

fn scene_cases() -> Vec<BadFile> {
    vec![
        bad("empty.toml", b"", ""),
        bad(
            "wrong-type.toml",
            b"[camera]\neye = [0, 1, 4]\ntarget = \"origin\"\n",
            "line 3",
        ),
        bad(
            "unknown-key.toml",
            b"[camera]\neye = [0, 1, 4]\ntarget = [0, 0, 0]\nzoom = 2\n",
            "line 4",
        ),
        bad("non-utf8.toml", b"[camera]\neye = [0, 1, 4]\xff\n", "byte 24"),
        bad(
            "missing-mesh.toml",
            b"[camera]\neye = [0, 1, 4]\ntarget = [0, 0, 0]\n[[object]]\nmesh = \"nowhere.ply\"\n",
            "line 4",
        ),
        bad(
            "nan-transform.toml",
            b"[camera]\neye = [0, 1, 4]\ntarget = [0, 0, 0]\n[[object]]\nshape = \"plane\"\nscale = nan\n",
            "line ",
        ),
    ]
}
