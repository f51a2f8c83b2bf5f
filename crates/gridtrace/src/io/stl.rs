//! STL, binary and ASCII. STL stores every triangle with its own three corners; vertices are
//! welded by exact position equality (bit patterns, with -0.0 folded into 0.0) so the result is
//! an indexed mesh. Facet normals are ignored (they are often wrong; the scene recomputes them).
//!
//! A file is binary when its size is exactly `84 + 50 * n` for the triangle count `n` stored at
//! byte 80, even if it starts with `solid` (many exporters write that into binary headers). A
//! file that does not start with `solid` is binary too, and must be at least that long.

use std::collections::HashMap;
use std::path::Path;

use glam::Vec3;

use super::{capped_capacity, check_finite, finish};
use crate::{Error, Location, Mesh, Result};

/// Parses STL bytes (binary or ASCII).
pub fn parse(data: &[u8], path: &Path) -> Result<Mesh> {
    if data.is_empty() {
        return Err(Error::parse(path, Location::Whole, "empty file"));
    }
    let declared = data.get(80..84).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let binary_len = declared.map(|n| 84 + 50 * n as u64);
    let starts_with_solid = {
        let start = data.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(data.len());
        data[start..].starts_with(b"solid")
    };
    if binary_len == Some(data.len() as u64) || !starts_with_solid {
        parse_binary(data, path)
    } else {
        parse_ascii(data, path)
    }
}

/// Welds vertices by exact position.
struct Welder {
    mesh: Mesh,
    ids: HashMap<[u32; 3], u32>,
}

impl Welder {
    fn new(triangles: usize) -> Self {
        let mut mesh = Mesh::default();
        mesh.triangles.reserve_exact(triangles);
        Welder {
            mesh,
            ids: HashMap::with_capacity(triangles / 2),
        }
    }

    fn vertex(&mut self, v: Vec3) -> u32 {
        let v = v + Vec3::ZERO; // -0.0 + 0.0 == +0.0
        let key = v.to_array().map(f32::to_bits);
        let positions = &mut self.mesh.positions;
        *self.ids.entry(key).or_insert_with(|| {
            positions.push(v);
            (positions.len() - 1) as u32
        })
    }
}

fn parse_binary(data: &[u8], path: &Path) -> Result<Mesh> {
    if data.len() < 84 {
        return Err(Error::parse(
            path,
            Location::Byte(data.len() as u64),
            format!("not an STL file: {} bytes, too short for a binary header", data.len()),
        ));
    }
    let n = u32::from_le_bytes([data[80], data[81], data[82], data[83]]) as u64;
    let expected = 84 + 50 * n;
    if (data.len() as u64) < expected {
        let complete = (data.len() as u64 - 84) / 50;
        return Err(Error::parse(
            path,
            Location::Byte(84 + 50 * complete),
            format!(
                "binary STL declares {n} triangles ({expected} bytes) but the file has {} bytes",
                data.len()
            ),
        ));
    }
    let mut w = Welder::new(capped_capacity(n, data.len() - 84, 50));
    let f32_at = |o: usize| f32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]]);
    for t in 0..n as usize {
        let record = 84 + 50 * t;
        let mut tri = [0u32; 3];
        for (k, slot) in tri.iter_mut().enumerate() {
            let o = record + 12 + 12 * k;
            let v = Vec3::new(f32_at(o), f32_at(o + 4), f32_at(o + 8));
            check_finite(path, Location::Byte(o as u64), "vertex", v)?;
            *slot = w.vertex(v);
        }
        w.mesh.triangles.push(tri);
    }
    finish(w.mesh, path)
}

fn parse_ascii(data: &[u8], path: &Path) -> Result<Mesh> {
    let err = |line: usize, msg: String| Error::parse(path, Location::Line(line), msg);
    // The smallest facet ("facet normal 0 0 0 outer loop vertex 0 0 0 ...") is well over 80 bytes.
    let mut w = Welder::new(data.len() / 80);
    let mut corners: Vec<u32> = Vec::new();
    let mut in_loop = false;
    for (i, raw) in data.split(|&b| b == b'\n').enumerate() {
        let n = i + 1;
        let text = String::from_utf8_lossy(raw);
        let mut t = text.split_ascii_whitespace();
        let Some(keyword) = t.next() else { continue };
        match keyword {
            "solid" | "endsolid" | "facet" | "endfacet" => {}
            "outer" => {
                if in_loop {
                    return Err(err(n, "'outer loop' inside a loop".into()));
                }
                in_loop = true;
                corners.clear();
            }
            "vertex" => {
                if !in_loop {
                    return Err(err(n, "'vertex' outside 'outer loop'".into()));
                }
                let mut c = [0.0f32; 3];
                for slot in &mut c {
                    let s = t.next().ok_or_else(|| err(n, "vertex needs 3 coordinates".into()))?;
                    *slot = s.parse().map_err(|_| err(n, format!("invalid number '{s}'")))?;
                }
                let v = Vec3::from_array(c);
                check_finite(path, Location::Line(n), "vertex", v)?;
                corners.push(w.vertex(v));
            }
            "endloop" => {
                if !in_loop {
                    return Err(err(n, "'endloop' without 'outer loop'".into()));
                }
                in_loop = false;
                if corners.len() < 3 {
                    return Err(err(n, format!("facet with {} vertices (need 3)", corners.len())));
                }
                for k in 1..corners.len() - 1 {
                    w.mesh.triangles.push([corners[0], corners[k], corners[k + 1]]);
                }
            }
            other => return Err(err(n, format!("unexpected '{other}'"))),
        }
    }
    if in_loop {
        let lines = data.split(|&b| b == b'\n').count() - usize::from(data.ends_with(b"\n"));
        return Err(err(lines, "unexpected end of file inside a facet".into()));
    }
    finish(w.mesh, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII: &str = "solid cube_corner\n\
        facet normal 0 0 -1\n  outer loop\n    vertex 0 0 0\n    vertex 1 0 0\n\
            vertex 1 1 0\n  endloop\nendfacet\n\
        facet normal 0 0 -1\r\n\touter loop\r\n\t\tvertex 0 0 0\r\n\t\tvertex 1 1 0\r\n\
        \t\tvertex -0 1 0\r\n\tendloop\r\nendfacet\r\nendsolid cube_corner\n";

    fn binary(header: &[u8], tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
        let mut out = vec![0u8; 80];
        out[..header.len()].copy_from_slice(header);
        out.extend_from_slice(&(tris.len() as u32).to_le_bytes());
        for t in tris {
            out.extend_from_slice(&[0u8; 12]);
            for v in t {
                for c in v {
                    out.extend_from_slice(&c.to_le_bytes());
                }
            }
            out.extend_from_slice(&[0, 0]);
        }
        out
    }

    const QUAD: [[[f32; 3]; 3]; 2] = [
        [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.]],
        [[0., 0., 0.], [1., 1., 0.], [0., 1., 0.]],
    ];

    fn err(data: &[u8]) -> String {
        parse(data, Path::new("bad.stl")).unwrap_err().to_string()
    }

    #[test]
    fn ascii_welds_vertices() {
        let m = parse(ASCII.as_bytes(), Path::new("a.stl")).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.positions[3], Vec3::new(0.0, 1.0, 0.0));
        assert!(m.positions[3].x.is_sign_positive());
    }

    #[test]
    fn binary_welds_vertices_even_with_solid_header() {
        for header in [&b"binary quad"[..], b"solid quad exported by a tool"] {
            let m = parse(&binary(header, &QUAD), Path::new("b.stl")).unwrap();
            assert_eq!(m.positions.len(), 4);
            assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
            assert_eq!(m.positions[2], Vec3::new(1.0, 1.0, 0.0));
        }
    }

    #[test]
    fn malformed_inputs() {
        let data = binary(b"x", &QUAD);
        let e = err(&data[..data.len() - 1]);
        assert!(e.starts_with("bad.stl:byte 134:") && e.contains("declares 2"), "{e}");
        let mut data = binary(b"x", &QUAD);
        data[84 + 50 + 12 + 12 + 4..84 + 50 + 12 + 12 + 8].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = err(&data);
        assert!(e.starts_with("bad.stl:byte 158:"), "{e}");
        // A header claiming 4 billion triangles with two present must not allocate for them.
        let mut data = binary(b"x", &QUAD);
        data[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(err(&data).contains("4294967295"));
        assert!(err(&binary(b"x", &[])).contains("no triangles"));

        let bad_num = ASCII.replace("vertex 1 0 0", "vertex 1 zero 0");
        assert!(err(bad_num.as_bytes()).starts_with("bad.stl:line 5:"));
        let nan = ASCII.replace("vertex 1 0 0", "vertex 1 NaN 0");
        assert!(err(nan.as_bytes()).starts_with("bad.stl:line 5:"));
        let two = ASCII.replace("vertex 1 1 0\n  endloop", "  endloop");
        let e = err(two.as_bytes());
        assert!(e.starts_with("bad.stl:line 6:") && e.contains("2 vertices"), "{e}");
        let junk = ASCII.replace("endfacet\r\n", "endfacet\r\nbogus\r\n");
        assert!(err(junk.as_bytes()).starts_with("bad.stl:line 16:"));
        assert!(err(b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n").contains("line 4"));
        assert!(err(b"").contains("empty file"));
        assert!(err(b"solid empty\nendsolid empty\n").contains("no triangles"));
        assert!(err(b"\x89garbage").contains("bad.stl"));
    }

    #[test]
    fn every_prefix_never_panics() {
        for data in [binary(b"solid", &QUAD), ASCII.as_bytes().to_vec()] {
            for len in 0..data.len() {
                let _ = parse(&data[..len], Path::new("p.stl"));
            }
        }
    }
}
