//! gridtrace: a ray tracer for triangle meshes built around the uniform grid with proximity
//! clouds (K. Ralovich, "Implementing and Analyzing a GPU Ray Tracer"), on the CPU and on any GPU.

pub mod error;
pub mod io;
pub mod scene;

pub use error::{Error, Location, Result};
pub use scene::{Material, Mesh};
