//! The binary PLY reader (`binary_little_endian`, `binary_big_endian`): values at byte
//! offsets, errors naming the byte.

use super::Reader;
use super::header::Scalar;
use crate::Location;

pub(super) struct Binary<'a> {
    data: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl<'a> Binary<'a> {
    /// A reader of `data` (the whole file, so that errors name bytes from its start) from byte
    /// `start`, the first after the header.
    pub(super) fn new(data: &'a [u8], start: usize, big_endian: bool) -> Binary<'a> {
        Binary {
            data,
            pos: start,
            big_endian,
        }
    }
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
