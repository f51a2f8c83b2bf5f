// The BVH walk's stack as a private array of BVH_STACK entries (`stack=private`, the default):
// the builder bounds the tree's depth below it for any input (SAH splits to depth 64, median
// splits after), and the upload checks the depth, so a push can never overflow; the guard
// below only keeps the index in bounds. A private array indexed at run time lives in the
// thread's local memory on GPUs (cached in L1); a walk touches only its top few entries.
// It holds the entries themselves (a node's index or a leaf's entry).

struct BvhStack { sp: u32, items: array<u32, BVH_STACK> }

fn bvh_stack_new() -> BvhStack {
    var st: BvhStack;
    st.sp = 0u;
    return st;
}

// Saves child `slot` of inner node `node`, whose entry is `entry`, for later.
fn bvh_push(st: ptr<function, BvhStack>, node: u32, slot: u32, entry: u32) {
    if ((*st).sp < BVH_STACK) {
        (*st).items[(*st).sp] = entry;
        (*st).sp += 1u;
    }
}

// The walk enters child `slot` of `node` (the short stack's climb starts from there).
fn bvh_at(st: ptr<function, BvhStack>, node: u32, slot: u32) {}

// The entry the walk goes on with after the subtree it was in: the top of the stack, or
// STACK_DONE when it is empty.
fn bvh_pop(st: ptr<function, BvhStack>, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_box: f32) -> u32 {
    if ((*st).sp == 0u) { return STACK_DONE; }
    (*st).sp -= 1u;
    return (*st).items[(*st).sp];
}
