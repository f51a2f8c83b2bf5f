//! gridtrace: a ray tracer for triangle meshes built around the uniform grid with proximity
//! clouds (K. Ralovich, "Implementing and Analyzing a GPU Ray Tracer"), on the CPU and on any GPU.

pub mod accel;
pub mod backend;
pub mod build_info;
pub mod cpu;
pub mod error;
pub mod frames;
pub mod gpu;
pub mod io;
pub mod mesh;
pub mod placement;
pub mod query;
pub mod query_scene;
pub mod render;
pub mod scene;
pub mod sensor;
#[cfg(any(test, feature = "testing"))]
pub mod testing;
pub mod util;

pub use accel::{Accel, AccelChoice, AccelKind, AccelParams, AccelSpec, Hit, Ray, Resolution, TracedOn, Work};
pub use backend::{Backend, Frame, Rendered, Tracer};
pub use build_info::cpu_features;
pub use error::{Error, Location, Result};
pub use frames::{FramesOptions, FramesStats};
pub use mesh::{Material, Mesh};
pub use placement::{OpenedScene, Placement, open_scene};
pub use query_scene::QueryScene;
pub use render::{Image, Mode, PixelFormat, RenderOptions, RenderStats};
pub use scene::{PreparedScene, Scene};
