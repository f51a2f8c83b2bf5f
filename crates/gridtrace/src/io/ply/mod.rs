//! Stanford PLY: `ascii`, `binary_little_endian` and `binary_big_endian`.
//!
//! The `vertex` element gives positions (`x`, `y`, `z`, any numeric type) and optionally normals
//! (`nx`, `ny`, `nz`); the `face` element gives polygons (`vertex_indices` or `vertex_index`, a
//! list of any integer type), fan-triangulated. Every other property and element is skipped by
//! its declared layout, in file order.
//!
//! Errors name a line for ASCII data and a byte offset for binary data. Header counts are never
//! trusted for allocation: preallocation is capped by what the remaining bytes could hold.
//!
//! `header` reads the header; `ascii` and `binary` are the two readers of the data behind
//! `Reader`; this file reads the records into a mesh (`read_body`), the same for both.

mod ascii;
mod binary;
mod header;
#[cfg(test)]
mod tests;

use std::path::Path;

use glam::Vec3;

use super::{capped_capacity, check_finite, finish};
use crate::{Error, Location, Mesh, Result};
use ascii::Ascii;
use binary::Binary;
use header::{Format, Header, Kind, Scalar, parse_header};

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

/// Parses PLY bytes.
pub fn parse(data: &[u8], path: &Path) -> Result<Mesh> {
    let header = parse_header(data, path)?;
    let body = &data[header.data_start..];
    match header.format {
        Format::Ascii => read_body(&header, &mut Ascii::new(body, header.lines + 1), path),
        Format::BinaryLe | Format::BinaryBe => {
            let big_endian = header.format == Format::BinaryBe;
            read_body(&header, &mut Binary::new(data, header.data_start, big_endian), path)
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
