// Ray batches at the bus's speed (queries.rs): the rays come up in the caller's own layout and
// only the answers the caller asked for go down; the queue records the walks read (48 bytes a
// ray) and their hits (16) are made and read here, on the device, where those bytes cost
// nothing. One file, two pipelines (override BATCH_ANSWERS), one invocation a ray of the chunk:
// - rays: a wire ray, 24 bytes (origin, direction; the batch's interval and mask), 32 (origin,
//   t_min, direction, t_max; the batch's mask) or 36 (those and the ray's mask), or a point,
//   12 bytes, into queue A (closest hits, closest points) or the shadow queue (occlusion);
//   Or no wire (stride 0): a sensor's rays made here from its table (each cell's ray in the
//   sensor's frame, kept on the device) and each column's pose (sensor.rs), so that a scan
//   sends up a few dozen bytes a column instead of 24 a ray;
// - answers: closest hits as (t, triangle), 8 bytes a ray (the caller who wants u, v reads the
//   hits themselves, 16), or `t` alone, 4 (a sensor's range); occlusion as bits, one u32 per 32
//   rays (ray k of the chunk is bit k % 32 of word k / 32), made by the word's first invocation.

// The wire as words: a ray's mask (stride 9) is an integer, whose bits no float load may
// touch; the coordinates are bit casts.
@group(1) @binding(0) var<storage, read> wire: array<u32>;
@group(1) @binding(1) var<storage, read_write> answers: array<u32>;
@group(1) @binding(2) var<uniform> batch: BatchUniform;
// A sensor's table (six floats a cell: origin, unit direction, in the sensor's frame) and then,
// from `batch.poses_at`, each environment's poses (`pose_cols` of them: one a column for a
// rolling scan, else one; twelve floats each: the sensor-to-world matrix's three columns, then
// its translation).
@group(1) @binding(3) var<storage, read> sensor: array<f32>;

override BATCH_ANSWERS: bool = false;

fn wire_f32(k: u32) -> f32 { return bitcast<f32>(wire[k]); }

fn v3_at(k: u32) -> vec3<f32> { return vec3<f32>(sensor[k], sensor[k + 1u], sensor[k + 2u]); }

// Ray `i` of the chunk made from the sensor: cell `g % cells` of environment `g / cells` (`g`
// the batch's numbering), carried into the world by its column's pose in the operation order of
// glam's `Affine3A::transform_point3` and `transform_vector3` (`Sensor::ray_in_world`), so the
// same rays as the CPU's up to the GPU's rounding (a compiler may fuse a multiply and an add).
fn sensor_ray(i: u32) -> array<vec3<f32>, 2> {
    let g = batch.first + i;
    let env = g / batch.cells;
    let cell = g - env * batch.cells;
    let col = select(0u, cell % batch.cols, batch.pose_cols > 1u);
    let p = batch.poses_at + (env * batch.pose_cols + col) * 12u;
    let x = v3_at(p);
    let y = v3_at(p + 3u);
    let z = v3_at(p + 6u);
    let so = v3_at(cell * 6u);
    let sd = v3_at(cell * 6u + 3u);
    let o = x * so.x + y * so.y + z * so.z + v3_at(p + 9u);
    let d = x * sd.x + y * sd.y + z * sd.z;
    return array<vec3<f32>, 2>(o, d);
}

fn batch_ray(i: u32) {
    if (batch.stride == 0u) {
        let r = sensor_ray(i);
        let weight = vec3<f32>(1.0, f32(batch.mask & 0xffffu), f32(batch.mask >> 16u));
        rays_in[i] = RayRec(r[0], i, r[1], batch.t_max, weight, batch.t_min);
        return;
    }
    let b = i * batch.stride;
    let o = vec3<f32>(wire_f32(b), wire_f32(b + 1u), wire_f32(b + 2u));
    var t_min = batch.t_min;
    var t_max = batch.t_max;
    var mask = batch.mask;
    // A point (stride 3) has no direction: the closest-point kernel reads its origin only.
    var d = vec3<f32>(0.0);
    if (batch.stride >= 8u) {
        t_min = wire_f32(b + 3u);
        d = vec3<f32>(wire_f32(b + 4u), wire_f32(b + 5u), wire_f32(b + 6u));
        t_max = wire_f32(b + 7u);
        if (batch.stride == 9u) { mask = wire[b + 8u]; }
    } else if (batch.stride == 6u) {
        d = vec3<f32>(wire_f32(b + 3u), wire_f32(b + 4u), wire_f32(b + 5u));
    }
    // `pixel` numbers the ray within its chunk; an occluded shadow ray's weight is zeroed; the
    // mask rides in the weight's y and z (`ray_mask`).
    let weight = vec3<f32>(1.0, f32(mask & 0xffffu), f32(mask >> 16u));
    let rec = RayRec(o, i, d, t_max, weight, t_min);
    if (batch.to_shadow != 0u) {
        shadow_rays[i] = rec;
    } else {
        rays_in[i] = rec;
    }
}

fn batch_answer(i: u32) {
    if (batch.to_shadow == 0u) {
        let h = hits[i];
        if (batch.range_only != 0u) {
            answers[i] = bitcast<u32>(h.t);
            return;
        }
        answers[2u * i] = bitcast<u32>(h.t);
        answers[2u * i + 1u] = h.tri;
        return;
    }
    if (i % 32u != 0u) { return; }
    let end = min(i + 32u, pass_.tile_pixels);
    var bits = 0u;
    for (var k = i; k < end; k++) {
        if (shadow_rays[k].weight.x == 0.0) {
            bits |= 1u << (k - i);
        }
    }
    answers[i / 32u] = bits;
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    if (i >= pass_.tile_pixels) { return; }
    if (BATCH_ANSWERS) {
        batch_answer(i);
    } else {
        batch_ray(i);
    }
}
