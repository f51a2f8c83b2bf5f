// The wide BVH walk's stack as a short ring in workgroup memory (`stack=short`; see
// bvh_stack_short.wgsl): a push onto a full ring drops the oldest group. When the ring runs
// dry after a drop, the walk climbs from the finished node by parent links (`info.w`): at each
// ancestor, the children after the one it came from (in the ray's visiting order) that the ray
// still enters are the next group; an ancestor with none is finished too. Every group on a
// stack belongs to an ancestor of the walk's node, so this finds the group a full stack would
// pop next (less any child the closest hit so far has since culled).

var<workgroup> bvh8_ring: array<u32, SHORT_STACK_MAX * WORKGROUP>;

struct Bvh8Stack { top: u32, bottom: u32, dropped: bool }

fn bvh8_stack_new() -> Bvh8Stack {
    return Bvh8Stack(0u, 0u, false);
}

fn bvh8_push(st: ptr<function, Bvh8Stack>, group: u32) {
    if ((*st).top - (*st).bottom == SHORT_STACK) {
        (*st).bottom += 1u;
        (*st).dropped = true;
    }
    bvh8_ring[((*st).top % SHORT_STACK) * WORKGROUP + lane] = group;
    (*st).top += 1u;
}

fn bvh8_pop(st: ptr<function, Bvh8Stack>, node: u32, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_box: f32,
            oct: u32, work: ptr<function, u32>) -> u32 {
    if ((*st).top > (*st).bottom) {
        (*st).top -= 1u;
        return bvh8_ring[((*st).top % SHORT_STACK) * WORKGROUP + lane];
    }
    if (!(*st).dropped) { return STACK_DONE; }
    var up = bvh8_nodes[node].info.w;
    while (up != STACK_DONE) {
        let parent = up >> 3u;
        let rank = (up & 7u) ^ oct;
        let n = bvh8_nodes[parent];
        if (COUNT_WORK) { *work += 1u; }
        let rest = bvh8_hits(n, o, inv, t_min, t_box, oct) & ~((2u << rank) - 1u);
        if (rest != 0u) { return (parent << 8u) | rest; }
        up = n.info.w;
    }
    return STACK_DONE;
}
