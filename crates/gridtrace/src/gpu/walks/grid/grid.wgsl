// The uniform grid's walk: Amanatides-Woo 3D-DDA over `cells`, with proximity-cloud jumps when
// the pass says `pc` (`pass_.accel == ACCEL_PC`); mirrors accel/grid/dda.rs. Group 1 holds the
// grid's arrays (gpu/walks/grid/mod.rs uploads them in this order).

struct Cell { start: u32, count: u32, dist: u32 }

@group(1) @binding(0) var<storage, read> cells: array<Cell>;
// The cells' triangle lists, cell after cell.
@group(1) @binding(1) var<storage, read> grid_refs: array<u32>;

// 3D-DDA state; mirrors GridAccel::walk. `lat` is the grid's lattice: the scene's, or one
// mesh's in a scene of two levels (`grid_closest_in`).
struct Dda {
    lat: Lattice,
    o: vec3<f32>, d: vec3<f32>, inv_d: vec3<f32>,
    cell: vec3<i32>, step: vec3<i32>, ahead: vec3<i32>,
    t_next: vec3<f32>, t_leave: f32, budget: u32,
    cells_visited: u32, jumps: u32,
}

fn boundary_t(s: ptr<function, Dda>, axis: i32, k: i32) -> f32 {
    if ((*s).step[axis] == 0) { return inf(); }
    return ((*s).lat.lo[axis] + f32(k) * (*s).lat.cell[axis] - (*s).o[axis]) * (*s).inv_d[axis];
}

fn refresh_t_next(s: ptr<function, Dda>) {
    (*s).t_next = vec3<f32>(
        boundary_t(s, 0, (*s).cell.x + (*s).ahead.x),
        boundary_t(s, 1, (*s).cell.y + (*s).ahead.y),
        boundary_t(s, 2, (*s).cell.z + (*s).ahead.z));
}


// Starts the walk; returns false if the ray misses the grid within [t_min, t_max].
fn dda_start(s: ptr<function, Dda>, lat: Lattice, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    (*s).lat = lat;
    (*s).o = o;
    (*s).d = d;
    (*s).inv_d = 1.0 / d;
    let c = clip_lattice(lat, o, (*s).inv_d, d, t_min, t_max);
    if (c.z == 0.0) { return false; }
    (*s).t_leave = c.y;
    (*s).step = vec3<i32>(sign(d));
    (*s).ahead = max((*s).step, vec3<i32>(0));
    let dims = vec3<i32>(lat.dims);
    (*s).cell = clamp(lattice_cell(lat, o + d * c.x), vec3<i32>(0), dims - 1);
    refresh_t_next(s);
    (*s).budget = u32(dims.x + dims.y + dims.z) * 2u + 8u;
    (*s).cells_visited = 0u;
    (*s).jumps = 0u;
    return true;
}

fn cell_index(l: Lattice, c: vec3<i32>) -> u32 {
    return l.first_cell + u32(c.x) + l.dims.x * (u32(c.y) + l.dims.y * u32(c.z));
}

// Leaves the current cell (whose record is `cell`): a proximity-cloud jump over the empty cube
// around an empty cell with dist >= 2, else one DDA step. Returns false when the walk is over.
fn dda_advance(s: ptr<function, Dda>, cell: Cell, t_exit: f32, use_pc: bool) -> bool {
    let dims = vec3<i32>((*s).lat.dims);
    if (use_pc && cell.count == 0u && cell.dist >= 2u) {
        let k = i32(min(cell.dist - 1u, JUMP_CAP));
        let cur = (*s).cell;
        let t_cube = vec3<f32>(
            boundary_t(s, 0, cur.x + (*s).ahead.x + (*s).step.x * k),
            boundary_t(s, 1, cur.y + (*s).ahead.y + (*s).step.y * k),
            boundary_t(s, 2, cur.z + (*s).ahead.z + (*s).step.z * k));
        let t_jump = min3(t_cube);
        if (t_jump >= (*s).t_leave) { return false; }
        (*s).jumps += 1u;
        let axis = min_position(t_cube);
        var next = clamp(lattice_cell((*s).lat, (*s).o + (*s).d * t_jump), cur - k, cur + k);
        next[axis] = cur[axis] + (*s).step[axis] * (k + 1);
        (*s).cell = next;
        if (any(next < vec3<i32>(0)) || any(next >= dims)) { return false; }
        refresh_t_next(s);
        if ((*s).budget <= 1u) { return false; }
        (*s).budget -= 1u;
        return true;
    }
    if (t_exit >= (*s).t_leave) { return false; }
    let axis = min_position((*s).t_next);
    (*s).cell[axis] += (*s).step[axis];
    if ((*s).cell[axis] < 0 || (*s).cell[axis] >= dims[axis]) { return false; }
    (*s).t_next[axis] = boundary_t(s, axis, (*s).cell[axis] + (*s).ahead[axis]);
    if ((*s).budget <= 1u) { return false; }
    (*s).budget -= 1u;
    return true;
}

// Closest hit with t_min <= t < t_max; mirrors GridAccel::intersect. `work` gets the cost
// (cells visited + triangle tests) when COUNT_WORK is set. The triangle is the lattice's mesh's
// own (`tris` from `lat.first_tri` on).
fn closest_hit(lat: Lattice, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, use_pc: bool, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(t_max, MISS, 0.0, 0.0);
    var s: Dda;
    if (!dda_start(&s, lat, o, d, t_min, t_max)) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    loop {
        if (COUNT_WORK) { *work += 1u; }
        let t_exit = min3(s.t_next);
        let cell = cells[cell_index(lat, s.cell)];
        if (cell.count > 0u) {
            for (var i = cell.start; i < cell.start + cell.count; i++) {
                if (COUNT_WORK) { *work += 1u; }
                let tri = grid_refs[i];
                let h = intersect_tri(tris[tri], o, d, t_min, leaf_bound(best.t));
                if (h.w != 0.0 && leaf_takes(h.x, tri, best, lat.first_tri)) { best = GpuHit(h.x, tri, h.y, h.z); }
            }
            if (best.tri != MISS && best.t <= min(t_exit, s.t_leave)) { break; }
        }
        if (!dda_advance(&s, cell, t_exit, use_pc)) { break; }
    }
    if (best.tri == MISS) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    best.tri -= lat.first_tri;
    return best;
}

// Any hit with t_min <= t < t_max; mirrors GridAccel::occluded.
fn any_hit(lat: Lattice, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, use_pc: bool) -> bool {
    var s: Dda;
    if (!dda_start(&s, lat, o, d, t_min, t_max)) { return false; }
    loop {
        let t_exit = min3(s.t_next);
        let cell = cells[cell_index(lat, s.cell)];
        for (var i = cell.start; i < cell.start + cell.count; i++) {
            let h = intersect_tri(tris[grid_refs[i]], o, d, t_min, t_max);
            if (h.w != 0.0) { return true; }
        }
        if (!dda_advance(&s, cell, t_exit, use_pc)) { break; }
    }
    return false;
}

// The walk's two entry points (gpu/walks/mod.rs calls them from walk_closest and walk_any),
// over the scene's lattice; a scene of two levels calls `closest_hit` and `any_hit` with each
// mesh's (grid_rows.wgsl).
fn grid_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    return closest_hit(scene_lattice(), o, d, t_min, t_max, pass_.accel == ACCEL_PC, work);
}
fn grid_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    return any_hit(scene_lattice(), o, d, t_min, t_max, pass_.accel == ACCEL_PC);
}

// ---- Closest points (accel/grid/closest.rs, accel/closest/shells.rs) ----
//
// The nearest point to `p`, by the lattice search of point_ring.wgsl, as Grid::closest_point
// searches: the point's cell's proximity distance `d` says the rings inside ring `d` are empty,
// so the search starts there, and a row jumps over the empty cells an empty cell's distance
// vouches for. Both grid structures: the plain grid's cells carry the distances too (its ray
// walk alone ignores them). Bounds and cell boxes are grown by the fill margin
// (`point_cell_margin`), and pruning is strict, so every triangle as near as the best is
// measured and the tie rule decides as on the CPU.

// The lattice search's cell (`lattice_point_search`, point_ring.wgsl): measures the triangles of
// cell `cc` if its grown box may hold something nearer than `best`. Returns how many cells a row
// may advance: an empty cell's proximity distance (the cells that close are empty too), else 1.
fn point_ring_cell(l: PointLattice, p: vec3<f32>, cc: vec3<i32>,
                   best: ptr<function, GpuHit>, work: ptr<function, u32>) -> i32 {
    *work += 1u;
    let cell = cells[cell_index(scene_lattice(), cc)];
    if (cell.count == 0u) {
        return i32(clamp(cell.dist, 1u, scene.dims.x));
    }
    let lo = l.min + vec3<f32>(cc) * l.cell;
    if (point_box_dist_sq(p, lo - l.margin, lo + l.cell + l.margin) > (*best).t) { return 1; }
    for (var i = cell.start; i < cell.start + cell.count; i++) {
        *work += 1u;
        point_steps += 1u;
        point_offer(best, grid_refs[i], p);
    }
    return 1;
}

// The nearest point to `p`; mirrors Grid::closest_point (the same answer, tie rule included).
fn grid_closest_point(p: vec3<f32>, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(inf(), MISS, 0.0, 0.0);
    let dims = vec3<i32>(scene.dims);
    let l = PointLattice(scene.bounds_min, scene.cell_size, dims, point_cell_margin(scene.cell_size));
    let c = lattice_cell_of(l, p);
    let d = cells[cell_index(scene_lattice(), c)].dist;
    // FAR (u32::MAX): no cell holds a triangle.
    if (d == MISS) { return best; }
    lattice_point_search(l, p, c, i32(min(d, u32(dims.x + dims.y + dims.z))), &best, work);
    return best;
}
