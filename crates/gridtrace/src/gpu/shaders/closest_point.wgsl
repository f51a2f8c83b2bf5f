// Closest points: for every point of the input queue (a RayRec whose origin is the point; the
// host replaces a point that is not finite by a stand-in and answers it itself), the nearest
// point of the mesh through the scene's structure's search (`walk_closest_point`, from its walk
// file: each structure's pipelines are this kernel compiled with its own walk). The answer goes
// to `hits` as (squared distance, triangle, u, v), and the search's work (cells or nodes
// visited plus triangles measured) to `accum[i].x`, for the statistics, and its loop iterations
// (`point_steps`, lattice searches only) to `accum[i].y`.

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    lane = lid;
    if (i >= queue_len(pass_.in_slot)) { return; }
    var work = 0u;
    hits[i] = walk_closest_point(rays_in[i].origin, &work);
    accum[i] = vec4<f32>(f32(work), f32(point_steps), 0.0, 0.0);
}
