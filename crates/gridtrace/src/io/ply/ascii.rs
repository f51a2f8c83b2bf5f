//! The ASCII PLY reader: whitespace-separated tokens, errors naming the line.

use super::Reader;
use super::header::Scalar;
use crate::Location;

pub(super) struct Ascii<'a> {
    data: &'a [u8],
    pos: usize,
    /// Line of the byte at `pos`.
    line: usize,
    /// Line of the last token read.
    token_line: usize,
}

impl<'a> Ascii<'a> {
    /// A reader of `body` (the data after the header), whose first line is the file's line
    /// `first_line`.
    pub(super) fn new(body: &'a [u8], first_line: usize) -> Ascii<'a> {
        Ascii {
            data: body,
            pos: 0,
            line: first_line,
            token_line: first_line,
        }
    }

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
