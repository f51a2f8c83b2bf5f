//! WGSL sources: the shared file, one per kernel and one per structure's walk (`walks/`, named
//! by `gpu::walks`). WGSL has no includes, so a kernel's module is the generated constant
//! prelude, then `common.wgsl`, then (for the walking kernels, traverse, occlusion and closest
//! point) `closest_tri.wgsl` (the nearest point of a triangle, which every walk's closest-point
//! search uses) and the scene's walk file with three generated lines naming its entry points
//! `walk_closest`, `walk_any` and `walk_closest_point`, then the kernel's own file.

use super::walks::wgsl_prelude;

pub const COMMON: &str = include_str!("shaders/common.wgsl");
/// The queue appends of ray generation and shading (`appends=per_ray|workgroup`).
pub const APPEND: &str = include_str!("shaders/append.wgsl");
/// The same with subgroup operations (`appends=subgroup`), swapped in by `module_source_for`.
pub const APPEND_SUBGROUP: &str = include_str!("shaders/append_subgroup.wgsl");
/// Ray generation and shading append to queues: their modules carry `append.wgsl`.
pub const RAYGEN: &str = concat!(include_str!("shaders/append.wgsl"), include_str!("shaders/raygen.wgsl"));
pub const TRAVERSE: &str = include_str!("shaders/traverse.wgsl");
pub const OCCLUSION: &str = include_str!("shaders/occlusion.wgsl");
pub const CLOSEST_POINT: &str = include_str!("shaders/closest_point.wgsl");
/// The nearest point of a triangle (Ericson), the tie rule and the ring searches' lattice
/// distances, in every walking kernel's module before the walk.
pub const CLOSEST_TRI: &str = include_str!("shaders/closest_tri.wgsl");
pub const SHADE: &str = concat!(include_str!("shaders/append.wgsl"), include_str!("shaders/shade.wgsl"));
pub const RESOLVE: &str = include_str!("shaders/resolve.wgsl");
pub const INDIRECT: &str = include_str!("shaders/indirect.wgsl");
pub const PACK: &str = include_str!("shaders/pack.wgsl");
/// A ray batch's rays in from the wire and its answers out (two pipelines of one file).
pub const BATCH: &str = include_str!("shaders/batch.wgsl");
/// Every hit of a ray batch's rays: counts, or lists (two pipelines of one file; `all_hits.rs`).
pub const ALL_HITS: &str = include_str!("shaders/all_hits.wgsl");
/// The running sum of a chunk's hit counts, where each ray's list ends.
pub const PREFIX_SUM: &str = include_str!("shaders/prefix_sum.wgsl");
/// Generalised winding numbers over the fast winding tree (`winding.rs`).
pub const WINDING: &str = include_str!("shaders/winding.wgsl");
/// Every kernel with its name.
pub const KERNELS: [(&str, &str); 12] = [
    ("raygen", RAYGEN),
    ("traverse", TRAVERSE),
    ("occlusion", OCCLUSION),
    ("closest point", CLOSEST_POINT),
    ("shade", SHADE),
    ("resolve", RESOLVE),
    ("indirect", INDIRECT),
    ("pack", PACK),
    ("batch", BATCH),
    ("all hits", ALL_HITS),
    ("prefix sum", PREFIX_SUM),
    ("winding", WINDING),
];

/// The prelude and `common.wgsl`: every declaration all kernels share.
pub fn shared_source() -> String {
    format!("{}\n{}", wgsl_prelude(), COMMON)
}

/// The directive a walk that traces by ray query (`WalkSpec::tlas`) needs: WGSL wants it
/// before every declaration, so it starts the module.
pub const RAY_QUERY_ENABLE: &str = "enable wgpu_ray_query;\n";

/// The whole module of a kernel that walks no structure, as the device compiles it.
pub fn module_source(kernel: &str) -> String {
    format!("{}\n{}", shared_source(), kernel)
}

/// The whole module of a kernel that walks no structure, for `variants`: with
/// `appends=subgroup` a kernel that appends gets `append_subgroup.wgsl` in place of
/// `append.wgsl`. (No `enable subgroups;`: naga 30 rejects the directive and offers the
/// subgroup built-ins to devices opened with the `SUBGROUP` feature.)
pub fn module_source_for(kernel: &str, variants: &super::variants::GpuVariants) -> String {
    match kernel.strip_prefix(APPEND) {
        Some(body) if variants.appends == super::variants::Appends::Subgroup => {
            format!("{}\n{APPEND_SUBGROUP}{body}", shared_source())
        }
        _ => module_source(kernel),
    }
}

/// The whole module of a walking kernel (traverse, occlusion, closest point) with the walk
/// `walk` names.
pub fn walk_module_source(kernel: &str, walk: &super::walks::WalkSpec) -> String {
    format!(
        "{}{}\n{}\n{}\n{}\n{}",
        if walk.tlas.is_some() { RAY_QUERY_ENABLE } else { "" },
        shared_source(),
        CLOSEST_TRI,
        walk.wgsl.join("\n"),
        walk.entry_points(),
        kernel
    )
}

/// Whether kernel `name` walks the scene's structure (its module includes a walk file).
pub fn walks(name: &str) -> bool {
    matches!(name, "traverse" | "occlusion" | "closest point" | "all hits")
}

/// Every module the tracer compiles, named `kernel` or `kernel [walk]`, with its source: the
/// walking kernels once per walk, the others once.
pub fn all_modules() -> Vec<(String, String)> {
    let mut out = Vec::new();
    for (name, src) in KERNELS {
        if walks(name) {
            // The closest-point kernel only with a walk that searches points.
            for w in super::walks::WALKS
                .iter()
                .filter(|w| w.points() || name != "closest point")
            {
                out.push((format!("{name} [{}]", w.name), walk_module_source(src, w)));
            }
        } else {
            out.push((name.to_string(), module_source(src)));
        }
    }
    out
}
