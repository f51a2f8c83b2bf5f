// Queue appends for the kernels that emit rays (raygen, shade): their modules include this
// file after common.wgsl; the others have no workgroup memory.

// Appends `n` entries to the queue whose length is `counters[slot]`; returns the first of the
// caller's `n` slots. Every invocation of the workgroup must call it (uniform control flow),
// those with nothing to append with `n = 0`. `per_ray`: one global atomic per appending
// invocation. `workgroup` (WG_APPENDS): the offsets are handed out in workgroup memory and one
// invocation makes the workgroup's one global atomic. Each caller's entries stay contiguous.
var<workgroup> wg_count: atomic<u32>;
var<workgroup> wg_base: u32;
fn append(slot: u32, n: u32, lid: u32) -> u32 {
    if (!WG_APPENDS) {
        // No return that depends on `n`: WGSL's uniformity analysis (which Tint enforces) would
        // then put the barriers below in non-uniform control flow, though this path skips them.
        var first = 0u;
        if (n != 0u) { first = atomicAdd(&counters[slot], n); }
        return first;
    }
    // Set here, not relied on from zero-initialisation (`checks=off` turns that off); the
    // barrier also keeps an earlier call's readers of wg_base ahead of this call's writer.
    if (lid == 0u) { atomicStore(&wg_count, 0u); }
    workgroupBarrier();
    let local = atomicAdd(&wg_count, n);
    workgroupBarrier();
    if (lid == 0u) {
        let total = atomicLoad(&wg_count);
        if (total > 0u) { wg_base = atomicAdd(&counters[slot], total); }
    }
    workgroupBarrier();
    return wg_base + local;
}
