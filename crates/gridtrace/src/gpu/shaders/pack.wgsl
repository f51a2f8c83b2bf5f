// Pack: the tile's pixels as 8-bit sRGB, one u32 each (red in the low byte, alpha 255), when
// the caller wants only those levels (`PixelFormat::Srgb8`): the frame's readback is then 4
// bytes a pixel instead of the accumulation's 16 (a 1920x1080 frame: 8 MB instead of 33 MB).

// Its own bind group, as indirect.wgsl's: group 1 is free in a kernel that walks no structure,
// and group 0 stays within every API's storage-buffer limit per stage.
@group(1) @binding(0) var<storage, read_write> packed: array<u32>;

// The host's `linear_to_srgb8`: NaN is black, clamp to [0, 1], the sRGB curve, then
// `s * 255 + 0.5` truncated (pack4x8unorm's rounding). `pow` is the device's, so a level may
// differ from the host's by one where the value lies on a rounding boundary.
fn srgb8(c: f32) -> u32 {
    let x = select(clamp(c, 0.0, 1.0), 0.0, c != c);
    let s = select(1.055 * pow(x, 1.0 / 2.4) - 0.055, 12.92 * x, x <= 0.0031308);
    return min(u32(s * 255.0 + 0.5), 255u);
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    if (i >= pass_.tile_pixels) { return; }
    let c = accum[i].xyz;
    packed[i] = srgb8(c.x) | (srgb8(c.y) << 8u) | (srgb8(c.z) << 16u) | (255u << 24u);
}
