use super::*;

const HEADER_VERTS: &str = "element vertex 4\n\
    property float x\nproperty float y\nproperty float z\n";

fn ascii_quad() -> String {
    format!(
        "ply\nformat ascii 1.0\ncomment made by hand\n{HEADER_VERTS}\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n"
    )
}

fn err(data: &[u8]) -> String {
    parse(data, Path::new("bad.ply")).unwrap_err().to_string()
}

/// Writes one value of a PLY type in the given byte order.
fn put(out: &mut Vec<u8>, ty: &str, v: f64, be: bool) {
    let mut b: Vec<u8> = match ty {
        "char" => vec![v as i8 as u8],
        "uchar" => vec![v as u8],
        "short" => (v as i16).to_le_bytes().to_vec(),
        "ushort" => (v as u16).to_le_bytes().to_vec(),
        "int" => (v as i32).to_le_bytes().to_vec(),
        "uint" => (v as u32).to_le_bytes().to_vec(),
        "float" => (v as f32).to_le_bytes().to_vec(),
        "double" => v.to_le_bytes().to_vec(),
        _ => unreachable!(),
    };
    if be {
        b.reverse();
    }
    out.extend_from_slice(&b);
}

/// A binary PLY quad with normals, colours, an unknown list property on vertices, an
/// unknown `edge` element between vertex and face, and a face `flags` property.
fn binary_quad(be: bool, count_ty: &str, index_ty: &str) -> Vec<u8> {
    let fmt = if be {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut out = format!(
        "ply\r\nformat {fmt} 1.0\r\nobj_info test\r\nelement vertex 4\r\n\
         property double x\r\nproperty float y\r\nproperty short z\r\n\
         property float nx\r\nproperty float ny\r\nproperty float nz\r\n\
         property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n\
         property list uchar uint tags\r\n\
         element edge 2\r\nproperty int vertex1\r\nproperty int vertex2\r\n\
         property list ushort float weights\r\n\
         element face 2\r\nproperty uchar flags\r\n\
         property list {count_ty} {index_ty} vertex_indices\r\nproperty double area\r\n\
         end_header\r\n"
    )
    .into_bytes();
    let verts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 5.0]];
    for (i, v) in verts.iter().enumerate() {
        put(&mut out, "double", v[0], be);
        put(&mut out, "float", v[1], be);
        put(&mut out, "short", v[2], be);
        for n in [0.0, 0.0, 1.0] {
            put(&mut out, "float", n, be);
        }
        for c in [255.0, 128.0, 0.0] {
            put(&mut out, "uchar", c, be);
        }
        put(&mut out, "uchar", i as f64, be);
        for t in 0..i {
            put(&mut out, "uint", t as f64, be);
        }
    }
    for (a, b) in [(0.0, 1.0), (1.0, 2.0)] {
        put(&mut out, "int", a, be);
        put(&mut out, "int", b, be);
        put(&mut out, "ushort", 2.0, be);
        put(&mut out, "float", 0.5, be);
        put(&mut out, "float", 0.25, be);
    }
    for face in [&[0.0, 1.0, 2.0, 3.0][..], &[0.0, 2.0, 3.0]] {
        put(&mut out, "uchar", 7.0, be);
        put(&mut out, count_ty, face.len() as f64, be);
        for &i in face {
            put(&mut out, index_ty, i, be);
        }
        put(&mut out, "double", 1.0, be);
    }
    out
}

#[test]
fn ascii_quad_loads() {
    let m = parse(ascii_quad().as_bytes(), Path::new("q.ply")).unwrap();
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(m.positions[2], Vec3::new(1.0, 1.0, 0.0));
    assert!(m.normals.is_empty());
}

#[test]
fn ascii_with_unknown_element_and_normals() {
    let src = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
               property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
               property list uchar float extra\n\
               element edge 1\nproperty int a\nproperty list uint int b\n\
               element face 1\nproperty list ushort uint vertex_index\nend_header\n\
               0 0 0 0 0 1 0\n1 0 0 0 0 1 2 0.5 1.5\n0 1 0 0 0 1 1 9\n\
               5 3 1 2 3\n\
               3 2 1 0\n";
    let m = parse(src.as_bytes(), Path::new("e.ply")).unwrap();
    assert_eq!(m.triangles, vec![[2, 1, 0]]);
    assert_eq!(m.normals, vec![Vec3::Z; 3]);
    assert_eq!(m.positions[1], Vec3::X);
}

#[test]
fn binary_variants_load() {
    for be in [false, true] {
        for (count_ty, index_ty) in [
            ("uchar", "int"),
            ("ushort", "uint"),
            ("uint", "ushort"),
            ("char", "uchar"),
        ] {
            let data = binary_quad(be, count_ty, index_ty);
            let m = parse(&data, Path::new("b.ply")).unwrap_or_else(|e| panic!("{be} {count_ty} {index_ty}: {e}"));
            assert_eq!(m.positions.len(), 4);
            assert_eq!(m.positions[3], Vec3::new(0.0, 1.0, 5.0));
            assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
            assert_eq!(m.normals, vec![Vec3::Z; 4]);
        }
    }
}

#[test]
fn truncated_binary_names_the_byte() {
    let data = binary_quad(false, "uchar", "int");
    let header_len = data.windows(12).position(|w| w == b"end_header\r\n").unwrap() + 12;
    // Cut inside the third vertex: 8+4+2+12+3+1 = 30 bytes per vertex plus 0,1,2 tags.
    let cut = header_len + 30 + 34 + 10;
    let e = err(&data[..cut]);
    assert!(
        e.starts_with(&format!("bad.ply:byte {}:", header_len + 30 + 34 + 8)),
        "{e}"
    );
    assert!(e.contains("unexpected end of data"), "{e}");
    // Cut in the last face.
    let e = err(&data[..data.len() - 3]);
    assert!(e.starts_with(&format!("bad.ply:byte {}:", data.len() - 8)), "{e}");
}

#[test]
fn lying_counts_do_not_allocate() {
    let mut data = b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n\
        property float x\nproperty float y\nproperty float z\n\
        element face 4000000000\nproperty list uchar int vertex_indices\nend_header\n"
        .to_vec();
    let start = data.len();
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in v {
            data.extend_from_slice(&c.to_le_bytes());
        }
    }
    let e = err(&data);
    assert!(e.starts_with(&format!("bad.ply:byte {}:", start + 36)), "{e}");
    assert!(e.contains("4000000000") && e.contains("found 3"), "{e}");

    let e = err(b"ply\nformat ascii 1.0\nelement vertex 18446744073709551615\n\
        property float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n");
    assert!(e.contains("bad.ply"), "{e}");
    let e = err(b"ply\nformat ascii 1.0\nelement vertex 3\n\
        property float x\nproperty float y\nproperty float z\n\
        element face 4000000000\nproperty list uchar int vertex_indices\nend_header\n\
        0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    assert!(e.starts_with("bad.ply:line 13:") && e.contains("found 1"), "{e}");
    // Unknown element with a huge count and a huge binary list length.
    let mut data = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\n\
        property uchar x\nproperty uchar y\nproperty uchar z\n\
        element junk 1\nproperty list uint double stuff\nend_header\n"
        .to_vec();
    data.extend_from_slice(&[0, 0, 0, 1, 0, 0, 0, 1, 0, 0xff, 0xff, 0xff, 0xff, 1, 2]);
    assert!(err(&data).contains("unexpected end of data"));
}

#[test]
fn malformed_inputs() {
    let quad = ascii_quad();
    let index_oob = quad.replace("4 0 1 2 3", "4 0 1 2 4");
    let e = err(index_oob.as_bytes());
    assert!(e.starts_with("bad.ply:line 15:") && e.contains("out of range"), "{e}");
    let nan = quad.replace("1 1 0\n", "1 nan 0\n");
    assert!(err(nan.as_bytes()).starts_with("bad.ply:line 13:"));
    let two = quad.replace("4 0 1 2 3", "2 0 1");
    let e = err(two.as_bytes());
    assert!(e.starts_with("bad.ply:line 15:") && e.contains("face with 2"), "{e}");
    let bad_num = quad.replace("1 0 0\n", "1 x 0\n");
    assert!(err(bad_num.as_bytes()).starts_with("bad.ply:line 12:"));
    let bad_type = quad.replace("property float y", "property flot y");
    assert!(err(bad_type.as_bytes()).starts_with("bad.ply:line 6:"));
    let no_end = quad.split("end_header").next().unwrap();
    assert!(err(no_end.as_bytes()).contains("no 'end_header'"));
    assert!(err(quad.replace("end_header\n", "").as_bytes()).starts_with("bad.ply:line 10:"));
    assert!(err(b"").contains("empty file"));
    assert!(err(b"\x00\x9f\x13garbage\xff\xfe").starts_with("bad.ply:line 1:"));

    // Binary: NaN coordinate and out-of-range index name their byte offsets.
    let mut data = binary_quad(false, "uchar", "int");
    let header_len = data.windows(12).position(|w| w == b"end_header\r\n").unwrap() + 12;
    data[header_len + 30 + 8..header_len + 30 + 12].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = err(&data);
    assert!(e.starts_with(&format!("bad.ply:byte {}:", header_len + 30)), "{e}");
    let mut data = binary_quad(true, "uchar", "int");
    let n = data.len();
    data[n - 12..n - 8].copy_from_slice(&9i32.to_be_bytes());
    let e = err(&data);
    assert!(
        e.starts_with(&format!("bad.ply:byte {}:", n - 12)) && e.contains("9"),
        "{e}"
    );
}

#[test]
fn random_mutations_never_panic() {
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for base in [binary_quad(false, "uchar", "int"), binary_quad(true, "uint", "ushort")] {
        for _ in 0..3000 {
            let mut data = base.clone();
            for _ in 0..1 + next() % 4 {
                let i = (next() % data.len() as u64) as usize;
                data[i] = next() as u8;
            }
            let _ = parse(&data, Path::new("m.ply"));
        }
    }
}

#[test]
fn every_prefix_never_panics() {
    for data in [binary_quad(false, "uchar", "int"), binary_quad(true, "ushort", "uint")] {
        for len in 0..data.len() {
            let _ = parse(&data[..len], Path::new("p.ply"));
        }
        assert!(parse(&data, Path::new("p.ply")).is_ok());
    }
    let data = ascii_quad().into_bytes();
    for len in 0..data.len() {
        let _ = parse(&data[..len], Path::new("p.ply"));
    }
}
