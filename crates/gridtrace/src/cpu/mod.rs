//! The multithreaded CPU path: renders and ray batches over rayon.

mod render;

pub(crate) use render::light_contribution;
pub use render::{Surface, render, render_view, render_with_counters, surface_at};
