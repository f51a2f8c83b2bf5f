// No structure: every triangle against every ray (accel/brute/). The oracle on the GPU, and the
// proof that a structure's GPU side is its own walk file plus one Rust file (gpu/walks/brute/mod.rs).
// It binds nothing of its own.
//
// Four triangles per loop iteration, written out: Mesa's llvmpipe (lavapipe) ends a shader
// invocation's loops after 65,535 iterations in all (a guard against endless loops), and a loop
// of one triangle per iteration never tested the Stanford Bunny's last 3,915 triangles (the
// edge-leak test caught it). Four a turn reach 262,140 triangles there; the upload refuses
// more on a software adapter (`gpu/walks/brute/mod.rs`). Hardware has no such cap.

// The walk of one mesh's triangles, `tris[h.first..h.first + h.count]` (the scene's one mesh:
// all of them; a scene of two levels: the mesh's part of the shared triangles,
// `gpu/walks/two_level/`). A hit names the mesh's own triangle, `i - h.first`.

fn brute_test(i: u32, end: u32, first: u32, o: vec3<f32>, d: vec3<f32>, t_min: f32, best: ptr<function, GpuHit>) {
    if (i < end) {
        let h = intersect_tri(tris[i], o, d, t_min, leaf_bound((*best).t));
        if (h.w != 0.0 && leaf_takes(h.x, i, *best, first)) { *best = GpuHit(h.x, i, h.y, h.z); }
    }
}

fn brute_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    return brute_closest_in(MeshHeader(0u, scene.n_tris), o, d, t_min, t_max, work);
}

fn brute_closest_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(t_max, MISS, 0.0, 0.0);
    let end = h.first + h.count;
    for (var i = h.first; i < end; i += 4u) {
        if (COUNT_WORK) { *work += min(4u, end - i); }
        brute_test(i, end, h.first, o, d, t_min, &best);
        brute_test(i + 1u, end, h.first, o, d, t_min, &best);
        brute_test(i + 2u, end, h.first, o, d, t_min, &best);
        brute_test(i + 3u, end, h.first, o, d, t_min, &best);
    }
    if (best.tri == MISS) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    best.tri -= h.first;
    return best;
}

fn brute_hits(i: u32, end: u32, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    return i < end && intersect_tri(tris[i], o, d, t_min, t_max).w != 0.0;
}

fn brute_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    return brute_any_in(MeshHeader(0u, scene.n_tris), o, d, t_min, t_max);
}

fn brute_any_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    let end = h.first + h.count;
    for (var i = h.first; i < end; i += 4u) {
        if (brute_hits(i, end, o, d, t_min, t_max) || brute_hits(i + 1u, end, o, d, t_min, t_max)
            || brute_hits(i + 2u, end, o, d, t_min, t_max) || brute_hits(i + 3u, end, o, d, t_min, t_max)) {
            return true;
        }
    }
    return false;
}

// The nearest point to `p`: every triangle measured, four a loop iteration (llvmpipe's cap, as
// above). `work` gets the triangles measured.
fn brute_point(i: u32, p: vec3<f32>, best: ptr<function, GpuHit>) {
    if (i < scene.n_tris) { point_offer(best, i, p); }
}

fn brute_closest_point(p: vec3<f32>, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(inf(), MISS, 0.0, 0.0);
    for (var i = 0u; i < scene.n_tris; i += 4u) {
        *work += min(4u, scene.n_tris - i);
        brute_point(i, p, &best);
        brute_point(i + 1u, p, &best);
        brute_point(i + 2u, p, &best);
        brute_point(i + 3u, p, &best);
    }
    return best;
}
