// Occlusion (any hit) for the shadow queue: an occluded shadow ray loses its contribution.
// Compiled with BVH = true for BVH scenes (as traverse.wgsl).

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    if (i >= atomicLoad(&counters[SLOT_SHADOW])) { return; }
    let r = shadow_rays[i];
    var occluded: bool;
    if (BVH) {
        occluded = bvh_any(v3(r.origin), v3(r.dir), r.t_min, r.t_max);
    } else {
        occluded = any_hit(v3(r.origin), v3(r.dir), r.t_min, r.t_max, pass_.accel == ACCEL_PC);
    }
    if (occluded) {
        shadow_rays[i].weight = array<f32, 3>(0.0, 0.0, 0.0);
    }
}
