// Traverse + intersect: closest hit for every ray of the input queue, one invocation per ray,
// through the scene's structure's walk (`walk_closest`, from its walk file: each structure's
// pipelines are this kernel compiled with its own walk).

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    lane = lid;
    if (i >= queue_len(pass_.in_slot)) { return; }
    let r = rays_in[i];
    if (r.pixel == MISS) { return; }
    var work = 0u;
    hits[i] = walk_closest(r.origin, r.dir, r.t_min, r.t_max, ray_mask(r), &work);
    if (COUNT_WORK) {
        accum[r.pixel] = vec4<f32>(f32(work), f32(work), f32(work), 0.0);
    }
}
