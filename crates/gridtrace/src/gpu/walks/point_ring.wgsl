// The nearest-point search of a lattice of cells (the grid's cells, the irregular grid's top
// cells), written once for the walks that include this file and the same search as the CPU's
// (`accel/closest/shells.rs`, whose notes give the bounds). Each walk defines
// `point_ring_cell(l, p, cell, best, work) -> i32`, which searches one cell and returns how
// many cells a walk along a row may advance (1, or more where the cell knows that many cells
// around it are empty: a Chebyshev distance, which holds along every axis and either way).
//
// Two phases, as on the CPU. Rings, from `first_ring`, until one holds a triangle; then the
// cells of the ball of the best distance outside the rings visited, row by row along x, nearest
// rows first, each row walked outward from the point and ended where the ball is.
//
// **Why not rings to the end.** Searching ring after ring until the next ring's bound passes
// the best distance enumerates every row of every ring, most of them outside the ball, and
// steps cell by cell over the part of a ring's row left of the ball: loop iterations grow as
// the cube of the rings searched, not as the cells the ball holds. For points in the Stanford
// Bunny's box grown by 10% the uniform grid's search ran up to 62,000 cells and triangles, and
// more iterations: past the 65,535 loop iterations in all that Mesa 22's llvmpipe gives an
// invocation before it silently ends its loops, so 14% of those points got `inf` or a farther
// triangle there (issue 55). The ball's rows are the ones its box spans, and a row's walk stops
// at the ball's edge, so iterations follow the cells searched. `point_steps` counts them.

// Ring `r` around cell `c`, clipped to the lattice: the rows of its two z faces and two y faces
// along x (clipped to the ball of the best distance), and the two cells of its x faces in the
// other rows.
fn lattice_point_ring(l: PointLattice, p: vec3<f32>, c: vec3<i32>, r: i32,
                      best: ptr<function, GpuHit>, work: ptr<function, u32>) {
    let lo = max(c - r, vec3<i32>(0));
    let hi = min(c + r, l.dims - 1);
    for (var z = lo.z; z <= hi.z; z++) {
        point_steps += 1u;
        let dz = lattice_slab_dist(l, p, 2, z);
        if (dz * dz > (*best).t) { continue; }
        for (var y = lo.y; y <= hi.y; y++) {
            point_steps += 1u;
            let dy = lattice_slab_dist(l, p, 1, y);
            let yz = dz * dz + dy * dy;
            if (yz > (*best).t) { continue; }
            if (abs(z - c.z) == r || abs(y - c.y) == r) {
                lattice_point_walk(l, p, y, z, yz, lo.x, hi.x, 1, best, work);
            } else {
                if (c.x - r >= 0) { point_ring_cell(l, p, vec3<i32>(c.x - r, y, z), best, work); }
                if (c.x + r < l.dims.x) { point_ring_cell(l, p, vec3<i32>(c.x + r, y, z), best, work); }
            }
        }
    }
}

// Cells `start`, `start + step`, ... of row (y, z) while in `[x0, x1]` and within the ball of the
// best distance (`yz`: the row's squared distance on y and z), advancing by what the cells say.
// Starting at or beside the point's cell and walking away from it, the cells only get farther:
// the first one outside the ball ends the walk.
fn lattice_point_walk(l: PointLattice, p: vec3<f32>, y: i32, z: i32, yz: f32, start: i32, x1: i32,
                      step: i32, best: ptr<function, GpuHit>, work: ptr<function, u32>) {
    var x = start;
    let x0 = select(0, start, step > 0);
    let x_hi = select(start, x1, step > 0);
    while (x >= x0 && x <= x_hi) {
        point_steps += 1u;
        let dx = lattice_slab_dist(l, p, 0, x);
        if (dx * dx + yz > (*best).t) {
            // Past the point, every later cell of the row is farther still; before it (a ring's
            // row walked from its left end), the ball is still ahead.
            if (step < 0 || l.min.x + f32(x) * l.cell.x > p.x) { break; }
            x += 1;
            continue;
        }
        x += step * max(point_ring_cell(l, p, vec3<i32>(x, y, z), best, work), 1);
    }
}

// Row (y, z) of the ball (`shells::search`'s phase two): outward from the point's cell along x,
// or from the faces of the block of rings `0..=done` where the row goes through it.
fn lattice_ball_row(l: PointLattice, p: vec3<f32>, c: vec3<i32>, done: i32, y: i32, z: i32, dz2: f32,
                    best: ptr<function, GpuHit>, work: ptr<function, u32>) {
    let dy = lattice_slab_dist(l, p, 1, y);
    let yz = dz2 + dy * dy;
    if (yz > (*best).t) { return; }
    var right = c.x;
    var left = c.x - 1;
    if (abs(y - c.y) <= done && abs(z - c.z) <= done) {
        right = c.x + done + 1;
        left = c.x - done - 1;
    }
    lattice_point_walk(l, p, y, z, yz, right, l.dims.x - 1, 1, best, work);
    lattice_point_walk(l, p, y, z, yz, left, l.dims.x - 1, -1, best, work);
}

// The slab z of the ball: its rows y0..=y1 outward from the point's row.
fn lattice_ball_slab(l: PointLattice, p: vec3<f32>, c: vec3<i32>, done: i32, z: i32, y0: i32, y1: i32,
                     best: ptr<function, GpuHit>, work: ptr<function, u32>) {
    let dz = lattice_slab_dist(l, p, 2, z);
    if (dz * dz > (*best).t) { return; }
    let cy = clamp(c.y, y0, y1);
    let span = max(y1 - cy, cy - y0);
    for (var k = 0; k <= span; k++) {
        point_steps += 1u;
        if (cy + k <= y1) { lattice_ball_row(l, p, c, done, cy + k, z, dz * dz, best, work); }
        if (k > 0 && cy - k >= y0) { lattice_ball_row(l, p, c, done, cy - k, z, dz * dz, best, work); }
    }
}

// The nearest point to `p` in the lattice's cells (`shells::search`): rings from `first_ring`
// (the rings inside it must be empty) around `c`, the point's cell clamped into the lattice,
// until one holds a triangle; then the ball of the best distance, less the rings visited.
fn lattice_point_search(l: PointLattice, p: vec3<f32>, c: vec3<i32>, first_ring: i32,
                        best: ptr<function, GpuHit>, work: ptr<function, u32>) {
    let out2 = lattice_out2(l, p);
    let last_ring = lattice_last_ring(l, c);
    var r = first_ring;
    // Phase one: whole rings until one holds a triangle.
    while (r <= last_ring && (*best).tri == MISS) {
        point_steps += 1u;
        lattice_point_ring(l, p, c, r, best, work);
        r += 1;
    }
    // Strict: a ring that may hold something as near as the best is still searched.
    if (r > last_ring || lattice_ring_bound(l, p, c, r, out2) > (*best).t) { return; }
    // Phase two: the ball, nearest slabs first (the best distance shrinks early and the later
    // slabs and rows are skipped without reading a cell).
    let done = r - 1;
    let reach = vec3<f32>(sqrt((*best).t)) + l.margin;
    let lo = lattice_cell_of(l, p - reach);
    let hi = lattice_cell_of(l, p + reach);
    let cz = clamp(c.z, lo.z, hi.z);
    let span = max(hi.z - cz, cz - lo.z);
    for (var k = 0; k <= span; k++) {
        point_steps += 1u;
        if (cz + k <= hi.z) { lattice_ball_slab(l, p, c, done, cz + k, lo.y, hi.y, best, work); }
        if (k > 0 && cz - k >= lo.z) { lattice_ball_slab(l, p, c, done, cz - k, lo.y, hi.y, best, work); }
    }
}
