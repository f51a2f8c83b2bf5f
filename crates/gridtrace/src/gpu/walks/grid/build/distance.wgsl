// The proximity cloud on the GPU: the chessboard distance transform of cell occupancy as three
// passes, one per axis, one invocation per line of cells along that axis. Each line runs the
// same linear-time lower-envelope algorithm as the CPU (`proximity::chessboard_1d`, Meijster,
// Roerdink and Hesselink 2000): pass x reads occupancy (`count > 0`) and writes `dt_a`, pass y
// reads `dt_a` and writes `dt_b`, pass z reads `dt_b` and writes the cells' `dist`. A line's
// envelope stack lives in `stack`, at the line's own `len` entries.

@group(0) @binding(2) var<storage, read_write> cells: array<Cell>;
@group(0) @binding(5) var<storage, read_write> dt_a: array<i32>;
@group(0) @binding(6) var<storage, read_write> dt_b: array<i32>;
// (s, t) of the envelope: the index of the function that is lowest from position t on.
@group(0) @binding(7) var<storage, read_write> stack: array<vec2<i32>>;

var<private> line_start: u32;
var<private> line_stride: u32;
var<private> inf: i32;

fn g(i: i32) -> i32 {
    let idx = line_start + u32(i) * line_stride;
    switch P.axis {
        case 0u: {
            return select(inf, 0, cells[idx].count > 0u);
        }
        case 1u: {
            return dt_a[idx];
        }
        default: {
            return dt_b[idx];
        }
    }
}

fn put(u: i32, d: i32) {
    let idx = line_start + u32(u) * line_stride;
    switch P.axis {
        case 0u: {
            dt_a[idx] = d;
        }
        case 1u: {
            dt_b[idx] = d;
        }
        default: {
            cells[idx].dist = select(u32(d), DIST_FAR, d >= inf);
        }
    }
}

fn f(x: i32, i: i32) -> i32 {
    return max(abs(x - i), g(i));
}

// First position from which f_u is no larger than f_i (i < u).
fn sep(i: i32, u: i32) -> i32 {
    let gi = g(i);
    let gu = g(u);
    if gi <= gu {
        return max(i + gu, (i + u) / 2);
    }
    return min(u - gi, (i + u) / 2);
}

@compute @workgroup_size(WORKGROUP)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let line = flat_id(wg, nwg, lid, WORKGROUP);
    if line >= P.n {
        return;
    }
    let d = P.dims;
    var len: u32;
    switch P.axis {
        case 0u: {
            len = d.x;
            line_start = line * d.x;
            line_stride = 1u;
        }
        case 1u: {
            len = d.y;
            line_start = line % d.x + (line / d.x) * d.x * d.y;
            line_stride = d.x;
        }
        default: {
            len = d.z;
            line_start = line;
            line_stride = d.x * d.y;
        }
    }
    // Larger than any real distance (as the CPU's `inf`).
    inf = i32(d.x + d.y + d.z) + 1;
    let m = i32(len);
    let base = line * len;
    var q = 0;
    stack[base] = vec2<i32>(0, 0);
    for (var u = 1; u < m; u++) {
        loop {
            if q < 0 {
                break;
            }
            let st = stack[base + u32(q)];
            if f(st.y, st.x) > f(st.y, u) {
                q -= 1;
            } else {
                break;
            }
        }
        if q < 0 {
            q = 0;
            stack[base] = vec2<i32>(u, 0);
        } else {
            let w = 1 + sep(stack[base + u32(q)].x, u);
            if w < m {
                q += 1;
                stack[base + u32(q)] = vec2<i32>(u, w);
            }
        }
    }
    for (var u = m - 1; u >= 0; u--) {
        let st = stack[base + u32(q)];
        put(u, min(f(u, st.x), inf));
        if u == st.y {
            q -= 1;
        }
    }
}
