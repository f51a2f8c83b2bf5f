// Traverse + intersect: closest hit for every ray of the input queue, one invocation per ray.
// The BVH pipelines are this kernel compiled with BVH = true, the irregular grid's with
// IRREGULAR = true; the grid's take the DDA, with or without proximity-cloud jumps as the pass
// says.

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    if (i >= queue_len(pass_.in_slot)) { return; }
    let r = rays_in[i];
    if (r.pixel == MISS) { return; }
    var work = 0u;
    if (BVH) {
        hits[i] = bvh_closest(v3(r.origin), v3(r.dir), r.t_min, r.t_max, &work);
    } else if (IRREGULAR) {
        hits[i] = irr_closest(v3(r.origin), v3(r.dir), r.t_min, r.t_max, &work);
    } else {
        hits[i] = closest_hit(v3(r.origin), v3(r.dir), r.t_min, r.t_max, pass_.accel == ACCEL_PC, &work);
    }
    if (COUNT_WORK) {
        accum[r.pixel] = vec4<f32>(f32(work), f32(work), f32(work), 0.0);
    }
}
