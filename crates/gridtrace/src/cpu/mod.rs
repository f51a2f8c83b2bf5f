//! The multithreaded CPU path: renders and ray batches over rayon.

mod blocks;
mod path;
mod render;

pub use path::{RayKind, Surface, surface_at};
pub use render::{RayObserver, render, render_view, render_with_counters, trace_pixel_observed};
