//! The multithreaded CPU path: renders and ray batches over rayon.

mod render;

pub use render::{
    RayKind, RayObserver, Surface, render, render_view, render_with_counters, surface_at, trace_pixel_observed,
};
