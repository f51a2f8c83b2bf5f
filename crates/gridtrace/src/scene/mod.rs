//! Scene description: meshes, materials, lights, camera.

pub mod mesh;

pub use mesh::{Material, Mesh};
