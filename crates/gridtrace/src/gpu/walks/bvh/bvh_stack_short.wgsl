// The BVH walk's stack as a short ring in workgroup memory (`stack=short`): SHORT_STACK
// entries per thread (an override, at most SHORT_STACK_MAX), interleaved by lane so that a
// warp's accesses fall in different banks. A push onto a full ring drops its oldest (the
// shallowest) entry. When the ring runs dry after a drop, the walk climbs from where it was
// by parent links (`GpuBvhNode::child[2]`) to the deepest ancestor whose other child it has not
// walked yet and the ray still enters (Hapala et al. 2011's stackless step): exactly the
// entry a full stack would pop next, or one whose box the closest hit so far has since
// culled. So the walk visits what the private stack's walk visits, in the same order.
//
// Entries are positions, `node << 1 | slot` (the child is re-read from its parent's node: one
// word), so that the climb knows where it starts.

var<workgroup> bvh_ring: array<u32, SHORT_STACK_MAX * WORKGROUP>;

struct BvhStack {
    // Pushes minus pops, and the count of pushes below the ring (dropped or popped past);
    // entry k of the ring is at index k % SHORT_STACK.
    top: u32,
    bottom: u32,
    dropped: bool,
    // The position the walk is in: the child it last entered (STACK_DONE: the root).
    pos: u32,
}

fn bvh_stack_new() -> BvhStack {
    return BvhStack(0u, 0u, false, STACK_DONE);
}

fn bvh_push(st: ptr<function, BvhStack>, node: u32, slot: u32, entry: u32) {
    if ((*st).top - (*st).bottom == SHORT_STACK) {
        (*st).bottom += 1u;
        (*st).dropped = true;
    }
    bvh_ring[((*st).top % SHORT_STACK) * WORKGROUP + lane] = (node << 1u) | slot;
    (*st).top += 1u;
}

fn bvh_at(st: ptr<function, BvhStack>, node: u32, slot: u32) {
    (*st).pos = (node << 1u) | slot;
}

fn bvh_pop(st: ptr<function, BvhStack>, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_box: f32) -> u32 {
    if ((*st).top > (*st).bottom) {
        (*st).top -= 1u;
        let p = bvh_ring[((*st).top % SHORT_STACK) * WORKGROUP + lane];
        (*st).pos = p;
        return bvh_nodes[p >> 1u].child[p & 1u];
    }
    if (!(*st).dropped) { return STACK_DONE; }
    // Climb: the walk has finished the subtree at `p`. If that was its parent's first child
    // (the nearer, as the descent ordered them) and the ray still enters the second, the
    // second is next; else the parent is finished too.
    var p = (*st).pos;
    while (p != STACK_DONE) {
        let node = p >> 1u;
        let slot = p & 1u;
        let n = bvh_nodes[node];
        let h = bvh_enter(n, o, inv, t_min, t_box);
        let first = select(1u, 0u, h.t0 <= h.t1);
        let other_hit = select(h.hit0, h.hit1, slot == 0u);
        if (slot == first && other_hit) {
            (*st).pos = (node << 1u) | (1u - slot);
            return n.child[1u - slot];
        }
        p = n.child.z;
    }
    (*st).pos = STACK_DONE;
    return STACK_DONE;
}
