// Shading: for each ray of the input queue and its hit, add ambient (and, in cast mode, direct
// light) to the pixel, emit shadow rays into the shadow queue and a reflection ray into the
// output queue. Mirrors trace_pixel in src/cpu/render.rs step for step.

struct Surface { p: vec3<f32>, ng: vec3<f32>, ns: vec3<f32> }

fn surface_at(o: vec3<f32>, d: vec3<f32>, h: GpuHit) -> Surface {
    let tri = tris[h.tri];
    var ng = normalize(cross(tri.v1 - tri.v0, tri.v2 - tri.v0));
    let sh = tri_shade[h.tri];
    let w = 1.0 - h.u - h.v;
    var ns = v3(sh.n0) * w + v3(sh.n1) * h.u + v3(sh.n2) * h.v;
    let len2 = dot(ns, ns);
    if (len2 > 0.0) { ns = ns / sqrt(len2); } else { ns = ng; }
    if (dot(ng, d) > 0.0) { ng = -ng; }
    if (dot(ns, ng) < 0.0) { ns = -ns; }
    return Surface(o + d * h.t, ng, ns);
}

// Light contribution factor (intensity * N.L / d^2) in xyz and the distance in w; w = -1 when
// the light is behind the surface (no shadow ray spent).
fn light_term(s: Surface, origin: vec3<f32>, l: PointLight, dir_out: ptr<function, vec3<f32>>) -> vec4<f32> {
    let to = l.position - origin;
    let d2 = dot(to, to);
    if (d2 == 0.0) { return vec4<f32>(0.0, 0.0, 0.0, -1.0); }
    let dist = sqrt(d2);
    let dir = to / dist;
    let ndl = dot(s.ns, dir);
    if (ndl <= 0.0 || dot(s.ng, dir) <= 0.0) { return vec4<f32>(0.0, 0.0, 0.0, -1.0); }
    *dir_out = dir;
    return vec4<f32>(l.intensity * (ndl / d2), dist);
}

// What shading one ray leaves to emit once its queue slots are known.
struct Shaded {
    // Shadow rays to emit (one per light in front of the surface), and a reflection ray?
    n_shadow: u32,
    reflect: bool,
    pixel: u32,
    s: Surface,
    origin: vec3<f32>,
    local: vec3<f32>,
    // The reflection ray's direction and weight.
    dir: vec3<f32>,
    weight: vec3<f32>,
}

// Shades ray `i` of the input queue: its colour into the pixel, and what it will emit.
fn shade_ray(i: u32) -> Shaded {
    var out: Shaded;
    let r = rays_in[i];
    resolve[i] = vec2<u32>(0u, 0u);
    if (!compacted()) {
        // Every slot this ray owns downstream starts finished; what it emits overwrites that.
        rays_out[i].pixel = MISS;
        if (pass_.mode != MODE_CAST) {
            for (var l = 0u; l < scene.n_lights; l++) { shadow_rays[i * scene.n_lights + l].pixel = MISS; }
        }
    }
    if (r.pixel == MISS) { return out; }
    let h = hits[i];
    let weight = r.weight;
    if (h.tri == MISS) {
        accum[r.pixel] += vec4<f32>(weight * scene.background, 0.0);
        return out;
    }
    let d = r.dir;
    let s = surface_at(r.origin, d, h);
    let mat = materials[tri_shade[h.tri].material];
    var reflect = 0.0;
    if (pass_.mode == MODE_TRACE) { reflect = mat.reflectivity; }
    let local = weight * (1.0 - reflect) * mat.diffuse;
    // Summed term by term into the pixel, in the CPU's order, so both round alike.
    var color = accum[r.pixel].xyz + local * scene.ambient;
    let origin = s.p + s.ng * scene.ray_epsilon;
    if (pass_.mode == MODE_CAST) {
        for (var l = 0u; l < scene.n_lights; l++) {
            var dir: vec3<f32>;
            let lt = light_term(s, origin, lights[l], &dir);
            if (lt.w >= 0.0) { color += local * lt.xyz; }
        }
    } else {
        // Two passes over the lights: count here, reserve contiguous slots, fill (`emit`).
        // Contiguous slots let the resolve kernel add the visible contributions in light
        // order, as the CPU does.
        for (var l = 0u; l < scene.n_lights; l++) {
            var dir: vec3<f32>;
            if (light_term(s, origin, lights[l], &dir).w >= 0.0) { out.n_shadow += 1u; }
        }
    }
    accum[r.pixel] = vec4<f32>(color, 0.0);
    out.pixel = r.pixel;
    out.s = s;
    out.origin = origin;
    out.local = local;
    if (reflect > 0.0 && pass_.depth < pass_.max_depth) {
        out.reflect = true;
        out.dir = normalize(d - 2.0 * dot(d, s.ns) * s.ns);
        out.weight = weight * reflect;
    }
    return out;
}

// Writes ray `i`'s shadow rays from slot `base` and its reflection ray into slot `slot`.
fn emit(i: u32, sh: Shaded, base: u32, slot: u32) {
    if (sh.n_shadow > 0u) {
        if (RAY_STATS || !compacted()) { atomicAdd(&counters[SLOT_SHADOW_TOTAL], sh.n_shadow); }
        var k = 0u;
        for (var l = 0u; l < scene.n_lights; l++) {
            var dir: vec3<f32>;
            let lt = light_term(sh.s, sh.origin, lights[l], &dir);
            if (lt.w >= 0.0) {
                shadow_rays[base + k] = RayRec(sh.origin, sh.pixel, dir, lt.w, sh.local * lt.xyz, 0.0);
                k += 1u;
            }
        }
        resolve[i] = vec2<u32>(base, sh.n_shadow);
    }
    if (sh.reflect) {
        if (RAY_STATS || !compacted()) { atomicAdd(&counters[SLOT_REFLECT_TOTAL], 1u); }
        rays_out[slot] = RayRec(sh.origin, sh.pixel, sh.dir, inf(), sh.weight, 0.0);
    }
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    // No early return: every invocation reaches the appends (workgroup-uniform control flow).
    var sh: Shaded;
    let in_queue = i < queue_len(pass_.in_slot);
    if (in_queue) { sh = shade_ray(i); }
    var base = i * scene.n_lights;
    var slot = i;
    if (compacted()) {
        base = append(SLOT_SHADOW, sh.n_shadow, lid);
        slot = append(pass_.out_slot, u32(sh.reflect), lid);
    }
    if (in_queue) { emit(i, sh, base, slot); }
}
