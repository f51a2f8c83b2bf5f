// Shared declarations and functions of all gridtrace kernels. Every kernel's module is the
// generated constant prelude, this file, then the kernel's own file (WGSL has no includes); the
// walking kernels (traverse, occlusion) get the scene's structure's walk file between them.
//
// The structs below mirror #[repr(C)] Rust structs in src/gpu/layout.rs (and accel/scene); a
// test (tests/gpu_layout.rs) parses this file with naga and checks every size and offset.
// Storage structs use array<f32, 3> (4-byte aligned) rather than vec3<f32> (16-byte aligned)
// so that they match the packed Rust layouts.

// `layout::GpuTri`: `TriAccel`'s vertex and edges in 16-byte groups (one load each).
struct GpuTri { v0: vec3<f32>, _pad0: u32, v1: vec3<f32>, _pad1: u32, v2: vec3<f32>, _pad2: u32 }
struct TriShade { n0: array<f32, 3>, n1: array<f32, 3>, n2: array<f32, 3>, material: u32 }
struct GpuMaterial { diffuse: vec3<f32>, reflectivity: f32 }
struct PointLight { position: vec3<f32>, _pad0: f32, intensity: vec3<f32>, _pad1: f32 }
// A queued ray: eye, reflection or shadow. `pixel` indexes the tile's accumulation buffer;
// `weight` is the path throughput (shadow rays: the contribution if unoccluded). Three 16-byte
// groups, each a vec3 and a scalar in its fourth word: the host's bytes (`layout::RayRec`), with
// the alignment that lets a GPU load each group in one 16-byte access (an array<f32, 3> is
// 4-byte aligned and is read as three scalars).
struct RayRec { origin: vec3<f32>, pixel: u32, dir: vec3<f32>, t_max: f32, weight: vec3<f32>, t_min: f32 }
struct GpuHit { t: f32, tri: u32, u: f32, v: f32 }
// A ray batch's constants (batch.wgsl; BatchUniform on the host).
struct BatchUniform { stride: u32, to_shadow: u32, t_min: f32, t_max: f32, mask: u32, range_only: u32, first: u32, cells: u32, cols: u32, poses_at: u32, pose_cols: u32, _pad0: u32 }

struct SceneUniform {
    bounds_min: vec3<f32>, ray_epsilon: f32,
    bounds_max: vec3<f32>, n_lights: u32,
    cell_size: vec3<f32>, n_tris: u32,
    inv_cell_size: vec3<f32>, _pad0: u32,
    dims: vec3<u32>, shift: u32,
    background: vec3<f32>, _pad2: u32,
    ambient: vec3<f32>, _pad3: u32,
}
struct CameraFrame {
    eye: vec3<f32>, width: u32,
    forward: vec3<f32>, height: u32,
    right_scaled: vec3<f32>, _pad0: u32,
    up_scaled: vec3<f32>, _pad1: u32,
}
struct PassUniform {
    depth: u32, in_slot: u32, out_slot: u32, tile_offset: u32,
    tile_pixels: u32, mode: u32, accel: u32, max_depth: u32,
    compact: u32, _pad0: u32, _pad1: u32, _pad2: u32,
}
// Arguments of the two indirect dispatches (x, y, z workgroups): the input ray queue's kernels
// and the shadow queue's. Written by the indirect kernel, read as INDIRECT arguments.
struct IndirectArgs { rays: array<u32, 3>, shadow: array<u32, 3> }

// Named constants (counter slots, modes, WORKGROUP, MISS, the triangle test's slack) are not
// declared here: the host prepends them, printed from src/gpu/constants.rs, to every module.

// Set per pipeline: the heat pipeline counts traversal work, the others compile it away.
override COUNT_WORK: bool = false;
// Set per pipeline: the occlusion kernel of the `shadow closest hit` ablation finds the closest
// hit of each shadow ray instead of stopping at the first (RenderOptions::ablation).
override SHADOW_CLOSEST: bool = false;
// GPU variants (gpu/variants/; every pipeline gets the same values, GpuVariants::overrides):
// ray generation in 8x8 squares (`order=tiles`), queue appends aggregated per workgroup
// (`appends=workgroup`), per-ray statistics atomics in shading (`stats=on`), and the entries of
// the BVH walk's short stack (`stack=short`, read by the short-stack walks only).
override TILE_ORDER: bool = false;
override WG_APPENDS: bool = false;
override RAY_STATS: bool = true;
override SHORT_STACK: u32 = 8u;

// The invocation's index in its workgroup, for walks that keep state in workgroup memory (the
// short stack); set by the walking kernels' entry points before they walk.
var<private> lane: u32;

// Every hit of a ray (all_hits.wgsl) is found one at a time: each the closest after the one
// found before it in the order of (t, triangle number), so that every hit comes once, ties at
// one t included, through each structure's own closest-hit walk rather than a second copy of
// every walk. Set per pipeline: the all-hits kernels compile the walks' leaf tests for it
// (`leaf_bound`, `leaf_takes`); every other pipeline folds the branch away.
override NEXT_HIT: bool = false;
// The hit found before (its t and number in the answers' numbering), none before the first.
var<private> after_none: bool = true;
var<private> after_t: f32;
var<private> after_key: u32;
// What the answers' numbering adds to a walk's own (mesh-local) triangle: a top level sets it
// to an instance record's first before the instance's walk; 0 for a walk of one level.
var<private> key_base: u32 = 0u;

// The next float above `t` toward +inf (the smallest normal above 0: a GPU may flush
// subnormals); inf stays inf.
fn next_up(t: f32) -> f32 {
    if (!(t < inf())) { return t; }
    if (t == 0.0) { return 1.17549435e-38; }
    let b = bitcast<u32>(t);
    return bitcast<f32>(select(b - 1u, b + 1u, t > 0.0));
}

// The bound a walk's leaf hands `intersect_tri` (`t < bound`) for the closest hit so far at
// `best_t`: with NEXT_HIT a hit at exactly `best_t` may still come first by its number.
fn leaf_bound(best_t: f32) -> f32 {
    if (NEXT_HIT) { return next_up(best_t); }
    return best_t;
}

// Whether a hit at `t` of the walk's triangle `tri` replaces `best` (a walk's closest so far;
// `first`: what the walk subtracts from its numbering for its answer). Without NEXT_HIT
// `intersect_tri` has decided already (t < best.t). With it: the hit must come after the one
// found before and before `best`, both in (t, number) order.
fn leaf_takes(t: f32, tri: u32, best: GpuHit, first: u32) -> bool {
    if (!NEXT_HIT) { return true; }
    let key = tri - first + key_base;
    if (!after_none && (t < after_t || (t == after_t && key <= after_key))) { return false; }
    return best.tri == MISS || t < best.t || (t == best.t && key < best.tri - first + key_base);
}

@group(0) @binding(0) var<uniform> scene: SceneUniform;
@group(0) @binding(1) var<uniform> camera: CameraFrame;
@group(0) @binding(2) var<uniform> pass_: PassUniform;
@group(0) @binding(5) var<storage, read> tris: array<GpuTri>;
@group(0) @binding(6) var<storage, read> tri_shade: array<TriShade>;
@group(0) @binding(7) var<storage, read> materials: array<GpuMaterial>;
@group(0) @binding(8) var<uniform> lights: array<PointLight, MAX_LIGHTS>;
@group(0) @binding(9) var<storage, read_write> rays_in: array<RayRec>;
@group(0) @binding(10) var<storage, read_write> rays_out: array<RayRec>;
@group(0) @binding(11) var<storage, read_write> hits: array<GpuHit>;
@group(0) @binding(12) var<storage, read_write> shadow_rays: array<RayRec>;
@group(0) @binding(13) var<storage, read_write> resolve: array<vec2<u32>>;
@group(0) @binding(14) var<storage, read_write> accum: array<vec4<f32>>;
@group(0) @binding(15) var<storage, read_write> counters: array<atomic<u32>, COUNTER_SLOTS>;
// The structure's own arrays are group 1 of the walking kernels (traverse, occlusion), declared
// in its walk file (walks/*.wgsl) with its `*_closest` and `*_any`; see gpu/walks/mod.rs.

// Queues. Compacted (the tracer's way): each kernel appends the rays it emits with an atomic
// counter, finished rays are never queued, and the next kernel runs over the queue's length.
// Without compaction (the `no_compaction` ablation, `pass_.compact` = 0): ray i of a bounce
// stays in slot i of every queue (its shadow rays in slots i * n_lights + l), a finished ray
// idles there marked `pixel = MISS`, and every kernel runs over the whole tile.
fn compacted() -> bool { return pass_.compact != 0u; }
fn queue_len(slot: u32) -> u32 {
    if (compacted()) { return atomicLoad(&counters[slot]); }
    return pass_.tile_pixels;
}
fn shadow_len() -> u32 {
    if (compacted()) { return atomicLoad(&counters[SLOT_SHADOW]); }
    return pass_.tile_pixels * scene.n_lights;
}

// A queued ray's mask: it sees an instance of a scene of two levels when `mask & the
// instance's mask != 0` (gpu/walks/two_level/top_level.wgsl). A batch ray carries it in its
// weight's y and z as two 16-bit halves, exact in f32 (batch.wgsl), since a batch ray's weight
// is only its occlusion flag (x); the tracer's own rays carry throughput there and walk one
// level, which drops the mask (`WalkSpec::entry_points`).
fn ray_mask(r: RayRec) -> u32 { return u32(r.weight.y) | (u32(r.weight.z) << 16u); }

// Where one mesh's structure lies in the arrays its walk reads: `first` and `count` are the
// structure's own (the BVH: its root node, `count` unused; brute force: its first triangle and
// how many). A scene of one mesh walks it with `first` 0; a scene of two levels keeps each
// instance's in its record (gpu/walks/two_level/).
struct MeshHeader { first: u32, count: u32 }

// 1 / d with zero components replaced by +-DIR_TINY first (BoxRay::new): the slabs never
// compute 0 * inf, and a box beside a parallel ray gets an entry beyond 1e20.
fn safe_inv_dir(d: vec3<f32>) -> vec3<f32> {
    let sign_bits = bitcast<vec3<u32>>(d) & vec3<u32>(0x80000000u);
    let tiny = bitcast<vec3<f32>>(sign_bits | vec3<u32>(bitcast<u32>(DIR_TINY)));
    return 1.0 / select(d, tiny, abs(d) < vec3<f32>(DIR_TINY));
}

fn v3(a: array<f32, 3>) -> vec3<f32> { return vec3<f32>(a[0], a[1], a[2]); }
fn a3(v: vec3<f32>) -> array<f32, 3> { return array<f32, 3>(v.x, v.y, v.z); }
// Through a `let`: WGSL evaluates a constant expression when the shader is created and must
// reject one whose value is not a finite f32, which Tint (Chrome's WebGPU) does; a `let` is a
// runtime value, so the bits become infinity on the GPU, as they do with naga.
fn inf() -> f32 { let bits = 0x7f800000u; return bitcast<f32>(bits); }

// Invocation index in a 2-D grid of 64-wide workgroups (dispatches may exceed 65535 groups in x).
fn flat_index(wg: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * WORKGROUP + lid;
}

// One edge function of the watertight test (see intersect_tri): twice the signed area of the
// sheared edge (a, b) with the ray's point (0, 0). WGSL has no f64 and lets the compiler fuse
// a product into the subtraction, which would make `a.x * b.y - a.y * b.x` round differently
// from its mirror `b.x * a.y - b.y * a.x` (the other triangle at a shared edge computes the
// mirror). So both orders are computed and subtracted: whatever the compiler fuses inside
// each, swapping a and b swaps the two operands of the last subtraction (which has no product
// left to fuse), and the result is exactly negated. That is what watertightness needs: the two
// triangles at a shared edge get exactly opposite values, and an exact 0 in both. A 0 is not
// refined as on the CPU (no f64): it counts as on the edge, so a ray whose products round
// together at an edge or vertex can hit there, never leak (the neighbours see the same 0).
fn edge_fn(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return (a.x * b.y - a.y * b.x) - (b.x * a.y - b.y * a.x);
}

// A vertex relative to the ray's origin, in the ray's frame: the axes permuted so that the
// direction's largest component is z (k), then sheared so that the ray is the point (0, 0).
fn shear_vertex(a: vec3<f32>, k: vec3<u32>, sx: f32, sy: f32) -> vec3<f32> {
    return vec3<f32>(a[k.x] - sx * a[k.z], a[k.y] - sy * a[k.z], a[k.z]);
}

// The watertight ray/triangle test (Woop, Benthin, Wald 2013), two-sided; mirrors
// TriAccel::intersect but for the exact zeros (edge_fn). Returns t, u, v in xyz and w = 1 for
// a hit with t_min <= t < t_max.
fn intersect_tri(tri: GpuTri, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> vec4<f32> {
    let ad = abs(d);
    var kz = 2u;
    if (ad.x > ad.y) {
        if (ad.x > ad.z) { kz = 0u; }
    } else if (ad.y > ad.z) {
        kz = 1u;
    }
    let k = vec3<u32>((kz + 1u) % 3u, (kz + 2u) % 3u, kz);
    let sz = 1.0 / d[kz];
    let sx = d[k.x] * sz;
    let sy = d[k.y] * sz;
    let p0 = shear_vertex(tri.v0 - o, k, sx, sy);
    let p1 = shear_vertex(tri.v1 - o, k, sx, sy);
    let p2 = shear_vertex(tri.v2 - o, k, sx, sy);
    // Twice the CPU's edge functions (edge_fn); the factor cancels in u, v and t.
    let e0 = edge_fn(p1, p2);
    let e1 = edge_fn(p2, p0);
    let e2 = edge_fn(p0, p1);
    if ((e0 < 0.0 || e1 < 0.0 || e2 < 0.0) && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0)) { return vec4<f32>(0.0); }
    let det = e0 + e1 + e2;
    if (det == 0.0) { return vec4<f32>(0.0); }
    let inv_det = 1.0 / det;
    // + 0.0: a hit at t = 0 as +0, never -0 (TriAccel::intersect).
    let t = (e0 * p0.z + e1 * p1.z + e2 * p2.z) * (sz * inv_det) + 0.0;
    if (!(t >= t_min && t < t_max)) { return vec4<f32>(0.0); }
    // Grazing rays (TriAccel::intersect): det / 2 = n . d / d[kz].
    let n = cross(tri.v1 - tri.v0, tri.v2 - tri.v0);
    let half = 0.5 * det * d[kz];
    if (half * half <= PARALLEL_COS2 * dot(n, n) * dot(d, d)) { return vec4<f32>(0.0); }
    return vec4<f32>(t, e1 * inv_det, e2 * inv_det, 1.0);
}

// A regular lattice over a box (the uniform grid's cells, the irregular grid's virtual voxels):
// the scene uniform's (`scene_lattice`), or, in a scene of two levels, one mesh's row of the
// grid's lattice table (gpu/walks/two_level/), where `first_cell` and `first_tri` say where the
// mesh's cells (the irregular grid's: its top cells' entries) and triangles start in the shared
// arrays, and `first_map` where its voxel maps do (the irregular grid's; 0 for the grid)
// (`LatticeRow` on the host).
struct Lattice {
    lo: vec3<f32>, first_cell: u32,
    hi: vec3<f32>, first_tri: u32,
    cell: vec3<f32>, shift: u32,
    inv_cell: vec3<f32>, first_map: u32,
    dims: vec3<u32>, _pad1: u32,
}

fn scene_lattice() -> Lattice {
    return Lattice(scene.bounds_min, 0u, scene.bounds_max, 0u, scene.cell_size, scene.shift,
                   scene.inv_cell_size, 0u, scene.dims, 0u);
}

// Ray/box slab clip against the lattice's box; mirrors Aabb::clip (axes with d == 0 handled
// apart: no 0 * inf). Returns (t_enter, t_exit, ok).
fn clip_lattice(l: Lattice, o: vec3<f32>, inv_d: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> vec3<f32> {
    var t_enter = t_min;
    var t_exit = t_max;
    for (var a = 0; a < 3; a++) {
        if (d[a] == 0.0 || abs(inv_d[a]) == inf()) {
            if (o[a] < l.lo[a] || o[a] > l.hi[a]) { return vec3<f32>(0.0, 0.0, 0.0); }
        } else {
            let t0 = (l.lo[a] - o[a]) * inv_d[a];
            let t1 = (l.hi[a] - o[a]) * inv_d[a];
            t_enter = max(t_enter, min(t0, t1));
            t_exit = min(t_exit, max(t0, t1));
        }
    }
    return vec3<f32>(t_enter, t_exit, select(0.0, 1.0, t_enter <= t_exit));
}

// `clip_lattice` against the scene's bounds.
fn clip_box(o: vec3<f32>, inv_d: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> vec3<f32> {
    return clip_lattice(scene_lattice(), o, inv_d, d, t_min, t_max);
}

// Lattice basics every grid walk shares (the uniform grid's DDA, the irregular grid's lookups):
// the cell of a point, and the axis of the smallest component (first on ties).
fn lattice_cell(l: Lattice, p: vec3<f32>) -> vec3<i32> {
    // Clamp before converting: f32 -> i32 of huge values is best kept away from.
    let g = clamp(floor((p - l.lo) * l.inv_cell), vec3<f32>(-2.0), vec3<f32>(l.dims) + 1.0);
    return vec3<i32>(g);
}

fn world_to_grid(p: vec3<f32>) -> vec3<i32> {
    return lattice_cell(scene_lattice(), p);
}

fn min_position(v: vec3<f32>) -> i32 {
    var m = v.x;
    var i = 0;
    if (v.y < m) { m = v.y; i = 1; }
    if (v.z < m) { i = 2; }
    return i;
}

fn min3(v: vec3<f32>) -> f32 { return min(v.x, min(v.y, v.z)); }
