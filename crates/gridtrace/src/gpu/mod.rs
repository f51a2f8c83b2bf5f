//! The GPU backend: the paper's streaming ray tracer (its Figure 1) as wgpu compute kernels.
//!
//! Every structure runs here: the grid and the proximity cloud (one DDA, `pass_.accel` says
//! whether it jumps), the BVH, the irregular grid and brute force (each its own pipelines of `traverse` and
//! `occlusion`, compiled per structure with its walk: `walks/`).
//!
//! Per image tile: `raygen` fills ray queue A with eye rays (rays that miss the scene are finished
//! at once); then per bounce `traverse` finds closest hits, `shade` writes colour and emits
//! shadow rays and reflection rays into compacted queues (atomic counters), `occlusion` runs the
//! shadow queue (any hit), and `resolve` adds the unoccluded contributions. Every dispatch after
//! ray generation is indirect, sized on the GPU by `indirect` from the queue lengths, so
//! finished rays cost nothing later: today's form of the paper's ray masks and early-Z.
//!
//! One concept per file, as pbrt-v4's `wavefront/`:
//! - `context`: adapter and device (one per process is enough; renderers share it by `Arc`);
//! - `kernels`: shader modules, layouts and pipelines, built once per device, and the one helper
//!   that records a kernel's pass;
//! - `bindings`: the bind group tables; `layout`: the structs the kernels share with the host;
//!   `constants`: the numbers they share, printed into every module as a WGSL prelude;
//! - `walks`: each structure's GPU side, a folder each (its arrays, lattice, constants, node
//!   layouts, walk file, and the grid's device build, `walks/grid/build/`);
//!   `scene`: the scene's upload (the BVH's two GPU layouts, each with a CPU mirror of its
//!   walk, are in `walks/bvh/`);
//!   `renderer`: `GpuRenderer` and its work buffers;
//! - `upload`: the ray batches' mapped upload buffer;
//! - `wavefront`: the frame, submitted and read back later so that frames can be in flight
//!   (its pixels to the host, or left in a `device_image` that the viewer presents from);
//!   `tiles`: a run of its tiles in one submission, recorded, submitted and read out; `queries`: ray-batch intersect and occluded; `points`:
//!   closest-point batches (each structure's `NAME_closest_point` search);
//! - `timing`: timestamp queries and per-stage milliseconds; `host_phases`: the host's side of
//!   the wall time;
//! - `variants`: the GPU choices switchable at run time (`--gpu-variant`), equal in results.

mod all_hits;
mod batch_buffers;
mod batch_grow;
pub mod bindings;
pub mod constants;
mod context;
mod device_image;
mod host_phases;
mod kernels;
pub mod layout;
mod points;
mod queries;
mod renderer;
mod scan;
mod scene;
pub mod shaders;
mod tiles;
mod timing;
mod upload;
pub mod variants;
pub mod walks;
mod wavefront;
mod winding;
mod wire;
mod work;

pub use all_hits::{AllHits, LIST_PASS_LIMIT};
pub use context::check_scene_fits;
pub use context::{Fault, GpuContext};
pub use device_image::DeviceImage;
pub use points::GpuClosestPoints;
pub use queries::{
    Answer, ChunkAnswers, PIPELINE_ITEMS, RaySlice, SensorLayout, TriHit, WireSource, gpu_hit, unpack_bits,
};
pub use renderer::{GpuRenderer, GpuUpdateStats, MAX_TILE_PIXELS};
pub use scan::{PoseColumns, ScanRays};
pub use timing::{GpuQueryStats, GpuTimings, HostPhases, MAX_TIMESTAMPS_BYTES};
pub use variants::GpuVariants;
/// The binary BVH's GPU layout and its CPU mirror walk (`walks::bvh::binary`), by its old path.
pub use walks::bvh::binary as bvh;
pub use walks::grid::build::{GpuBuildStats, GpuGrid};
pub use wavefront::{FrameInFlight, GpuRenderStats, PrepareParts};
pub use winding::WIND_STACK_LIMIT;
