// Ray generation: one eye ray per pixel of the tile into queue A. Rays that miss the grid are
// finished here (background written, never queued): the paper's early ray masking. (Without
// compaction every ray keeps its invocation's slot, and a finished one idles there: common.wgsl.)

// The tile-local pixel that invocation `j` starts. Rows order: pixel j. Tiles order
// (TILE_ORDER): the tile's whole rows are cut into bands of 8 rows and each band into 8x8
// squares (narrower or lower at the right and bottom edges), one after another, so a
// workgroup of 64 covers a square; the partial rows at the tile's two ends stay in row order.
// A bijection on [0, tile_pixels), so every pixel gets exactly one ray and the same one.
fn tile_pixel(j: u32) -> u32 {
    if (!TILE_ORDER) { return j; }
    let w = camera.width;
    let n = pass_.tile_pixels;
    let head = min((w - pass_.tile_offset % w) % w, n);
    let rows = (n - head) / w;
    if (j < head || j >= head + rows * w) { return j; }
    let k = j - head;
    let band = k / (8u * w);
    let h = min(8u, rows - band * 8u);
    let r = k - band * 8u * w;
    let bx = r / (8u * h);
    let within = r - bx * 8u * h;
    let bw = min(8u, w - bx * 8u);
    return head + (band * 8u + within / bw) * w + bx * 8u + within % bw;
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let j = flat_index(wg, nwg, lid);
    // No early return: every invocation reaches `append` (workgroup-uniform control flow).
    var queued = false;
    var rec: RayRec;
    if (j < pass_.tile_pixels) {
        let i = tile_pixel(j);
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
            if (!compacted()) { rays_in[j].pixel = MISS; }
        } else {
            accum[i] = vec4<f32>(0.0);
            queued = true;
            rec = RayRec(camera.eye, i, d, inf(), vec3<f32>(1.0), 0.0);
        }
    }
    var slot = j;
    if (compacted()) { slot = append(SLOT_QUEUE_A, u32(queued), lid); }
    if (queued) { rays_in[slot] = rec; }
}
