// Indirect dispatch sizes from the queue lengths: `rays` for the input ray queue, `shadow` for
// the shadow queue. Large queues use a second dimension to stay under 65535 groups per dimension.

// Its own bind group: a buffer bound as storage in the dispatch that reads it as indirect
// arguments would be a usage conflict.
@group(1) @binding(0) var<storage, read_write> indirect: IndirectArgs;

fn groups(n: u32) -> array<u32, 3> {
    let g = (n + WORKGROUP - 1u) / WORKGROUP;
    let x = min(g, MAX_GROUPS_X);
    return array<u32, 3>(x, select(0u, (g + x - 1u) / x, x > 0u), 1u);
}

@compute @workgroup_size(1)
fn main() {
    indirect.rays = groups(queue_len(pass_.in_slot));
    indirect.shadow = groups(shadow_len());
    // `stats=off`: the tile's shadow and reflection totals, read off the queue lengths instead
    // of counted per ray in shading. Every bounce starts with its output and shadow queues
    // empty, so the call before tracing adds nothing and the call after shading (before
    // occlusion; Cast mode, which has no second call, emits neither) adds the bounce's rays.
    // Without compaction the queues have no lengths and shading counts per ray as with `on`.
    if (!RAY_STATS && compacted()) {
        atomicAdd(&counters[SLOT_SHADOW_TOTAL], shadow_len());
        atomicAdd(&counters[SLOT_REFLECT_TOTAL], queue_len(pass_.out_slot));
    }
}
