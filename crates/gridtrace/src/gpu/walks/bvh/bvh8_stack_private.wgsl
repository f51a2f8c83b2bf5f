// The wide BVH walk's stack as a private array (`stack=private`): one group per level at most,
// and the wide tree is no deeper than the binary one (BVH_STACK bounds that).

struct Bvh8Stack { sp: u32, items: array<u32, BVH_STACK> }

fn bvh8_stack_new() -> Bvh8Stack {
    var st: Bvh8Stack;
    st.sp = 0u;
    return st;
}

fn bvh8_push(st: ptr<function, Bvh8Stack>, group: u32) {
    if ((*st).sp < BVH_STACK) {
        (*st).items[(*st).sp] = group;
        (*st).sp += 1u;
    }
}

// The next group after node `node` is finished: the top of the stack, or STACK_DONE.
fn bvh8_pop(st: ptr<function, Bvh8Stack>, node: u32, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_box: f32,
            oct: u32, work: ptr<function, u32>) -> u32 {
    if ((*st).sp == 0u) { return STACK_DONE; }
    (*st).sp -= 1u;
    return (*st).items[(*st).sp];
}
