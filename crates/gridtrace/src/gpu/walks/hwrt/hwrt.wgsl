// `hwrt`: rays traced by the GPU's ray-tracing hardware (accel/hwrt/, gpu/walks/hwrt/). The
// module starts with `enable wgpu_ray_query;` (shaders.rs puts it first for a walk that binds a
// top-level structure). Closest points have no ray query: `hwrt_closest_point` is the BVH's
// walk, over the BVH arrays bound before the structure.
//
// The geometry is opaque and the rays force it so: the hardware commits the closest hit itself
// and the loop below ends at its first `rayQueryProceed`. Hits are those of the driver's
// triangle test, not of `intersect_tri` (edges and vertices shared by two triangles are its
// rule: tests/gpu_hwrt.rs measures the leaks). The triangle is the primitive index (the BLAS
// lists the triangles in the tracer's order, three vertices each), and the committed
// barycentrics are the weights of v1 and v2, `intersect_tri`'s u and v.
//
// Heat counts one per ray query: the hardware's steps are not visible to a shader.

@group(1) @binding(3) var hwrt_tlas: acceleration_structure;

// Vulkan requires 0 <= tmin <= tmax and finite origins and directions; the tracer's
// intervals are open (t_min <= t < t_max), the driver's closed: the bounds themselves differ
// only for a hit at exactly t_min or t_max.
fn hwrt_ray(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, flags: u32) -> RayDesc {
    let lo = max(t_min, 0.0);
    return RayDesc(flags, 0xffu, lo, max(t_max, lo), o, d);
}

fn hwrt_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    // Every hit (NEXT_HIT) as the CPU lists them, by `intersect_tri`: through the BVH the
    // structure keeps beside the driver's (its arrays are bound for the closest points).
    if (NEXT_HIT) { return bvh_closest(o, d, t_min, t_max, work); }
    if (COUNT_WORK) { *work += 1u; }
    if (!(t_max > t_min)) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    var rq: ray_query;
    rayQueryInitialize(&rq, hwrt_tlas, hwrt_ray(o, d, t_min, t_max, RAY_FLAG_FORCE_OPAQUE));
    while (rayQueryProceed(&rq)) {}
    let h = rayQueryGetCommittedIntersection(&rq);
    if (h.kind != RAY_QUERY_INTERSECTION_TRIANGLE || !(h.t >= t_min && h.t < t_max)) {
        return GpuHit(inf(), MISS, 0.0, 0.0);
    }
    return GpuHit(h.t, h.primitive_index, h.barycentrics.x, h.barycentrics.y);
}

fn hwrt_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    if (!(t_max > t_min)) { return false; }
    var rq: ray_query;
    rayQueryInitialize(&rq, hwrt_tlas,
        hwrt_ray(o, d, t_min, t_max, RAY_FLAG_FORCE_OPAQUE | RAY_FLAG_TERMINATE_ON_FIRST_HIT));
    while (rayQueryProceed(&rq)) {}
    let h = rayQueryGetCommittedIntersection(&rq);
    return h.kind == RAY_QUERY_INTERSECTION_TRIANGLE && h.t >= t_min && h.t < t_max;
}

fn hwrt_closest_point(p: vec3<f32>, work: ptr<function, u32>) -> GpuHit {
    return bvh_closest_point(p, work);
}
