// Draws the traced image over the whole window: one triangle that covers the viewport, sampled
// with the nearest texel, so a frame traced at a reduced resolution scale shows its pixels as
// blocks rather than blurred. The texture's format matches the surface's encoding (sRGB to sRGB,
// or unorm to unorm), so the traced bytes reach the screen unchanged at scale 1.

@group(0) @binding(0) var image: texture_2d<f32>;
@group(0) @binding(1) var nearest: sampler;

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

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return textureSample(image, nearest, in.uv);
}
