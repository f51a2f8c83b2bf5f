//! Mesh loaders. Each format has its own module with a `parse` function over bytes, so tests
//! and fuzzers can feed them data without touching the file system.

use std::path::Path;

use crate::{Error, Location, Mesh, Result};

/// Loads a mesh, choosing the format from the file extension.
pub fn load_mesh(path: &Path) -> Result<Mesh> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    Err(Error::parse(
        path,
        Location::Whole,
        format!("unsupported mesh format '.{ext}'"),
    ))
}
