// Resolve: add the contributions of a hit's unoccluded shadow rays to its pixel, in light order.

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    if (i >= queue_len(pass_.in_slot)) { return; }
    let span = resolve[i];
    if (span.y == 0u) { return; }
    let p = rays_in[i].pixel;
    var c = accum[p].xyz;
    for (var k = 0u; k < span.y; k++) {
        c += shadow_rays[span.x + k].weight;
    }
    accum[p] = vec4<f32>(c, 0.0);
}
