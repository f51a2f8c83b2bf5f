// Shared declarations of the GPU grid build's kernels (src/gpu/walks/grid/build/): its parameters,
// its bindings, and the cell assignment. Every build module is the constant prelude, this file,
// then the kernel's own file.
//
// The cell assignment mirrors `grid::overlap_pairs` and `tri_box::triangle_overlaps_box`
// operation for operation (the same products, summed in the same order, no `dot` or `cross`
// builtins whose order is unspecified): the GPU-built grid must reference exactly the cells the
// CPU-built one does, and a test compares the two cell by cell.

// `GridBuildUniform` in layout.rs: one per dispatch, at a 256-byte slot of the params buffer.
struct GridBuildUniform {
    bounds_min: vec3<f32>, n_tris: u32,
    cell_size: vec3<f32>, n_cells: u32,
    inv_cell_size: vec3<f32>, refs_capacity: u32,
    margin: vec3<f32>, axis: u32,
    dims: vec3<u32>, n: u32,
    in_offset: u32, out_offset: u32, last: u32, _pad0: u32,
}
struct Cell { start: u32, count: u32, dist: u32 }
// `layout::GpuTri`, as the tracer reads it.
struct GpuTri { v0: vec3<f32>, _pad0: u32, v1: vec3<f32>, _pad1: u32, v2: vec3<f32>, _pad2: u32 }

@group(0) @binding(0) var<uniform> P: GridBuildUniform;
@group(0) @binding(1) var<storage, read> tris: array<GpuTri>;

fn v3(a: array<f32, 3>) -> vec3<f32> {
    return vec3<f32>(a[0], a[1], a[2]);
}

// Invocation index in a 2-D grid of workgroups of `size` (dispatches may exceed 65535 groups).
fn flat_id(wg: vec3<u32>, nwg: vec3<u32>, lid: u32, size: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * size + lid;
}

fn max3(v: vec3<f32>) -> f32 {
    return max(v.x, max(v.y, v.z));
}

// `TriAccel::vertices`.
struct Verts { a: vec3<f32>, b: vec3<f32>, c: vec3<f32> }
fn tri_vertices(i: u32) -> Verts {
    let t = tris[i];
    return Verts(t.v0, t.v1, t.v2);
}

// The triangle's cell range (inclusive) and its grown margin, as `overlap_pairs` computes them.
struct CellRange { c0: vec3<u32>, c1: vec3<u32>, margin: vec3<f32> }
fn cell_range(v: Verts) -> CellRange {
    let lo = min(min(v.a, v.b), v.c);
    let hi = max(max(v.a, v.b), v.c);
    // `slack_pad` (accel/triangle.rs).
    let pad = SLACK_PAD * max3(hi - lo) + (4.0 * F32_EPSILON) * max3(max(abs(lo), abs(hi)));
    let margin = max(P.margin, vec3<f32>(pad));
    let top = vec3<f32>(P.dims - vec3<u32>(1u));
    // Rust's float-to-integer `as` saturates; clamping in floats first gives the same cells.
    let f0 = min(max(floor(((lo - margin) - P.bounds_min) * P.inv_cell_size), vec3<f32>(0.0)), top);
    let f1 = min(max(floor(((hi + margin) - P.bounds_min) * P.inv_cell_size), vec3<f32>(0.0)), top);
    return CellRange(vec3<u32>(f0), vec3<u32>(f1), margin);
}

fn dot_ordered(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

fn radius(half: vec3<f32>, axis: vec3<f32>) -> f32 {
    return half.x * abs(axis.x) + half.y * abs(axis.y) + half.z * abs(axis.z);
}

// Whether the axis separates the triangle (vertices relative to the box centre) from the box.
fn separates(axis: vec3<f32>, v0: vec3<f32>, v1: vec3<f32>, v2: vec3<f32>, half: vec3<f32>) -> bool {
    let p0 = dot_ordered(axis, v0);
    let p1 = dot_ordered(axis, v1);
    let p2 = dot_ordered(axis, v2);
    let r = radius(half, axis);
    return min(min(p0, p1), p2) > r || max(max(p0, p1), p2) < -r;
}

// The three axes `edge x box axis` of one edge.
fn edge_separates(e: vec3<f32>, v0: vec3<f32>, v1: vec3<f32>, v2: vec3<f32>, half: vec3<f32>) -> bool {
    return separates(vec3<f32>(0.0, -e.z, e.y), v0, v1, v2, half)
        || separates(vec3<f32>(e.z, 0.0, -e.x), v0, v1, v2, half)
        || separates(vec3<f32>(-e.y, e.x, 0.0), v0, v1, v2, half);
}

// `triangle_overlaps_box` (separating axes, Akenine-Möller 2001).
fn overlaps_box(center: vec3<f32>, half: vec3<f32>, v: Verts) -> bool {
    let v0 = v.a - center;
    let v1 = v.b - center;
    let v2 = v.c - center;
    let e0 = v1 - v0;
    let e1 = v2 - v1;
    // Written out, not looped over the edges: lavapipe bounds every invocation's loop
    // iterations in total (see `MAX_CELLS_PER_TRI`), and this runs per cell.
    if edge_separates(e0, v0, v1, v2, half) || edge_separates(e1, v0, v1, v2, half)
        || edge_separates(v0 - v2, v0, v1, v2, half) {
        return false;
    }
    let tmin = min(min(v0, v1), v2);
    let tmax = max(max(v0, v1), v2);
    if any(tmin > half) || any(tmax < -half) {
        return false;
    }
    // glam's cross: (y*z' - y'*z, z*x' - z'*x, x*y' - x'*y).
    let n = vec3<f32>(e0.y * e1.z - e1.y * e0.z, e0.z * e1.x - e1.z * e0.x, e0.x * e1.y - e1.x * e0.y);
    let d = dot_ordered(n, v0);
    return abs(d) <= radius(half, n);
}

// Whether cell `c` of the range takes the triangle: every cell of a range one cell thick on
// at least two axes does (as in `overlap_pairs_by_triangle`, which says why), else the exact
// test on the cell box grown by the margin.
fn takes(c: vec3<u32>, r: CellRange, v: Verts) -> bool {
    let spans = vec3<u32>(r.c1 > r.c0);
    if spans.x + spans.y + spans.z <= 1u {
        return true;
    }
    let box_min = P.bounds_min + vec3<f32>(c) * P.cell_size;
    let half = P.cell_size * 0.5 + r.margin;
    return overlaps_box(box_min + P.cell_size * 0.5, half, v);
}

// Cells in a triangle's range (saturating: a range past u32 counts as too large).
fn range_cells(r: CellRange) -> u32 {
    let n = r.c1 - r.c0 + vec3<u32>(1u);
    let xy = n.x * n.y;
    if n.y != 0u && xy / n.y != n.x {
        return 0xffffffffu;
    }
    let xyz = xy * n.z;
    if n.z != 0u && xyz / n.z != xy {
        return 0xffffffffu;
    }
    return xyz;
}

fn cell_index(c: vec3<u32>) -> u32 {
    return c.x + P.dims.x * (c.y + P.dims.y * c.z);
}
