// The generalised winding number of each point of queue A (compute_winding_number, the sign of
// signed distance and occupancy; gpu/winding.rs): the CPU's fast winding tree
// (accel/winding/wide.rs) as it lies in memory, walked as the CPU walks it. A node's eight
// children are seen from the point: one farther than `accuracy` times its radius adds its
// second-order expansion (Barill et al. 2018, libigl's terms); a nearer one is opened, a leaf
// through the exact solid angles of its block's triangles (Van Oosterom and Strackee), an
// inner node pushed. The sum is in f32, as the CPU's lanes sum it.
//
// The answer goes to the batch's `answers` as the winding number's bits (4 bytes a point);
// the batch's `t_max` is accuracy squared (`Query::Winding`). A stack deeper than
// WIND_STACK is refused on the host (`DeviceTree::stack`), so no push here is lost.

@group(1) @binding(1) var<storage, read_write> answers: array<u32>;
@group(1) @binding(2) var<uniform> batch: BatchUniform;

// A node: 26 rows of eight children's coefficients (`Moment::coefficients`: centre, radius
// squared, the dipole, the quadratic and cubic terms), then the eight children (a node's
// index, WIND_LEAF | a block's, or WIND_EMPTY: the host's values, in the prelude).
struct WindNode { rows: array<array<f32, 8>, 26>, child: array<u32, 8> }
// A leaf's triangles, a lane each: vertex, then axis (an unused lane repeats one vertex: its
// angle is 0).
struct WindBlock { v: array<array<array<f32, 8>, 3>, 3> }

@group(2) @binding(0) var<storage, read> wind_nodes: array<WindNode>;
@group(2) @binding(1) var<storage, read> wind_blocks: array<WindBlock>;


// Child `k` of node `i` seen from `p`: its expansion where it is far (`far` set), else 0.
fn wind_far(i: u32, k: u32, p: vec3<f32>, accuracy2: f32, far: ptr<function, bool>) -> f32 {
    let c = vec3<f32>(wind_nodes[i].rows[0][k], wind_nodes[i].rows[1][k], wind_nodes[i].rows[2][k]);
    let q = c - p;
    let d2 = dot(q, q);
    *far = false;
    if (!(d2 > accuracy2 * wind_nodes[i].rows[3][k])) { return 0.0; }
    let inv2 = 1.0 / d2;
    let inv1 = sqrt(inv2);
    let x = q.x * inv1;
    let y = q.y * inv1;
    let z = q.z * inv1;
    let r = &wind_nodes[i].rows;
    let order0 = ((*r)[4][k] * x + (*r)[5][k] * y + (*r)[6][k] * z) * inv2;
    let quad = (*r)[7][k] * x * x + (*r)[8][k] * y * y + (*r)[9][k] * z * z
        + (*r)[10][k] * (x * y) + (*r)[11][k] * (y * z) + (*r)[12][k] * (z * x);
    let order1 = ((*r)[7][k] + (*r)[8][k] + (*r)[9][k] - 3.0 * quad) * (inv2 * inv1);
    let lin = (*r)[13][k] * x + (*r)[14][k] * y + (*r)[15][k] * z;
    let cubic = (*r)[16][k] * (x * x * x) + (*r)[17][k] * (y * y * y) + (*r)[18][k] * (z * z * z)
        + (*r)[19][k] * (x * x * y) + (*r)[20][k] * (x * x * z) + (*r)[21][k] * (y * y * x)
        + (*r)[22][k] * (y * y * z) + (*r)[23][k] * (z * z * x) + (*r)[24][k] * (z * z * y)
        + (*r)[25][k] * (x * y * z);
    let order2 = (7.5 * cubic - 1.5 * lin) * (inv2 * inv2);
    let omega = order0 + order1 + order2;
    // A point so close to a tiny cluster that the powers overflow opens it instead (as the
    // CPU: `abs < inf` is false for NaN and infinities alike).
    if (!(abs(omega) < inf())) { return 0.0; }
    *far = true;
    return omega;
}

// The exact solid angle at `p` of lane `k` of block `b`.
fn wind_angle(b: u32, k: u32, p: vec3<f32>) -> f32 {
    let v0 = vec3<f32>(wind_blocks[b].v[0][0][k], wind_blocks[b].v[0][1][k], wind_blocks[b].v[0][2][k]);
    let v1 = vec3<f32>(wind_blocks[b].v[1][0][k], wind_blocks[b].v[1][1][k], wind_blocks[b].v[1][2][k]);
    let v2 = vec3<f32>(wind_blocks[b].v[2][0][k], wind_blocks[b].v[2][1][k], wind_blocks[b].v[2][2][k]);
    let a = v0 - p;
    let bb = v1 - p;
    let c = v2 - p;
    // The triple product against the edges' cross product (no cancellation of large terms).
    let num = dot(a, cross(v1 - v0, v2 - v0));
    let la = length(a);
    let lb = length(bb);
    let lc = length(c);
    let den = la * lb * lc + dot(a, bb) * lc + dot(bb, c) * la + dot(c, a) * lb;
    // atan2(0, 0) (the point on a vertex, or an unused lane there) is 0, as the CPU's lanes.
    if (num == 0.0 && den == 0.0) { return 0.0; }
    return 2.0 * atan2(num, den);
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    if (i >= queue_len(pass_.in_slot)) { return; }
    let p = rays_in[i].origin;
    let accuracy2 = batch.t_max;
    var stack: array<u32, WIND_STACK>;
    var sp = 1u;
    stack[0] = 0u;
    var sum = 0.0;
    while (sp > 0u) {
        sp -= 1u;
        let node = stack[sp];
        for (var k = 0u; k < 8u; k++) {
            let child = wind_nodes[node].child[k];
            if (child == WIND_EMPTY) { continue; }
            var far = false;
            let omega = wind_far(node, k, p, accuracy2, &far);
            if (far) {
                sum += omega;
            } else if ((child & WIND_LEAF) != 0u) {
                let b = child & ~WIND_LEAF;
                for (var t = 0u; t < 8u; t++) {
                    sum += wind_angle(b, t, p);
                }
            } else if (sp < WIND_STACK) {
                stack[sp] = child;
                sp += 1u;
            }
        }
    }
    // 4 pi steradians a turn.
    answers[i] = bitcast<u32>(sum * 0.07957747154594767);
}
