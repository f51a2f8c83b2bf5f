// Occlusion (any hit) for the shadow queue: an occluded shadow ray loses its contribution.
// Compiled with each structure's walk (as traverse.wgsl), and with SHADOW_CLOSEST = true for the
// ablation that finds closest hits instead.

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    lane = lid;
    if (i >= shadow_len()) { return; }
    let r = shadow_rays[i];
    if (r.pixel == MISS) { return; }
    let o = r.origin;
    let d = r.dir;
    var occluded: bool;
    var work = 0u;
    if (SHADOW_CLOSEST) {
        // The ablation: the closest hit before the light, as a closest-hit-only tracer would.
        occluded = walk_closest(o, d, r.t_min, r.t_max, ray_mask(r), &work).tri != MISS;
    } else {
        occluded = walk_any(o, d, r.t_min, r.t_max, ray_mask(r));
    }
    if (occluded) {
        shadow_rays[i].weight = vec3<f32>(0.0);
    }
}
