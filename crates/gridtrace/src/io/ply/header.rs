//! A PLY file's header: the format line and each element's properties with their types, read
//! up to `end_header`. Errors name the header line.

use std::path::Path;

use crate::{Error, Location, Result};

/// A property's scalar type, by its PLY names (`uchar` or `uint8`, ...).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Scalar {
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
    pub(super) fn from_name(name: &str) -> Option<Self> {
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

    pub(super) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    pub(super) fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Debug, Clone)]
pub(super) enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
pub(super) struct Property {
    pub(super) name: String,
    pub(super) kind: Kind,
}

#[derive(Debug, Clone)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: u64,
    pub(super) props: Vec<Property>,
}

impl Element {
    /// Smallest possible binary record (lists may be empty).
    pub(super) fn min_binary_size(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => s.size(),
                Kind::List { count, .. } => count.size(),
            })
            .sum()
    }

    pub(super) fn find(&self, name: &str) -> Option<usize> {
        self.props.iter().position(|p| p.name == name)
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

pub(super) struct Header {
    pub(super) format: Format,
    pub(super) elements: Vec<Element>,
    /// Byte offset of the first data byte.
    pub(super) data_start: usize,
    /// Number of lines in the header (the data's first line is `lines + 1`).
    pub(super) lines: usize,
}

/// Reads the header at the start of `data`, up to and including `end_header`.
pub(super) fn parse_header(data: &[u8], path: &Path) -> Result<Header> {
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
