// Ray generation: one eye ray per pixel of the tile into queue A. Rays that miss the grid are
// finished here (background written, never queued): the paper's early ray masking. (Without
// compaction every pixel keeps slot i, and a finished one idles there: common.wgsl.)

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    if (i >= pass_.tile_pixels) { return; }
    let pixel = pass_.tile_offset + i;
    let x = pixel % camera.width;
    let y = pixel / camera.width;
    // CameraFrame::ray: the convention in scene/camera.rs.
    let px = 2.0 * (f32(x) + 0.5) / f32(camera.width) - 1.0;
    let py = 1.0 - 2.0 * (f32(y) + 0.5) / f32(camera.height);
    let d = normalize(camera.forward + px * camera.right_scaled + py * camera.up_scaled);
    let c = clip_box(camera.eye, 1.0 / d, d, 0.0, inf());
    if (c.z == 0.0) {
        accum[i] = select(vec4<f32>(scene.background, 0.0), vec4<f32>(0.0), pass_.mode == MODE_HEAT);
        if (!compacted()) { rays_in[i].pixel = MISS; }
        return;
    }
    accum[i] = vec4<f32>(0.0);
    var slot = i;
    if (compacted()) { slot = atomicAdd(&counters[SLOT_QUEUE_A], 1u); }
    rays_in[slot] = RayRec(a3(camera.eye), i, a3(d), inf(), array<f32, 3>(1.0, 1.0, 1.0), 0.0);
}
