// Queue appends with subgroup operations (`appends=subgroup`): in place of append.wgsl in the
// modules of raygen and shade (compiled on devices opened with wgpu's SUBGROUP feature). The
// same contract:
// every invocation of the workgroup calls it (so every subgroup is whole), each caller's `n`
// entries stay contiguous, and the first is returned. One invocation per subgroup makes the
// subgroup's one global atomic: the aggregation CUDA compilers do for a warp's atomics, made
// explicit, with no workgroup memory and no barrier.
fn append(slot: u32, n: u32, lid: u32) -> u32 {
    let before = subgroupExclusiveAdd(n);
    let total = subgroupAdd(n);
    // The lowest active invocation makes the atomic, and subgroupBroadcastFirst reads its
    // result: `lid` is unique in the workgroup, so it names that invocation. (No
    // subgroupElect: naga 30 has none.)
    let first = subgroupBroadcastFirst(lid);
    var base = 0u;
    if (lid == first && total > 0u) {
        base = atomicAdd(&counters[slot], total);
    }
    return subgroupBroadcastFirst(base) + before;
}
