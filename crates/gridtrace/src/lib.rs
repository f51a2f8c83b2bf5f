//! gridtrace: a ray tracer for triangle meshes built around the uniform grid with proximity
//! clouds (K. Ralovich, "Implementing and Analyzing a GPU Ray Tracer"), on the CPU and on any GPU.

pub mod accel;
pub mod bench;
pub mod cpu;
pub mod error;
pub mod gpu;
pub mod io;
pub mod query;
pub mod render;
pub mod scene;
pub mod testing;
pub mod util;

pub use accel::{AccelKind, GridAccel, Hit, Ray, Resolution};
pub use error::{Error, Location, Result};
pub use render::{Image, Mode, RenderOptions, RenderStats};
pub use scene::{Material, Mesh, PreparedScene, Scene};
