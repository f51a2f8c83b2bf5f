//! Wavefront OBJ (with MTL material libraries).
//!
//! Supported: `v` (extra w / colour components ignored), `vn`, `f` in the `v`, `v/vt`, `v//vn`
//! and `v/vt/vn` forms with positive or negative (relative) indices, polygons (fan-triangulated),
//! `usemtl` (one material per name, in order of first use), `mtllib` (`newmtl`, `Kd`, and `Pm`
//! as a metallic hint mapped to reflectivity), `#` comments, tabs / runs of spaces, `\r\n` line
//! endings and `\` line continuations. Everything else (`vt`, `o`, `g`, `s`, `l`, ...) is ignored.
//!
//! Face indices must refer to vertices (and normals) defined earlier in the file.
//!
//! Normals are kept only when every face corner names one and no position is used with two
//! different normals; otherwise `normals` is left empty for the scene to compute.

use std::collections::HashMap;
use std::path::Path;

use glam::Vec3;

use super::{check_finite, count_of, finish};
use crate::{Error, Location, Material, Mesh, Result};

const NONE: u32 = u32::MAX;

/// Parses OBJ bytes. `mtl` returns the bytes of a material library named by `mtllib` (relative
/// to the OBJ file), or `None` when it cannot be found, which is not an error.
pub fn parse(data: &[u8], path: &Path, mtl: &dyn Fn(&str) -> Option<Vec<u8>>) -> Result<Mesh> {
    let mut p = Parser {
        path,
        positions: Vec::new(),
        vn: Vec::new(),
        pos_normal: Vec::new(),
        normals_ok: false,
        any_face: false,
        triangles: Vec::new(),
        tri_mat: Vec::new(),
        current_mat: 0,
        mat_names: Vec::new(),
        mat_ids: HashMap::new(),
        mtllibs: Vec::new(),
        face: Vec::new(),
        binary_line: None,
    };
    for (line_no, line) in logical_lines(data) {
        p.line(line_no, &line)?;
    }
    if p.triangles.is_empty() {
        return Err(p.why_no_triangles(data));
    }
    p.into_mesh(mtl)
}

/// Formats whose files are taken for OBJ when renamed, by their first bytes, for the error that
/// says what the file is instead.
const MAGIC: [(&[u8], &str); 7] = [
    (b"\x89PNG", "a PNG image"),
    (b"\xFF\xD8\xFF", "a JPEG image"),
    (b"glTF", "a binary glTF (.glb)"),
    (b"ply", "a PLY mesh (.ply)"),
    (b"OFF", "an OFF mesh (.off)"),
    (b"PK\x03\x04", "a zip archive"),
    (b"\x1F\x8B", "a gzip archive"),
];

struct Parser<'p> {
    path: &'p Path,
    positions: Vec<Vec3>,
    vn: Vec<Vec3>,
    /// Per position: index into `vn` of the normal it was used with, or `NONE`.
    pos_normal: Vec<u32>,
    normals_ok: bool,
    any_face: bool,
    triangles: Vec<[u32; 3]>,
    /// Per triangle: material slot, or `NONE` before the first `usemtl`.
    tri_mat: Vec<u32>,
    current_mat: u32,
    mat_names: Vec<String>,
    mat_ids: HashMap<String, u32>,
    mtllibs: Vec<String>,
    /// Scratch for one face: (position, normal or NONE).
    face: Vec<(u32, u32)>,
    /// The first line (outside comments) that is not text: invalid UTF-8 or a NUL byte.
    binary_line: Option<usize>,
}

/// Splits into lines (`\n`, optional `\r`), joining `\`-continued lines. Yields the 1-based number
/// of each logical line's first physical line.
fn logical_lines(data: &[u8]) -> impl Iterator<Item = (usize, Vec<u8>)> + '_ {
    let mut phys = data.split(|&b| b == b'\n').enumerate().peekable();
    std::iter::from_fn(move || {
        let (i, first) = phys.next()?;
        let mut line = strip_cr(first).to_vec();
        while line.last() == Some(&b'\\') {
            line.pop();
            line.push(b' ');
            match phys.next() {
                Some((_, next)) => line.extend_from_slice(strip_cr(next)),
                None => break,
            }
        }
        Some((i + 1, line))
    })
}

fn strip_cr(line: &[u8]) -> &[u8] {
    line.strip_suffix(b"\r").unwrap_or(line)
}

impl Parser<'_> {
    fn err(&self, line: usize, msg: impl Into<String>) -> Error {
        Error::parse(self.path, Location::Line(line), msg)
    }

    /// The error for a file that gave no face: what it holds instead (binary data, vertices
    /// only, nothing OBJ at all), where `finish` alone would say "no triangles". Unknown
    /// keywords and lines that are not text are skipped while parsing (OBJ files carry many
    /// statements we do not read), so a renamed image parses to nothing; this says why.
    fn why_no_triangles(&self, data: &[u8]) -> Error {
        // What the first bytes say the file is, when it is a format people rename by mistake.
        let looks = MAGIC
            .iter()
            .find(|(magic, _)| data.starts_with(magic))
            .map_or(String::new(), |(_, what)| format!("; it starts as {what} does"));
        let (location, msg) = if let Some(line) = self.binary_line {
            (
                Location::Line(line),
                format!(
                    "not an OBJ text file: binary data, no faces read{looks} (an OBJ mesh is text \
                     with 'v X Y Z' and 'f I J K' lines)"
                ),
            )
        } else if data.iter().all(u8::is_ascii_whitespace) {
            (Location::Whole, "empty file: no triangles".to_string())
        } else if self.positions.is_empty() {
            (
                Location::Whole,
                format!("no 'v' (vertex) or 'f' (face) lines, so no triangles: not a Wavefront OBJ mesh{looks}"),
            )
        } else {
            (
                Location::Whole,
                format!(
                    "{} but no 'f' (face) lines: no triangles",
                    count_of(self.positions.len(), "vertex")
                ),
            )
        };
        Error::parse(self.path, location, msg)
    }

    fn line(&mut self, n: usize, raw: &[u8]) -> Result<()> {
        // Comments may hold anything; only the part before `#` must be text.
        let raw = match raw.iter().position(|&b| b == b'#') {
            Some(i) => &raw[..i],
            None => raw,
        };
        if self.binary_line.is_none() && (raw.contains(&0) || std::str::from_utf8(raw).is_err()) {
            self.binary_line = Some(n);
        }
        let text = match std::str::from_utf8(raw) {
            Ok(t) => std::borrow::Cow::Borrowed(t),
            Err(_) => {
                let kw = raw.split(|b| b.is_ascii_whitespace()).find(|t| !t.is_empty());
                if matches!(kw, Some(b"v" | b"vn" | b"vt" | b"f")) {
                    return Err(self.err(n, "invalid UTF-8"));
                }
                String::from_utf8_lossy(raw)
            }
        };
        let mut tokens = text.split_ascii_whitespace();
        let Some(keyword) = tokens.next() else {
            return Ok(());
        };
        match keyword {
            "v" => {
                let v = self.vec3(n, &mut tokens, "vertex")?;
                check_finite(self.path, Location::Line(n), "vertex", v)?;
                if self.positions.len() >= NONE as usize {
                    return Err(self.err(n, "too many vertices"));
                }
                self.positions.push(v);
                self.pos_normal.push(NONE);
            }
            "vn" => {
                let v = self.vec3(n, &mut tokens, "normal")?;
                check_finite(self.path, Location::Line(n), "normal", v)?;
                self.vn.push(v);
            }
            "f" => self.face(n, tokens)?,
            "usemtl" => {
                let name = text.trim_start()["usemtl".len()..].trim().to_string();
                let next = self.mat_names.len() as u32;
                self.current_mat = *self.mat_ids.entry(name.clone()).or_insert_with(|| {
                    self.mat_names.push(name);
                    next
                });
            }
            "mtllib" => {
                let rest = text.trim_start()["mtllib".len()..].trim();
                if !rest.is_empty() {
                    self.mtllibs.push(rest.to_string());
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn vec3<'a>(&self, n: usize, tokens: &mut impl Iterator<Item = &'a str>, what: &str) -> Result<Vec3> {
        let mut c = [0.0f32; 3];
        for (k, slot) in c.iter_mut().enumerate() {
            let t = tokens
                .next()
                .ok_or_else(|| self.err(n, format!("{what} has {k} coordinates, expected 3")))?;
            *slot = t.parse().map_err(|_| self.err(n, format!("invalid number '{t}'")))?;
        }
        Ok(Vec3::from_array(c))
    }

    /// Resolves a 1-based or negative (relative) OBJ index into `0..count`.
    fn index(&self, n: usize, t: &str, count: usize, what: &str) -> Result<u32> {
        let i: i64 = t
            .parse()
            .map_err(|_| self.err(n, format!("invalid {what} index '{t}'")))?;
        let resolved = match i {
            0 => return Err(self.err(n, format!("{what} index 0 (OBJ indices start at 1)"))),
            i if i > 0 => i - 1,
            i => count as i64 + i,
        };
        if resolved < 0 || resolved >= count as i64 {
            return Err(self.err(
                n,
                format!(
                    "{what} index {i} out of range ({} defined so far)",
                    count_of(count, what)
                ),
            ));
        }
        Ok(resolved as u32)
    }

    fn face<'a>(&mut self, n: usize, tokens: impl Iterator<Item = &'a str>) -> Result<()> {
        let mut face = std::mem::take(&mut self.face);
        face.clear();
        for t in tokens {
            let mut parts = t.split('/');
            let v = self.index(n, parts.next().unwrap_or(""), self.positions.len(), "vertex")?;
            if let Some(vt) = parts.next()
                && !vt.is_empty()
            {
                vt.parse::<i64>()
                    .map_err(|_| self.err(n, format!("invalid texture index '{vt}'")))?;
            }
            let vn = match parts.next() {
                Some(vn) if !vn.is_empty() => self.index(n, vn, self.vn.len(), "normal")?,
                _ => NONE,
            };
            if parts.next().is_some() {
                return Err(self.err(n, format!("malformed face vertex '{t}'")));
            }
            face.push((v, vn));
        }
        if face.len() < 3 {
            return Err(self.err(n, format!("face with {} vertices (need at least 3)", face.len())));
        }
        if !self.any_face {
            self.any_face = true;
            self.normals_ok = true;
        }
        if self.normals_ok {
            for &(v, vn) in &face {
                let slot = &mut self.pos_normal[v as usize];
                if vn == NONE {
                    self.normals_ok = false;
                } else if *slot == NONE {
                    *slot = vn;
                } else if *slot != vn && self.vn[*slot as usize] != self.vn[vn as usize] {
                    self.normals_ok = false;
                }
            }
        }
        for k in 1..face.len() - 1 {
            self.triangles.push([face[0].0, face[k].0, face[k + 1].0]);
            self.tri_mat.push(if self.mat_names.is_empty() {
                NONE
            } else {
                self.current_mat
            });
        }
        self.face = face;
        Ok(())
    }

    fn into_mesh(self, resolve: &dyn Fn(&str) -> Option<Vec<u8>>) -> Result<Mesh> {
        let mut mesh = Mesh {
            positions: self.positions,
            triangles: self.triangles,
            ..Mesh::default()
        };
        if self.any_face && self.normals_ok {
            // Positions no face uses get no normal from the file; any unit vector will do.
            mesh.normals = self
                .pos_normal
                .iter()
                .map(|&i| self.vn.get(i as usize).copied().unwrap_or(Vec3::Z))
                .collect();
        }
        if !self.mat_names.is_empty() {
            let mut library: HashMap<String, Material> = HashMap::new();
            for lib in &self.mtllibs {
                let bytes = resolve(lib).or_else(|| {
                    // `mtllib a.mtl b.mtl`: several files on one line.
                    let files: Vec<_> = lib.split_ascii_whitespace().filter_map(resolve).collect();
                    (!files.is_empty()).then(|| files.join(&b'\n'))
                });
                if let Some(bytes) = bytes {
                    parse_mtl(&bytes, &mut library);
                }
            }
            mesh.materials = self
                .mat_names
                .into_iter()
                .map(|name| {
                    library.remove(&name).unwrap_or(Material {
                        name,
                        ..Material::default()
                    })
                })
                .collect();
            let mut tri_mat = self.tri_mat;
            if tri_mat.contains(&NONE) {
                let default = mesh.materials.len() as u32;
                mesh.materials.push(Material::default());
                for m in &mut tri_mat {
                    if *m == NONE {
                        *m = default;
                    }
                }
            }
            mesh.triangle_materials = tri_mat;
        }
        finish(mesh, self.path)
    }
}

/// Reads `newmtl` / `Kd` / `Pm` from a material library into `out`, leniently: a material
/// library only adds colour, so lines that do not parse are skipped.
fn parse_mtl(data: &[u8], out: &mut HashMap<String, Material>) {
    let text = String::from_utf8_lossy(data);
    let mut current: Option<String> = None;
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        let mut tokens = line.split_ascii_whitespace();
        let Some(keyword) = tokens.next() else {
            continue;
        };
        let numbers: Vec<f32> = tokens.filter_map(|t| t.parse().ok()).collect();
        match keyword {
            "newmtl" => {
                let name = line["newmtl".len()..].trim().to_string();
                out.insert(
                    name.clone(),
                    Material {
                        name: name.clone(),
                        ..Material::default()
                    },
                );
                current = Some(name);
            }
            "Kd" => {
                let kd = match numbers[..] {
                    [r, g, b, ..] => Vec3::new(r, g, b),
                    [grey] => Vec3::splat(grey),
                    _ => continue,
                };
                if let Some(m) = current.as_ref().and_then(|c| out.get_mut(c))
                    && kd.is_finite()
                {
                    m.diffuse = kd.clamp(Vec3::ZERO, Vec3::ONE);
                }
            }
            "Pm" => {
                if let (Some(m), Some(&pm)) = (current.as_ref().and_then(|c| out.get_mut(c)), numbers.first())
                    && pm.is_finite()
                {
                    m.reflectivity = pm.clamp(0.0, 1.0);
                }
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_mtl(_: &str) -> Option<Vec<u8>> {
        None
    }

    fn obj(src: &str) -> Result<Mesh> {
        parse(src.as_bytes(), Path::new("test.obj"), &no_mtl)
    }

    fn err(src: &[u8]) -> String {
        parse(src, Path::new("bad.obj"), &no_mtl).unwrap_err().to_string()
    }

    #[test]
    fn out_of_range_index_counts_with_real_plural() {
        let e = err(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
        assert!(
            e.contains("bad.obj:line 4") && e.contains("(3 vertices defined so far)"),
            "{e}"
        );
        let e = err(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//2\n");
        assert!(e.contains("(1 normal defined so far)"), "{e}");
        assert!(!e.contains("vertexs") && !e.contains("normals"), "{e}");
    }

    /// A file that gives no face says what it holds instead, where it was found out.
    #[test]
    fn no_faces_says_what_the_file_is() {
        let png = b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0\0\x10";
        let e = err(png);
        assert!(
            e.contains("bad.obj:line 1") && e.contains("binary data") && e.contains("a PNG image"),
            "{e}"
        );
        let e = err(b"# comment\nv 0 0 0\nv 1 0 0\nv 0 1 0\n");
        assert!(e.contains("3 vertices but no 'f' (face) lines"), "{e}");
        let e = err(b"ply\nformat ascii 1.0\nend_header\n");
        assert!(
            e.contains("no 'v' (vertex) or 'f' (face) lines") && e.contains("a PLY mesh"),
            "{e}"
        );
        assert!(err(b" \n\n").contains("empty file: no triangles"));
        // Binary bytes in a comment or an ignored line do not matter when the faces are there.
        assert!(obj("# \u{0}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").is_ok());
    }

    #[test]
    fn quad_is_two_triangles() {
        let m = obj("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n").unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(m.normals.is_empty());
        assert!(m.materials.is_empty() && m.triangle_materials.is_empty());
        assert_eq!(m.positions[2], Vec3::new(1.0, 1.0, 0.0));
    }

    #[test]
    fn face_forms_and_negative_indices() {
        let src = "v 0 0 0 1\nv 1 0 0 1 0.5 0.5 0.5\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n\
                   vn 0 0 1\n\
                   f 1/1 2/2 3/3\nf -3//-1 -2//-1 -1//-1\nf 1/1/1 2/2/1 3/3/1\nf -3 -2 -1\n";
        let m = obj(src).unwrap();
        assert_eq!(m.positions.len(), 3);
        assert_eq!(m.triangles, vec![[0, 1, 2]; 4]);
        // Not every corner has a normal, so none are kept.
        assert!(m.normals.is_empty());
    }

    #[test]
    fn consistent_normals_are_kept() {
        let src = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nvn 0 0 1\n\
                   f 1//1 2//1 3//1\nf 2//2 4//2 3//2\n";
        let m = obj(src).unwrap();
        assert_eq!(m.normals, vec![Vec3::Z; 4]);

        // Position 2 used with two different normals: dropped.
        let src = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nvn 0 1 0\n\
                   f 1//1 2//1 3//1\nf 2//2 4//2 3//2\n";
        assert!(obj(src).unwrap().normals.is_empty());
    }

    #[test]
    fn separators_line_endings_comments_continuations() {
        let src = "# header\r\nv\t0  0 \t0 # trailing\r\nv 1 0 0\r\nv 0 1 \\\r\n 0\r\n\
                   \r\n   \r\nf 1 \\\n2 3\r\n";
        let m = obj(src).unwrap();
        assert_eq!(m.positions[2], Vec3::Y);
        assert_eq!(m.triangles, vec![[0, 1, 2]]);

        // Non-UTF-8 in a comment or an ignored line is fine.
        let mut bytes = b"# caf\xe9\no na\xefve\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 # \xff\n".to_vec();
        assert_eq!(parse(&bytes, Path::new("t.obj"), &no_mtl).unwrap().triangles.len(), 1);
        bytes.extend_from_slice(b"v 1 \xff 0\n");
        let e = err(&bytes);
        assert!(e.contains("bad.obj:line 7") && e.contains("UTF-8"), "{e}");
    }

    #[test]
    fn usemtl_groups_with_mtllib() {
        let src = "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n\
                   f 1 2 3\nusemtl red\nf 1 2 3\nf 2 4 3\nusemtl blue\nf 1 2 4\n\
                   usemtl red\nf 1 3 4\nusemtl unknown\nf 1 2 3\n";
        let mtl = |name: &str| {
            (name == "scene.mtl")
                .then(|| b"newmtl red\nKd 1 0 0\nKs 1 1 1\nillum 2\n\nnewmtl blue\nKd 0 0 0.5\nPm 0.25\n".to_vec())
        };
        let m = parse(src.as_bytes(), Path::new("t.obj"), &mtl).unwrap();
        assert_eq!(m.triangles.len(), 6);
        let names: Vec<_> = m.materials.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["red", "blue", "unknown", "default"]);
        assert_eq!(m.materials[0].diffuse, Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(m.materials[0].reflectivity, 0.0);
        assert_eq!(m.materials[1].diffuse, Vec3::new(0.0, 0.0, 0.5));
        assert_eq!(m.materials[1].reflectivity, 0.25);
        assert_eq!(m.materials[2].diffuse, Material::default().diffuse);
        assert_eq!(m.triangle_materials, vec![3, 0, 0, 1, 0, 2]);

        // Missing .mtl: materials named, default colours, no error.
        let m = obj(src).unwrap();
        assert_eq!(m.materials.len(), 4);
        assert_eq!(m.materials[1].name, "blue");
        assert_eq!(m.materials[1].diffuse, Material::default().diffuse);
    }

    #[test]
    fn malformed_inputs_name_the_line() {
        let cases: [(&[u8], &str); 11] = [
            (b"v 0 0 0\nv 1 x 0\n", "line 2"),
            (b"v 0 0\n", "line 1"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2\n", "line 5"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "line 4"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "line 4"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n", "line 4"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//1\n", "line 4"),
            (b"v 0 0 0\nv nan 0 0\n", "line 2"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 inf\n", "line 3"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", "line 4"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n", "line 4"),
        ];
        for (src, loc) in cases {
            let e = err(src);
            assert!(e.starts_with(&format!("bad.obj:{loc}:")), "{e} (wanted {loc})");
        }
        assert!(err(b"").contains("no triangles"));
        assert!(err(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n").contains("no triangles"));
        let garbage: Vec<u8> = (0..2000u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8).collect();
        let _ = parse(&garbage, Path::new("g.obj"), &no_mtl);
    }

    #[test]
    fn every_prefix_never_panics() {
        let src = b"mtllib m.mtl\nv 0 0 0\nv 1.5 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\n\
                    usemtl a\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf -4//-1 -3//-1 -2//-1\n";
        let mtl = |_: &str| Some(b"newmtl a\nKd 0.1 0.2 0.3\nPm 1\n".to_vec());
        for len in 0..=src.len() {
            let _ = parse(&src[..len], Path::new("p.obj"), &mtl);
        }
        assert_eq!(parse(src, Path::new("p.obj"), &mtl).unwrap().triangles.len(), 3);
    }
}
