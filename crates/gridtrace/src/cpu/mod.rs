//! The multithreaded CPU path: renders and ray batches over rayon.

mod render;

pub(crate) use render::light_contribution;
pub use render::{Surface, intersect_batch, occluded_batch, render, render_with_counters, surface_at};
