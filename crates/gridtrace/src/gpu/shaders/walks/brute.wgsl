// No structure: every triangle against every ray (accel/brute/). The oracle on the GPU, and the
// proof that a structure's GPU side is its own walk file plus one Rust file (gpu/walks/brute.rs).
// It binds nothing of its own.

fn brute_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(t_max, MISS, 0.0, 0.0);
    for (var i = 0u; i < scene.n_tris; i++) {
        if (COUNT_WORK) { *work += 1u; }
        let h = intersect_tri(tris[i], o, d, t_min, best.t);
        if (h.w != 0.0) { best = GpuHit(h.x, i, h.y, h.z); }
    }
    if (best.tri == MISS) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    return best;
}

fn brute_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    for (var i = 0u; i < scene.n_tris; i++) {
        if (intersect_tri(tris[i], o, d, t_min, t_max).w != 0.0) { return true; }
    }
    return false;
}
