// `hwrt` over a scene's instances (gpu/walks/hwrt/instances.rs): the driver walks the TLAS (an
// instance a scene instance, its world-from-mesh transform, its custom data the instance's
// index) and each mesh's BLAS. The driver carries the ray into the mesh's space with its
// direction not normalised, so `t` is world `t`, as the software top level's (top_level.wgsl).
// The primitive index is the mesh's own triangle and the barycentrics the weights of v1 and
// v2 (`intersect_tri`'s u and v); the answer numbers the triangle among every instance's by the
// instance's first (the instance table), as the software top level does.
//
// The instance table (words): the mask class table (DRIVER_CLASSES words), at DRIVER_EXACT_WORD
// whether the driver's cull is the 32-bit rule exactly, then from DRIVER_FIRST_RECORD each
// instance's (32-bit mask, first answer).
//
// Masks (masks.rs): the ray's 8-bit cull mask has bit j where class j shares a bit with the
// ray's mask. With exact masks the driver culls by the rule itself and the geometry is traced
// opaque (the hardware commits its hits; the proceed loop ends at once). Otherwise the cull is
// conservative (it keeps every instance the rule sees, maybe more): the geometry is traced
// non-opaque and a candidate is confirmed only where its instance's own 32-bit mask shares a
// bit with the ray's. A candidate is only ever confirmed, so the driver's duplicate candidates
// change nothing.
//
// Intervals: the tracer's are half-open (t_min <= t < t_max), the driver's closed and from 0
// (t_min >= 0 is checked on the host). The driver's t_max is the float below t_max: on floats
// [t_min, below(t_max)] is [t_min, t_max) exactly, so even the first hit the any-hit query
// ends at lies inside (a hit at exactly t_max could otherwise end it and hide a nearer one).
//
// Counts and lists of every hit (NEXT_HIT) do not come here: the host lists them on the CPU's
// two levels (query_scene/gpu_all_hits.rs), by `intersect_tri` as the CPU lists them.
//
// Heat counts one per ray query: the hardware's steps are not visible to a shader.

@group(1) @binding(0) var<storage, read> hwrt_instances: array<u32>;
@group(1) @binding(1) var hwrt_driver_tlas: acceleration_structure;

// The ray's 8-bit cull mask: bit j where class j shares a bit with `mask`.
fn driver_cull_mask(mask: u32) -> u32 {
    var hw = 0u;
    for (var j = 0u; j < DRIVER_CLASSES; j++) {
        if ((hwrt_instances[j] & mask) != 0u) { hw |= 1u << j; }
    }
    return hw;
}

// The float below `t` (t > 0); inf stays inf.
fn driver_below(t: f32) -> f32 {
    if (!(t < inf())) { return t; }
    return bitcast<f32>(bitcast<u32>(t) - 1u);
}

fn driver_ray(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, mask: u32, any: bool) -> RayDesc {
    let exact = hwrt_instances[DRIVER_EXACT_WORD] != 0u;
    var flags = select(RAY_FLAG_FORCE_NO_OPAQUE, RAY_FLAG_FORCE_OPAQUE, exact);
    if (any) { flags |= RAY_FLAG_TERMINATE_ON_FIRST_HIT; }
    let lo = max(t_min, 0.0);
    return RayDesc(flags, driver_cull_mask(mask), lo, max(driver_below(t_max), lo), o, d);
}

// Whether instance `k`'s own 32-bit mask shares a bit with the ray's.
fn driver_sees(k: u32, mask: u32) -> bool {
    return (hwrt_instances[DRIVER_FIRST_RECORD + 2u * k] & mask) != 0u;
}

fn driver_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, mask: u32, work: ptr<function, u32>) -> GpuHit {
    if (COUNT_WORK) { *work += 1u; }
    // An empty or NaN interval sees nothing (t_max > t_min > = 0 from here: below(t_max) > 0).
    if (NEXT_HIT || !(t_max > t_min)) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    var rq: ray_query;
    rayQueryInitialize(&rq, hwrt_driver_tlas, driver_ray(o, d, t_min, t_max, mask, false));
    while (rayQueryProceed(&rq)) {
        let c = rayQueryGetCandidateIntersection(&rq);
        if (driver_sees(c.instance_custom_data, mask)) { rayQueryConfirmIntersection(&rq); }
    }
    let h = rayQueryGetCommittedIntersection(&rq);
    if (h.kind != RAY_QUERY_INTERSECTION_TRIANGLE || !(h.t >= t_min && h.t < t_max)) {
        return GpuHit(inf(), MISS, 0.0, 0.0);
    }
    let first = hwrt_instances[DRIVER_FIRST_RECORD + 2u * h.instance_custom_data + 1u];
    return GpuHit(h.t, first + h.primitive_index, h.barycentrics.x, h.barycentrics.y);
}

fn driver_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, mask: u32) -> bool {
    if (!(t_max > t_min)) { return false; }
    var rq: ray_query;
    rayQueryInitialize(&rq, hwrt_driver_tlas, driver_ray(o, d, t_min, t_max, mask, true));
    while (rayQueryProceed(&rq)) {
        let c = rayQueryGetCandidateIntersection(&rq);
        if (driver_sees(c.instance_custom_data, mask)) { rayQueryConfirmIntersection(&rq); }
    }
    let h = rayQueryGetCommittedIntersection(&rq);
    return h.kind == RAY_QUERY_INTERSECTION_TRIANGLE && h.t >= t_min && h.t < t_max;
}
