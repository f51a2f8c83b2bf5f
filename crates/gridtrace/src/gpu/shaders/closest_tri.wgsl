// Closest points: the nearest point of a triangle to a point, shared by every structure's walk
// (`NAME_closest_point` in walks/*.wgsl); mirrors accel/closest.rs (`closest_on_triangle`,
// `ClosestPoint::offer`) operation for operation, so the GPU and the CPU measure the same
// distance up to the compilers' contractions (a GPU may fuse a multiply-add the CPU rounds
// twice: the last bits of u, v and the distance can differ, never the region chosen except
// at a region's boundary, where both regions give the same point within rounding).
//
// A closest-point answer is a GpuHit: `t` holds the squared distance (inf: nothing found),
// `tri` the triangle (MISS: none), `u`, `v` the barycentrics of the nearest point.

// Barycentrics (u, v) of the point nearest to `a + ap` on the three edges of the triangle
// `a, a + ab, a + ac`: the fallback for (nearly) degenerate triangles (`nearest_on_edges`).
fn tri_nearest_on_edges(ap: vec3<f32>, ab: vec3<f32>, ac: vec3<f32>) -> vec2<f32> {
    let bc = ac - ab;
    let s_ab = tri_along(ap, ab);
    let s_ac = tri_along(ap, ac);
    let s_bc = tri_along(ap - ab, bc);
    // Written out rather than looped: llvmpipe counts every loop iteration against its cap.
    var best = vec2<f32>(s_ab, 0.0);
    let q0 = ap - ab * s_ab;
    var best_d = dot(q0, q0);
    let q1 = ap - ac * s_ac;
    if (dot(q1, q1) < best_d) { best_d = dot(q1, q1); best = vec2<f32>(0.0, s_ac); }
    let q2 = ap - ab * (1.0 - s_bc) - ac * s_bc;
    if (dot(q2, q2) < best_d) { best = vec2<f32>(1.0 - s_bc, s_bc); }
    return best;
}

// Parameter in [0, 1] of the point of segment `s d` (s in [0, 1]) nearest to `q`; 0 for a
// zero-length segment.
fn tri_along(q: vec3<f32>, d: vec3<f32>) -> f32 {
    let len2 = dot(d, d);
    if (len2 > 0.0) { return clamp(dot(q, d) / len2, 0.0, 1.0); }
    return 0.0;
}

// Ericson, Real-Time Collision Detection, 5.1.5: the Voronoi region of the triangle holding
// `p` (three vertices, three edges, the face) by signs of dot products, then the projection
// onto it. Returns (squared distance, u, v); the distance is measured to `v0 + u e1 + v e2`,
// the point reported.
fn closest_on_tri(t: GpuTri, p: vec3<f32>) -> vec3<f32> {
    let a = t.v0;
    let ab = t.v1 - t.v0;
    let ac = t.v2 - t.v0;
    let ap = p - a;
    let uv = tri_region(ap, ab, ac);
    let q = p - (a + ab * uv.x + ac * uv.y);
    return vec3<f32>(dot(q, q), uv.x, uv.y);
}

fn tri_region(ap: vec3<f32>, ab: vec3<f32>, ac: vec3<f32>) -> vec2<f32> {
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) { return vec2<f32>(0.0, 0.0); } // vertex v0
    let bp = ap - ab;
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) { return vec2<f32>(1.0, 0.0); } // vertex v1
    let vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) { return vec2<f32>(d1 / (d1 - d3), 0.0); } // edge v0-v1
    let cp = ap - ac;
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) { return vec2<f32>(0.0, 1.0); } // vertex v2
    let vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) { return vec2<f32>(0.0, d2 / (d2 - d6)); } // edge v0-v2
    let va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return vec2<f32>(1.0 - w, w); // edge v1-v2
    }
    let denom = va + vb + vc;
    // Rounding can make the denominator zero or one of the three negative for a sliver: then
    // the edges (closest.rs says why).
    if (va >= 0.0 && vb >= 0.0 && vc >= 0.0 && denom > 0.0 && denom < inf()) {
        let inv = 1.0 / denom;
        return vec2<f32>(vb * inv, vc * inv); // the face
    }
    return tri_nearest_on_edges(ap, ab, ac);
}

// Offers triangle `tri` for point `p`: kept if nearer than the best so far, or as near with a
// smaller index (the tie rule every structure and the CPU follow, `ClosestPoint::is_beaten_by`).
fn point_offer(best: ptr<function, GpuHit>, tri: u32, p: vec3<f32>) {
    let c = closest_on_tri(tris[tri], p);
    if (c.x < (*best).t || (c.x == (*best).t && tri < (*best).tri)) {
        *best = GpuHit(c.x, tri, c.y, c.z);
    }
}

// Loop iterations of this invocation's closest-point search, counted by the lattice searches
// (`walks/point_ring.wgsl` and the cells they search; 0 for the other walks) and written to
// the answer's work texel (`y`), so that tests hold them under llvmpipe's loop budget.
var<private> point_steps: u32;

// Squared distance from `p` to the box [lo, hi] (0 inside).
fn point_box_dist_sq(p: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> f32 {
    let d = max(max(lo - p, p - hi), vec3<f32>(0.0));
    return dot(d, d);
}

// `binning::cell_margin` of a lattice of `cell`-sized cells over the scene's bounds, doubled:
// the cells were filled with boxes grown by it, so a search that grows its bounds by it never
// prunes a triangle that rounding put on the wrong side of a face; doubled so that the GPU's
// own rounding of this formula cannot make it smaller than the CPU's.
fn point_cell_margin(cell: vec3<f32>) -> vec3<f32> {
    let big = max(abs(scene.bounds_min), abs(scene.bounds_max));
    return 2.0 * (cell * 1e-3 + vec3<f32>(1e-6 * max(big.x, max(big.y, big.z))));
}

// ---- Lattices searched in rings (accel/closest/shells.rs) ----
//
// The uniform grid searches its cells, the irregular grid its top cells, in growing Chebyshev
// rings around the point's cell. Each walk enumerates a ring itself (its visit is its own);
// the distances and the bound that ends the search are these.

// `dims` cells of size `cell` from `min`; their contents lie within `margin` of their boxes.
struct PointLattice { min: vec3<f32>, cell: vec3<f32>, dims: vec3<i32>, margin: vec3<f32> }

// The cell of `l` nearest to `p` (holding it, clamped into the lattice; clamped in floats
// first, so that an infinite coordinate converts safely).
fn lattice_cell_of(l: PointLattice, p: vec3<f32>) -> vec3<i32> {
    let g = clamp(floor((p - l.min) / l.cell), vec3<f32>(0.0), vec3<f32>(l.dims - 1));
    return vec3<i32>(g);
}

// Distance along `axis` from `p` to the slab of cells `k`, grown by the margin (0 inside).
fn lattice_slab_dist(l: PointLattice, p: vec3<f32>, axis: i32, k: i32) -> f32 {
    let lo = l.min[axis] + f32(k) * l.cell[axis] - l.margin[axis];
    let hi = l.min[axis] + f32(k + 1) * l.cell[axis] + l.margin[axis];
    return max(max(lo - p[axis], p[axis] - hi), 0.0);
}

// How far outside the lattice (less the margin) `p` is, per axis, squared.
fn lattice_out2(l: PointLattice, p: vec3<f32>) -> vec3<f32> {
    let hi = l.min + vec3<f32>(l.dims) * l.cell;
    let out = max(max(l.min - l.margin - p, p - hi - l.margin), vec3<f32>(0.0));
    return out * out;
}

// The last ring around cell `c` that has cells.
fn lattice_last_ring(l: PointLattice, c: vec3<i32>) -> i32 {
    let last = max(max(c, l.dims - 1 - c), vec3<i32>(0));
    return max(last.x, max(last.y, last.z));
}

// A lower bound on the squared distance from `p` to any cell of ring `r` or beyond around cell
// `c` (`shells::lower_bound`): on each side that still has cells, the distance to the face of
// the block of rings below `r`, plus how far outside the lattice the point is on the other
// axes (`out2`). Infinite when no side has cells left.
fn lattice_ring_bound(l: PointLattice, p: vec3<f32>, c: vec3<i32>, r: i32, out2: vec3<f32>) -> f32 {
    if (r == 0) { return out2.x + out2.y + out2.z; }
    var lower = inf();
    for (var a = 0; a < 3; a++) {
        let rest = out2[(a + 1) % 3] + out2[(a + 2) % 3];
        if (c[a] - r >= 0) {
            let face = l.min[a] + f32(c[a] - r + 1) * l.cell[a];
            let d = max(p[a] - face - l.margin[a], 0.0);
            lower = min(lower, d * d + rest);
        }
        if (c[a] + r < l.dims[a]) {
            let face = l.min[a] + f32(c[a] + r) * l.cell[a];
            let d = max(face - p[a] - l.margin[a], 0.0);
            lower = min(lower, d * d + rest);
        }
    }
    return lower;
}
