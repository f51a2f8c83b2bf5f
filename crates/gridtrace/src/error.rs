//! One error type for the library. Every error about input names the file and the place in it
//! (line or byte offset), because "invalid mesh" with no location is useless on a 100 MB file.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in an input file a problem was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line number in a text file.
    Line(usize),
    /// 0-based byte offset in a binary file (or a text file where lines mean nothing).
    Byte(u64),
    /// The file as a whole (empty file, missing section, ...).
    Whole,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(l) => write!(f, "line {l}"),
            Location::Byte(b) => write!(f, "byte {b}"),
            Location::Whole => Ok(()),
        }
    }
}

#[derive(Debug)]
pub enum Error {
    /// A file could not be read at all.
    Io { path: PathBuf, source: std::io::Error },
    /// A file was read but its content is wrong.
    Parse {
        path: PathBuf,
        location: Location,
        message: String,
    },
    /// The scene as a whole is unusable (no triangles left, NaN camera, ...).
    Scene(String),
    /// A caller passed bad arguments (bad ray data, bad grid dims, ...).
    InvalidInput(String),
    /// The GPU backend failed (no adapter, a scene over the device's limits, device lost, ...).
    Gpu(String),
    /// One query asked more of the device than one of its limits allows (a ray with more hits
    /// than one list pass holds). Not a fault: the device works and the next query may fit,
    /// so under `auto` the CPU answers this query alone and the scene stays on the GPU.
    Limit {
        /// The limit met, as wgpu's `Limits` names it (`max_storage_buffer_binding_size`).
        limit: &'static str,
        /// What asked for more, in the units of `asked` and `allowed` ("ray 3's hits in one
        /// list pass").
        what: String,
        /// How much it asked.
        asked: u64,
        /// How much the limit allows on this device.
        allowed: u64,
    },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub fn parse(path: &Path, location: Location, message: impl Into<String>) -> Self {
        Error::Parse {
            path: path.to_path_buf(),
            location,
            message: message.into(),
        }
    }
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io { path, source } => write!(f, "{}: {source}", path.display()),
            Error::Parse {
                path,
                location: Location::Whole,
                message,
            } => {
                write!(f, "{}: {message}", path.display())
            }
            Error::Parse {
                path,
                location,
                message,
            } => {
                write!(f, "{}:{location}: {message}", path.display())
            }
            Error::Scene(m) => write!(f, "scene: {m}"),
            Error::InvalidInput(m) => write!(f, "invalid input: {m}"),
            Error::Gpu(m) => write!(f, "gpu: {m}"),
            Error::Limit {
                limit,
                what,
                asked,
                allowed,
            } => write!(
                f,
                "gpu: {what}: {asked} asked, {allowed} allowed on this device (limit {limit})"
            ),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}
