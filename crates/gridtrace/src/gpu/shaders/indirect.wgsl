// Indirect dispatch sizes from the queue lengths: [0..3] for the input ray queue, [3..6] for the
// shadow queue. Large queues use a second dimension to stay under 65535 groups per dimension.

// Its own bind group: a buffer bound as storage in the dispatch that reads it as indirect
// arguments would be a usage conflict.
@group(1) @binding(0) var<storage, read_write> indirect: array<u32, 6>;

fn groups(n: u32, out: u32) {
    let g = (n + WORKGROUP - 1u) / WORKGROUP;
    let x = min(g, 32768u);
    indirect[out] = x;
    indirect[out + 1u] = select(0u, (g + x - 1u) / x, x > 0u);
    indirect[out + 2u] = 1u;
}

@compute @workgroup_size(1)
fn main() {
    groups(atomicLoad(&counters[pass_.in_slot]), 0u);
    groups(atomicLoad(&counters[SLOT_SHADOW]), 3u);
}
