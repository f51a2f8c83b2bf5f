//! Stanford PLY: `ascii`, `binary_little_endian` and `binary_big_endian`.
//!
//! The `vertex` element gives positions (`x`, `y`, `z`, any numeric type) and optionally normals
//! (`nx`, `ny`, `nz`); the `face` element gives polygons (`vertex_indices` or `vertex_index`, a
//! list of any integer type), fan-triangulated. Every other property and element is skipped by
//! its declared layout, in file order.
//!
//! Errors name a line for ASCII data and a byte offset for binary data. Header counts are never
//! trusted for allocation: preallocation is capped by what the remaining bytes could hold.

use std::path::Path;

use glam::Vec3;

use super::{capped_capacity, check_finite, finish};
use crate::{Error, Location, Mesh, Result};

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Debug, Clone)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

impl Element {
    /// Smallest possible binary record (lists may be empty).
    fn min_binary_size(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => s.size(),
                Kind::List { count, .. } => count.size(),
            })
            .sum()
    }

    fn find(&self, name: &str) -> Option<usize> {
        self.props.iter().position(|p| p.name == name)
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset of the first data byte.
    data_start: usize,
    /// Number of lines in the header (the data's first line is `lines + 1`).
    lines: usize,
}

fn parse_header(data: &[u8], path: &Path) -> Result<Header> {
    let err = |line: usize, msg: String| Error::parse(path, Location::Line(line), msg);
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        if pos >= data.len() {
            return Err(if line_no == 0 {
                Error::parse(path, Location::Whole, "empty file")
            } else {
                err(line_no, "header has no 'end_header'".into())
            });
        }
        line_no += 1;
        let end = data[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(data.len(), |i| pos + i);
        let raw = &data[pos..end];
        pos = (end + 1).min(data.len());
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        let text = String::from_utf8_lossy(raw);
        let mut t = text.split_ascii_whitespace();
        let keyword = t.next().unwrap_or("");
        if line_no == 1 {
            if keyword != "ply" {
                return Err(err(1, "not a PLY file (first line is not 'ply')".into()));
            }
            continue;
        }
        match keyword {
            "" | "comment" | "obj_info" => {}
            "format" => {
                format = Some(match t.next() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::BinaryLe,
                    Some("binary_big_endian") => Format::BinaryBe,
                    other => {
                        return Err(err(line_no, format!("unknown format {:?}", other.unwrap_or(""))));
                    }
                });
            }
            "element" => {
                let (Some(name), Some(count)) = (t.next(), t.next()) else {
                    return Err(err(line_no, "expected 'element <name> <count>'".into()));
                };
                let count = count
                    .parse::<u64>()
                    .map_err(|_| err(line_no, format!("invalid element count '{count}'")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            "property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(err(line_no, "property before any element".into()));
                };
                let ty = |name: Option<&str>| {
                    let name = name.unwrap_or("");
                    Scalar::from_name(name).ok_or_else(|| err(line_no, format!("unknown property type '{name}'")))
                };
                let first = t.next();
                let kind = if first == Some("list") {
                    let count = ty(t.next())?;
                    if !count.is_integer() {
                        return Err(err(line_no, "list count type must be an integer".into()));
                    }
                    Kind::List {
                        count,
                        item: ty(t.next())?,
                    }
                } else {
                    Kind::Scalar(ty(first)?)
                };
                let Some(name) = t.next() else {
                    return Err(err(line_no, "property without a name".into()));
                };
                element.props.push(Property {
                    name: name.to_string(),
                    kind,
                });
            }
            "end_header" => break,
            other => return Err(err(line_no, format!("unexpected header keyword '{other}'"))),
        }
    }
    let Some(format) = format else {
        return Err(Error::parse(path, Location::Whole, "header has no 'format' line"));
    };
    Ok(Header {
        format,
        elements,
        data_start: pos,
        lines: line_no,
    })
}

/// Where the parser is in the data, to read values and to name places in errors.
trait Reader {
    /// Place of the last value read (or of the read that failed), for errors.
    fn location(&self) -> Location;
    /// Place of the next value, for errors about what is read next.
    fn next_location(&mut self) -> Location;
    /// Reads one scalar as f64 (every PLY type fits exactly).
    fn read(&mut self, ty: Scalar) -> std::result::Result<f64, String>;
    /// Skips `n` values of type `ty`.
    fn skip(&mut self, ty: Scalar, n: u64) -> std::result::Result<(), String>;
    fn remaining(&self) -> usize;
}

struct Binary<'a> {
    data: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl Reader for Binary<'_> {
    fn location(&self) -> Location {
        Location::Byte(self.pos as u64)
    }

    fn next_location(&mut self) -> Location {
        Location::Byte(self.pos as u64)
    }

    fn read(&mut self, ty: Scalar) -> std::result::Result<f64, String> {
        let size = ty.size();
        let bytes = self
            .pos
            .checked_add(size)
            .and_then(|end| self.data.get(self.pos..end))
            .ok_or("unexpected end of data")?;
        let mut b = [0u8; 8];
        b[..size].copy_from_slice(bytes);
        if self.big_endian {
            b[..size].reverse();
        }
        self.pos += size;
        let le2 = [b[0], b[1]];
        let le4 = [b[0], b[1], b[2], b[3]];
        Ok(match ty {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => i16::from_le_bytes(le2) as f64,
            Scalar::U16 => u16::from_le_bytes(le2) as f64,
            Scalar::I32 => i32::from_le_bytes(le4) as f64,
            Scalar::U32 => u32::from_le_bytes(le4) as f64,
            Scalar::F32 => f32::from_le_bytes(le4) as f64,
            Scalar::F64 => f64::from_le_bytes(b),
        })
    }

    fn skip(&mut self, ty: Scalar, n: u64) -> std::result::Result<(), String> {
        let end = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(ty.size()))
            .and_then(|len| self.pos.checked_add(len))
            .filter(|&end| end <= self.data.len())
            .ok_or("unexpected end of data")?;
        self.pos = end;
        Ok(())
    }

    fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }
}

struct Ascii<'a> {
    data: &'a [u8],
    pos: usize,
    /// Line of the byte at `pos`.
    line: usize,
    /// Line of the last token read.
    token_line: usize,
}

impl<'a> Ascii<'a> {
    fn skip_whitespace(&mut self) {
        while let Some(&b) = self.data.get(self.pos) {
            if b == b'\n' {
                self.line += 1;
            } else if !b.is_ascii_whitespace() {
                break;
            }
            self.pos += 1;
        }
    }

    /// The next whitespace-separated token. At the end of the data, `token_line` stays on the
    /// last line that held a token, which is where a reader would look for the missing value.
    fn token(&mut self) -> std::result::Result<&'a [u8], String> {
        self.skip_whitespace();
        let start = self.pos;
        while self.data.get(self.pos).is_some_and(|b| !b.is_ascii_whitespace()) {
            self.pos += 1;
        }
        if start == self.pos {
            return Err("unexpected end of data".into());
        }
        self.token_line = self.line;
        Ok(&self.data[start..self.pos])
    }
}

impl Reader for Ascii<'_> {
    fn location(&self) -> Location {
        Location::Line(self.token_line)
    }

    fn next_location(&mut self) -> Location {
        self.skip_whitespace();
        if self.pos < self.data.len() {
            Location::Line(self.line)
        } else {
            Location::Line(self.token_line)
        }
    }

    fn read(&mut self, ty: Scalar) -> std::result::Result<f64, String> {
        let t = self.token()?;
        let s = std::str::from_utf8(t).map_err(|_| "invalid UTF-8 in data".to_string())?;
        let bad = || format!("invalid {ty:?} value '{s}'");
        if ty.is_integer() {
            s.parse::<i64>().map(|v| v as f64).map_err(|_| bad())
        } else {
            s.parse::<f64>().map_err(|_| bad())
        }
    }

    fn skip(&mut self, ty: Scalar, n: u64) -> std::result::Result<(), String> {
        for _ in 0..n {
            self.read(ty)?;
        }
        Ok(())
    }

    fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }
}

/// Parses PLY bytes.
pub fn parse(data: &[u8], path: &Path) -> Result<Mesh> {
    let header = parse_header(data, path)?;
    let body = &data[header.data_start..];
    match header.format {
        Format::Ascii => {
            let line = header.lines + 1;
            let mut r = Ascii {
                data: body,
                pos: 0,
                line,
                token_line: line,
            };
            read_body(&header, &mut r, path)
        }
        Format::BinaryLe | Format::BinaryBe => {
            let mut r = Binary {
                data,
                pos: header.data_start,
                big_endian: header.format == Format::BinaryBe,
            };
            read_body(&header, &mut r, path)
        }
    }
}

fn read_body(header: &Header, r: &mut dyn Reader, path: &Path) -> Result<Mesh> {
    let Some(vertex) = header.elements.iter().find(|e| e.name == "vertex") else {
        return Err(Error::parse(path, Location::Whole, "no 'vertex' element"));
    };
    let vertex_count = vertex.count;
    if vertex_count > u64::from(u32::MAX) {
        return Err(Error::parse(
            path,
            Location::Whole,
            format!("{vertex_count} vertices is more than 32-bit indices can address"),
        ));
    }
    let [Some(x), Some(y), Some(z)] = ["x", "y", "z"].map(|n| vertex.find(n)) else {
        return Err(Error::parse(path, Location::Whole, "vertex element lacks x, y or z"));
    };
    let normal_props = match ["nx", "ny", "nz"].map(|n| vertex.find(n)) {
        [Some(nx), Some(ny), Some(nz)] => Some([nx, ny, nz]),
        _ => None,
    };
    let face = header.elements.iter().find(|e| e.name == "face");
    let face_list = match face {
        None => None,
        Some(face) => {
            let Some(list) = face.find("vertex_indices").or_else(|| face.find("vertex_index")) else {
                return Err(Error::parse(
                    path,
                    Location::Whole,
                    "face element has no vertex_indices",
                ));
            };
            match face.props[list].kind {
                Kind::List { item, .. } if item.is_integer() => Some(list),
                _ => {
                    return Err(Error::parse(
                        path,
                        Location::Whole,
                        "vertex_indices must be a list of integers",
                    ));
                }
            }
        }
    };

    let mut mesh = Mesh::default();
    let mut values = vec![0.0f64; vertex.props.len()];
    let mut indices: Vec<u32> = Vec::new();
    for element in &header.elements {
        if element.props.is_empty() {
            continue; // nothing stored per record, whatever the count
        }
        let is_vertex = std::ptr::eq(element, vertex);
        let is_face = face.is_some_and(|f| std::ptr::eq(element, f));
        // Smallest valid record; a face holds at least 3 indices.
        // `face_list` indexes the face element's properties: only look it up on that element
        // (fuzzing found the out-of-bounds index on a vertex element with fewer properties).
        let face_item = match face_list
            .filter(|_| is_face)
            .and_then(|k| element.props.get(k))
            .map(|p| &p.kind)
        {
            Some(Kind::List { item, .. }) => Some(*item),
            _ => None,
        };
        let min_size = match header.format {
            // A digit and a separator per value.
            Format::Ascii => 2 * (element.props.len() + if face_item.is_some() { 3 } else { 0 }),
            _ => element.min_binary_size() + face_item.map_or(0, |item| 3 * item.size()),
        };
        let capacity = capped_capacity(element.count, r.remaining(), min_size);
        if is_vertex {
            mesh.positions.reserve_exact(capacity);
            if normal_props.is_some() {
                mesh.normals.reserve_exact(capacity);
            }
        } else if is_face {
            mesh.triangles.reserve_exact(capacity);
        }
        for done in 0..element.count {
            let start = r.next_location();
            let fail = |r: &dyn Reader, m: String| {
                let m = if m.starts_with("unexpected end") {
                    format!(
                        "unexpected end of data: element '{}' declares {} records, found {done}",
                        element.name, element.count
                    )
                } else {
                    m
                };
                Error::parse(path, r.location(), m)
            };
            for (k, p) in element.props.iter().enumerate() {
                match p.kind {
                    Kind::Scalar(s) if is_vertex => values[k] = r.read(s).map_err(|m| fail(r, m))?,
                    Kind::Scalar(s) => r.skip(s, 1).map_err(|m| fail(r, m))?,
                    Kind::List { count, item } if is_face && Some(k) == face_list => {
                        let at = r.next_location();
                        let n = read_count(r, count).map_err(|m| fail(r, m))?;
                        if n < 3 {
                            return Err(Error::parse(
                                path,
                                at,
                                format!("face with {n} vertices (need at least 3)"),
                            ));
                        }
                        indices.clear();
                        for _ in 0..n {
                            let at = r.next_location();
                            let v = r.read(item).map_err(|m| fail(r, m))?;
                            if v < 0.0 || v >= vertex_count as f64 {
                                return Err(Error::parse(
                                    path,
                                    at,
                                    format!("vertex index {v} out of range ({vertex_count} vertices)"),
                                ));
                            }
                            indices.push(v as u32);
                        }
                        for j in 1..indices.len() - 1 {
                            mesh.triangles.push([indices[0], indices[j], indices[j + 1]]);
                        }
                    }
                    Kind::List { count, item } => read_count(r, count)
                        .and_then(|n| r.skip(item, n))
                        .map_err(|m| fail(r, m))?,
                }
            }
            if is_vertex {
                let at = |i: usize| values[i] as f32;
                let pos = Vec3::new(at(x), at(y), at(z));
                check_finite(path, start, "vertex position", pos)?;
                mesh.positions.push(pos);
                if let Some([nx, ny, nz]) = normal_props {
                    mesh.normals.push(Vec3::new(at(nx), at(ny), at(nz)));
                }
            }
        }
    }
    finish(mesh, path)
}

fn read_count(r: &mut dyn Reader, ty: Scalar) -> std::result::Result<u64, String> {
    let n = r.read(ty)?;
    if n < 0.0 {
        return Err(format!("negative list length {n}"));
    }
    Ok(n as u64)
}

#[cfg(test)]
mod tests {
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
}
