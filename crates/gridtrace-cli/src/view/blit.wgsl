// Draws the traced image over the whole window: one triangle that covers the viewport, each
// window pixel showing the traced pixel under it (nearest), so a frame traced at a reduced
// resolution scale shows its pixels as blocks rather than blurred.
//
// The traced pixels come from one of two places, row by row:
// - `frame`: the tracer's own device image (8-bit sRGB words, red in the low byte, as the pack
//   kernel writes them), when the presenter shares the tracer's device: the frame never leaves
//   the GPU;
// - `image`: a texture the host uploads (CPU frames, heat frames, the coarse preview), in the
//   surface's encoding (sRGB to sRGB, or unorm to unorm), so its bytes reach the screen as they
//   are at scale 1.
// Rows in `texture_rows` (a half-open range) come from the texture, the others from `frame`;
// with no device image the range covers every row.

struct Blit {
    // The traced image's size in pixels.
    size: vec2<u32>,
    // First and one-past-last row drawn from the texture.
    texture_rows: vec2<u32>,
    // 1 when the surface is sRGB: the device image's encoded bytes are decoded here so that
    // the surface's encoding gives them back.
    srgb_target: u32,
    _pad: u32,
};

@group(0) @binding(0) var image: texture_2d<f32>;
@group(0) @binding(1) var nearest: sampler;
@group(0) @binding(2) var<storage, read> frame: array<u32>;
@group(0) @binding(3) var<uniform> blit: Blit;

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VertexOut {
    // (0,0), (2,0), (0,2) in uv: the triangle's corners at -1..3 in clip space.
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: VertexOut;
    out.position = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

// The sRGB transfer function's inverse (IEC 61966-2-1), as a sampler of an sRGB texture
// applies it.
fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let low = c / 12.92;
    let high = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(high, low, c <= vec3<f32>(0.04045));
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    // Sampled before any branch: implicit-derivative sampling needs uniform control flow.
    let from_texture = textureSample(image, nearest, in.uv);
    let size = max(blit.size, vec2<u32>(1u));
    let px = min(vec2<u32>(in.uv * vec2<f32>(size)), size - 1u);
    if px.y >= blit.texture_rows.x && px.y < blit.texture_rows.y {
        return from_texture;
    }
    let word = frame[min(px.y * size.x + px.x, arrayLength(&frame) - 1u)];
    let encoded = unpack4x8unorm(word).rgb;
    var rgb = encoded;
    if blit.srgb_target == 1u {
        rgb = srgb_to_linear(encoded);
    }
    return vec4<f32>(rgb, 1.0);
}
