//! Object File Format (Geomview OFF), ASCII.
//!
//! ```text
//! OFF                  # or COFF / NOFF / CNOFF / STOFF ...; counts may follow on this line
//! nv nf ne
//! x y z [anything]     # nv vertex lines; extra values (normals, colours) ignored,
//!                      # except that the N variants' normals are read
//! n i1 .. in [colour]  # nf faces; polygons fan-triangulated, trailing colour ignored
//! ```
//! `#` starts a comment; blank lines are skipped. Binary OFF is not supported.

use std::path::Path;

use glam::Vec3;

use super::{capped_capacity, check_finite, finish};
use crate::{Error, Location, Mesh, Result};

/// Parses OFF bytes.
pub fn parse(data: &[u8], path: &Path) -> Result<Mesh> {
    let err = |line: usize, msg: String| Error::parse(path, Location::Line(line), msg);
    // The last line, for errors about missing data (a final newline does not start a line).
    let total_lines = data.split(|&b| b == b'\n').count() - usize::from(data.ends_with(b"\n"));
    // Non-empty lines without comments, with their 1-based numbers.
    let mut lines = data.split(|&b| b == b'\n').enumerate().filter_map(|(i, raw)| {
        let raw = raw.split(|&b| b == b'#').next().unwrap_or(raw);
        let text = String::from_utf8_lossy(raw).into_owned();
        (!text.trim().is_empty()).then_some((i + 1, text))
    });
    let Some((first_no, first)) = lines.next() else {
        return Err(Error::parse(path, Location::Whole, "empty file"));
    };
    let mut tokens = first.split_ascii_whitespace();
    let keyword = tokens.next().unwrap_or("");
    let Some(prefix) = keyword.strip_suffix("OFF") else {
        return Err(err(first_no, format!("not an OFF file (starts with '{keyword}')")));
    };
    if tokens.clone().next() == Some("BINARY") {
        return Err(err(first_no, "binary OFF is not supported".into()));
    }
    let has_normals = prefix.contains('N');
    if prefix.contains('4') || prefix.contains('n') {
        return Err(err(first_no, format!("'{keyword}' (non-3D OFF) is not supported")));
    }
    // Counts on the keyword line, or on the next line.
    let mut rest: Vec<String> = tokens.map(str::to_string).collect();
    let mut counts_no = first_no;
    if rest.is_empty() {
        let Some((no, line)) = lines.next() else {
            return Err(err(first_no, "missing vertex/face counts".into()));
        };
        counts_no = no;
        rest = line.split_ascii_whitespace().map(str::to_string).collect();
    }
    let count = |k: usize| -> Result<u64> {
        let s = rest
            .get(k)
            .ok_or_else(|| err(counts_no, "expected 'vertices faces edges'".into()))?;
        s.parse().map_err(|_| err(counts_no, format!("invalid count '{s}'")))
    };
    let (nv, nf) = (count(0)?, count(1)?);
    if nv > u64::from(u32::MAX) {
        return Err(err(
            counts_no,
            format!("{nv} vertices is more than 32-bit indices can address"),
        ));
    }

    let mut mesh = Mesh::default();
    // A vertex line is at least "0 0 0\n", a face line at least "3 0 0 0\n".
    mesh.positions.reserve_exact(capped_capacity(nv, data.len(), 6));
    mesh.triangles.reserve_exact(capped_capacity(nf, data.len(), 8));
    let truncated = |what: &str, declared: u64, found: u64| {
        err(
            total_lines,
            format!("unexpected end of file: {declared} {what} declared, found {found}"),
        )
    };
    let number =
        |no: usize, s: &str| -> Result<f32> { s.parse().map_err(|_| err(no, format!("invalid number '{s}'"))) };
    for done in 0..nv {
        let Some((no, line)) = lines.next() else {
            return Err(truncated("vertices", nv, done));
        };
        let t: Vec<&str> = line.split_ascii_whitespace().collect();
        let want = if has_normals { 6 } else { 3 };
        if t.len() < want {
            return Err(err(no, format!("vertex has {} values, expected {want}", t.len())));
        }
        let v = Vec3::new(number(no, t[0])?, number(no, t[1])?, number(no, t[2])?);
        check_finite(path, Location::Line(no), "vertex", v)?;
        mesh.positions.push(v);
        if has_normals {
            mesh.normals
                .push(Vec3::new(number(no, t[3])?, number(no, t[4])?, number(no, t[5])?));
        }
    }
    let mut face: Vec<u32> = Vec::new();
    for done in 0..nf {
        let Some((no, line)) = lines.next() else {
            return Err(truncated("faces", nf, done));
        };
        let mut t = line.split_ascii_whitespace();
        let n_str = t.next().unwrap_or("");
        let n: usize = n_str
            .parse()
            .map_err(|_| err(no, format!("invalid vertex count '{n_str}'")))?;
        if n < 3 {
            return Err(err(no, format!("face with {n} vertices (need at least 3)")));
        }
        face.clear();
        for k in 0..n {
            let s = t
                .next()
                .ok_or_else(|| err(no, format!("face lists {k} of {n} vertices")))?;
            let i: i64 = s.parse().map_err(|_| err(no, format!("invalid vertex index '{s}'")))?;
            if i < 0 || i >= nv as i64 {
                return Err(err(no, format!("vertex index {i} out of range ({nv} vertices)")));
            }
            face.push(i as u32);
        }
        for k in 1..n - 1 {
            mesh.triangles.push([face[0], face[k], face[k + 1]]);
        }
    }
    finish(mesh, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CUBE_TOP: &str = "OFF\n# a comment\n\n4 2 0\n0 0 1\n1 0 1\n1 1 1 # corner\n0 1 1\n\
                            3 0 1 2 255 0 0\n3 0 2 3\n";

    fn err(data: &[u8]) -> String {
        parse(data, Path::new("bad.off")).unwrap_err().to_string()
    }

    #[test]
    fn loads_triangles_and_polygons() {
        let m = parse(CUBE_TOP.as_bytes(), Path::new("t.off")).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.positions[2], Vec3::new(1.0, 1.0, 1.0));

        let m = parse(
            b"OFF 4 1 0\r\n0 0 0\r\n1 0 0\r\n1 1 0\r\n0 1 0\r\n4 3 2 1 0\r\n",
            Path::new("q.off"),
        )
        .unwrap();
        assert_eq!(m.triangles, vec![[3, 2, 1], [3, 1, 0]]);

        let m = parse(
            b"COFF\n3 1 3\n0 0 0 1 0 0 1\n1 0 0 1 0 0 1\n0 1 0 1 0 0 1\n3 0 1 2\n",
            Path::new("c.off"),
        )
        .unwrap();
        assert_eq!(m.triangles.len(), 1);
        let m = parse(
            b"NOFF\n3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n",
            Path::new("n.off"),
        )
        .unwrap();
        assert_eq!(m.normals, vec![Vec3::Z; 3]);
    }

    #[test]
    fn malformed_inputs() {
        let oob = CUBE_TOP.replace("3 0 2 3", "3 0 2 4");
        let e = err(oob.as_bytes());
        assert!(e.starts_with("bad.off:line 10:") && e.contains("out of range"), "{e}");
        let two = CUBE_TOP.replace("3 0 2 3", "2 0 2");
        assert!(err(two.as_bytes()).starts_with("bad.off:line 10:"));
        let nan = CUBE_TOP.replace("1 0 1\n", "1 nan 1\n");
        assert!(err(nan.as_bytes()).starts_with("bad.off:line 6:"));
        let bad = CUBE_TOP.replace("0 1 1\n", "0 1 one\n");
        assert!(err(bad.as_bytes()).starts_with("bad.off:line 8:"));
        let lying = CUBE_TOP.replace("4 2 0", "4000000000 2 0");
        let e = err(lying.as_bytes());
        assert!(e.contains("4000000000 vertices declared, found 6"), "{e}");
        let lying = CUBE_TOP.replace("4 2 0", "4 3 0");
        assert!(err(lying.as_bytes()).contains("3 faces declared, found 2"));
        assert!(err(b"").contains("empty file"));
        assert!(err(b"OFF\n0 0 0\n").contains("no triangles"));
        assert!(err(b"PLY\n").starts_with("bad.off:line 1:"));
        assert!(err(b"OFF\nthree 1 0\n").starts_with("bad.off:line 2:"));
        assert!(err(b"OFF BINARY\n").contains("binary"));
        assert!(err(b"\xff\xfe\x00garbage").contains("bad.off"));
    }

    #[test]
    fn every_prefix_never_panics() {
        let data = CUBE_TOP.as_bytes();
        for len in 0..data.len() {
            let _ = parse(&data[..len], Path::new("p.off"));
        }
    }
}
