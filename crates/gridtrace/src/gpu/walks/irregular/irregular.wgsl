// Irregular grid traversal: closest and any hit, mirroring IrregularGrid::walk (accel/irregular/
// walk.rs) step for step, and using the same triangle test as the grid (`intersect_tri`).
//
// No DDA: the walk looks up the cell under its current voxel (the top cell's entry, then that
// top cell's voxel map), tests the cell's triangles, and leaves the cell's grown box in one
// step. The walk's lattice (the scene uniform's lattice fields, or a mesh's row of the lattice
// table in a scene of two levels) is the virtual voxels here (`dims` voxels per axis of
// `cell`, `shift` levels below the top cells), so `lattice_cell` maps a point to its voxel
// exactly as the CPU's `world_to_voxel` does (same host-computed reciprocal).
//
// Why it terminates and misses nothing in floating point (walk.rs says it at length): the next
// voxel is never found by rounding the exit point alone. On the exit axis it is the voxel just
// past the grown box's face, in integers; on the other axes the exit point's voxel clamped into
// the box's range and never behind the current voxel in the ray's direction. Every step moves
// forward on one axis and back on none, so `sum(dims)` steps bound the walk; the budget is
// there all the same, as in the DDA. Where rounding puts the ray a voxel off near a face, the
// build's `cell_margin` put the triangles that close to the face in both cells.

// An irregular-grid cell as stored (IrrCell in accel/irregular/mod.rs): its grown box in virtual
// voxels as six 16-bit coordinates (`min.x | min.y << 16, min.z | max.x << 16, max.y | max.z <<
// 16`) and the first of its `refs`, which end where the next cell's start (the array ends with
// a sentinel cell). A vec3<u32> in storage is 16-byte aligned with a 4-byte scalar after it, so
// this is the Rust layout: 16 bytes, one load. `irr_cell` unpacks it.
struct IrrCell { bounds: vec3<u32>, start: u32 }

// Group 1 is declared by the file after this one, with the functions that read it: the cells
// (`irr_cells`), a top cell's entry (`irr_entry`: `begin << IRR_LEVEL_BITS | level`), a voxel
// map's entry (`irr_voxel`) and a reference (`irr_ref`). One level: arrays.wgsl, the scene's
// four arrays; two levels: two_level/irregular_rows.wgsl, every mesh's in shared arrays with
// its lattice in a row of a table.

// The walk's state. `lat` is the grid's lattice of virtual voxels: the scene's, or one mesh's in
// a scene of two levels (`irr_closest_in`).
struct IrrWalk {
    lat: Lattice,
    o: vec3<f32>, d: vec3<f32>, inv_d: vec3<f32>,
    // The voxel the walk is in, and the sign of the direction per axis (0: parallel).
    v: vec3<i32>, step: vec3<i32>,
    t_leave: f32, budget: u32,
}

// A cell unpacked (`IrregularGrid::cell`): its grown box (`min` inclusive, `max` exclusive) and
// its slice of `refs`.
struct IrrBox { min: vec3<u32>, max: vec3<u32>, start: u32, count: u32 }
fn irr_cell(id: u32) -> IrrBox {
    let c = irr_cells[id];
    let end = irr_cells[id + 1u].start;
    let lo = vec3<u32>(c.bounds.x & IRR_COORD_MASK, c.bounds.x >> IRR_COORD_BITS, c.bounds.y & IRR_COORD_MASK);
    let hi = vec3<u32>(c.bounds.y >> IRR_COORD_BITS, c.bounds.z & IRR_COORD_MASK, c.bounds.z >> IRR_COORD_BITS);
    return IrrBox(lo, hi, c.start, end - c.start);
}

// The index of the cell holding voxel `v` (inside the grid of `l`); mirrors
// IrregularGrid::cell_at.
fn irr_cell_at(l: Lattice, v: vec3<u32>) -> u32 {
    let s = l.shift;
    let top = v >> vec3<u32>(s);
    let t = l.dims >> vec3<u32>(s);
    let entry = irr_entry(l, top.x + t.x * (top.y + t.y * top.z));
    let level = entry & ((1u << IRR_LEVEL_BITS) - 1u);
    let begin = entry >> IRR_LEVEL_BITS;
    let local = (v & vec3<u32>((1u << s) - 1u)) >> vec3<u32>(s - level);
    return irr_voxel(l, begin + local.x + (local.y << level) + (local.z << (2u * level)));
}

// The parameter where the ray crosses voxel plane `k` of `axis`: from the integer plane index
// each time, as the DDA's `boundary_t`, so nothing accumulates; infinite along a parallel axis.
fn irr_plane_t(w: ptr<function, IrrWalk>, axis: i32, k: u32) -> f32 {
    if ((*w).step[axis] == 0) { return inf(); }
    return ((*w).lat.lo[axis] + f32(k) * (*w).lat.cell[axis] - (*w).o[axis]) * (*w).inv_d[axis];
}

// Starts the walk at the voxel of the entry point, clamped into the grid (the entry point lies
// on the box within rounding); false if the ray misses the grid within [t_min, t_max].
fn irr_start(w: ptr<function, IrrWalk>, lat: Lattice, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    (*w).lat = lat;
    (*w).o = o;
    (*w).d = d;
    (*w).inv_d = 1.0 / d;
    let c = clip_lattice(lat, o, (*w).inv_d, d, t_min, t_max);
    if (c.z == 0.0) { return false; }
    (*w).t_leave = c.y;
    (*w).step = vec3<i32>(sign(d));
    let dims = vec3<i32>(lat.dims);
    (*w).v = clamp(lattice_cell(lat, o + d * c.x), vec3<i32>(0), dims - 1);
    (*w).budget = u32(dims.x + dims.y + dims.z) + 8u;
    return true;
}

// Where the ray leaves `cell`'s grown box on each axis: through the face ahead.
fn irr_faces(w: ptr<function, IrrWalk>, cell: IrrBox) -> vec3<f32> {
    let face = select(cell.min, cell.max, (*w).step > vec3<i32>(0));
    return vec3<f32>(irr_plane_t(w, 0, face.x), irr_plane_t(w, 1, face.y), irr_plane_t(w, 2, face.z));
}

// Leaves `cell` (whose faces the ray crosses at `t_faces`) for the voxel just past its exit;
// false when the walk is over: the exit is past the grid's, the next voxel is outside the grid,
// or the budget is spent.
fn irr_advance(w: ptr<function, IrrWalk>, cell: IrrBox, t_faces: vec3<f32>) -> bool {
    let t_exit = min3(t_faces);
    if (t_exit >= (*w).t_leave) { return false; }
    let axis = min_position(t_faces);
    let at_exit = lattice_cell((*w).lat, (*w).o + (*w).d * t_exit);
    let lo = vec3<i32>(cell.min);
    let hi = vec3<i32>(cell.max) - 1;
    let v = (*w).v;
    let step = (*w).step;
    var next = v;
    for (var a = 0; a < 3; a++) {
        if (a == axis) {
            // The voxel past the face, in integers: never the cell just left.
            next[a] = select(lo[a] - 1, hi[a] + 1, step[a] > 0);
        } else if (step[a] != 0) {
            // The exact exit point is in the box, so its voxel is clamped into the box's range;
            // and the ray never moves back along an axis, whatever the rounding.
            let inside = clamp(at_exit[a], lo[a], hi[a]);
            next[a] = select(min(inside, v[a]), max(inside, v[a]), step[a] > 0);
        }
    }
    if (next[axis] < 0 || next[axis] >= i32((*w).lat.dims[axis])) { return false; }
    (*w).v = next;
    if ((*w).budget <= 1u) { return false; }
    (*w).budget -= 1u;
    return true;
}

// Closest hit with t_min <= t < t_max in the grid of `lat`; mirrors IrregularGrid::intersect.
// `work` gets the cost (cells visited + triangle tests) when COUNT_WORK is set, as the CPU's
// counters count it. The triangle is the lattice's mesh's own (`tris` from `lat.first_tri` on).
fn irr_closest_at(lat: Lattice, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(t_max, MISS, 0.0, 0.0);
    var w: IrrWalk;
    if (!irr_start(&w, lat, o, d, t_min, t_max)) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    loop {
        if (COUNT_WORK) { *work += 1u; }
        let cell = irr_cell(irr_cell_at(lat, vec3<u32>(w.v)));
        let t_faces = irr_faces(&w, cell);
        if (cell.count > 0u) {
            for (var i = cell.start; i < cell.start + cell.count; i++) {
                if (COUNT_WORK) { *work += 1u; }
                let tri = irr_ref(i);
                let h = intersect_tri(tris[tri], o, d, t_min, leaf_bound(best.t));
                if (h.w != 0.0 && leaf_takes(h.x, tri, best, lat.first_tri)) { best = GpuHit(h.x, tri, h.y, h.z); }
            }
            // As in the grid: a hit is final only inside the (grown) cell; a triangle that
            // reaches beyond it may hide a nearer one in a later cell.
            if (best.tri != MISS && best.t <= min(min3(t_faces), w.t_leave)) { break; }
        }
        if (!irr_advance(&w, cell, t_faces)) { break; }
    }
    if (best.tri == MISS) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    best.tri -= lat.first_tri;
    return best;
}

// Any hit with t_min <= t < t_max in the grid of `lat`; mirrors IrregularGrid::occluded.
fn irr_any_at(lat: Lattice, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    var w: IrrWalk;
    if (!irr_start(&w, lat, o, d, t_min, t_max)) { return false; }
    loop {
        let cell = irr_cell(irr_cell_at(lat, vec3<u32>(w.v)));
        for (var i = cell.start; i < cell.start + cell.count; i++) {
            if (intersect_tri(tris[irr_ref(i)], o, d, t_min, t_max).w != 0.0) { return true; }
        }
        if (!irr_advance(&w, cell, irr_faces(&w, cell))) { break; }
    }
    return false;
}

// The walk's two entry points (gpu/walks/mod.rs calls them from walk_closest and walk_any),
// over the scene's lattice; a scene of two levels calls `irr_closest_at` and `irr_any_at` with
// each mesh's (two_level/irregular_rows.wgsl: `irr_closest_in`, `irr_any_in`).
fn irr_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    return irr_closest_at(scene_lattice(), o, d, t_min, t_max, work);
}

fn irr_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    return irr_any_at(scene_lattice(), o, d, t_min, t_max);
}

// ---- Closest points (accel/irregular/closest.rs) ----
//
// By its cells, as the CPU searches them: the top cells (a uniform lattice, `dims >> shift`)
// searched by `lattice_point_search` (point_ring.wgsl): rings around the point's top cell until
// one holds a triangle, then the top cells of the ball of the best distance. A top cell whose
// box is near enough is searched through its voxel map (`2^level` entries per axis, each naming
// the merged cell covering it), the slabs and rows the ball's box spans, each row clipped to
// the ball; the entries a merged cell covers after the first are skipped (merged cells repeat
// along x; the row goes on from the cell's end), and a cell's triangles are measured only if
// its grown box may hold something nearer. A merged cell spanning several top cells is met once
// per top cell: its box test repeats, never an answer. Boxes and bounds are grown by twice the
// top cells' fill margin (`point_cell_margin`: at least the voxels' margin the cells were
// filled with); pruning is strict, so ties are all measured and the tie rule decides.

// Measures the triangles of cell `id` if its grown box, widened by `margin`, may hold
// something nearer than `best`. Returns the cell's end on x (its box's high voxel plane): the
// voxel-map entries before it on the row name this cell too.
fn irr_point_cell(id: u32, p: vec3<f32>, margin: vec3<f32>, best: ptr<function, GpuHit>, work: ptr<function, u32>) -> u32 {
    *work += 1u;
    let cell = irr_cell(id);
    if (cell.count == 0u) { return cell.max.x; }
    let lo = scene.bounds_min + vec3<f32>(cell.min) * scene.cell_size - margin;
    let hi = scene.bounds_min + vec3<f32>(cell.max) * scene.cell_size + margin;
    if (point_box_dist_sq(p, lo, hi) > (*best).t) { return cell.max.x; }
    for (var i = cell.start; i < cell.start + cell.count; i++) {
        *work += 1u;
        point_steps += 1u;
        point_offer(best, irr_ref(i), p);
    }
    return cell.max.x;
}

// Top cell `tc` of the top lattice `l`, if its box may hold something nearer than `best`: its
// voxel map's rows, each clipped to the ball of the best distance as the row starts.
fn irr_point_top(l: PointLattice, p: vec3<f32>, tc: vec3<i32>, best: ptr<function, GpuHit>, work: ptr<function, u32>) {
    *work += 1u;
    let lo = l.min + vec3<f32>(tc) * l.cell;
    if (point_box_dist_sq(p, lo - l.margin, lo + l.cell + l.margin) > (*best).t) { return; }
    let t = vec3<u32>(l.dims);
    let tcu = vec3<u32>(tc);
    let entry = irr_entry(scene_lattice(), tcu.x + t.x * (tcu.y + t.y * tcu.z));
    let level = entry & ((1u << IRR_LEVEL_BITS) - 1u);
    let begin = entry >> IRR_LEVEL_BITS;
    // One cell (empty space, most top cells): no loops (iterations count, point_ring.wgsl).
    if (level == 0u) {
        irr_point_cell(irr_voxel(scene_lattice(), begin), p, l.margin, best, work);
        return;
    }
    let n = i32(1u << level);
    let sub = PointLattice(lo, l.cell / f32(n), vec3<i32>(n), l.margin);
    // Only the slabs and rows the ball's box spans: every row of every top cell searched would
    // be `4^level` loop iterations a top cell, most of them outside the ball (point_ring.wgsl
    // says why iterations count on a software adapter).
    let reach = vec3<f32>(sqrt((*best).t)) + l.margin;
    let first = lattice_cell_of(sub, p - reach);
    let last = lattice_cell_of(sub, p + reach);
    for (var z = first.z; z <= last.z; z++) {
        point_steps += 1u;
        let dz = lattice_slab_dist(sub, p, 2, z);
        for (var y = first.y; y <= last.y; y++) {
            point_steps += 1u;
            let dy = lattice_slab_dist(sub, p, 1, y);
            let rest = (*best).t - dz * dz - dy * dy;
            if (!(rest >= 0.0)) { continue; }
            let half = sqrt(rest) + l.margin.x;
            let x0 = lattice_cell_of(sub, vec3<f32>(p.x - half, p.y, p.z)).x;
            let x1 = lattice_cell_of(sub, vec3<f32>(p.x + half, p.y, p.z)).x;
            let row = begin + (u32(y) << level) + (u32(z) << (2u * level));
            var x = x0;
            while (x <= x1) {
                point_steps += 1u;
                // A merged cell covers the entries up to its end: the row goes on from there.
                let end = irr_point_cell(irr_voxel(scene_lattice(), row + u32(x)), p, l.margin, best, work);
                x = max(x + 1, i32((end - (tcu.x << scene.shift)) >> (scene.shift - level)));
            }
        }
    }
}

// The lattice search's cell (`lattice_point_search`, point_ring.wgsl): a top cell, searched
// whole; the row goes on to the next.
fn point_ring_cell(l: PointLattice, p: vec3<f32>, tc: vec3<i32>, best: ptr<function, GpuHit>, work: ptr<function, u32>) -> i32 {
    irr_point_top(l, p, tc, best, work);
    return 1;
}

// The nearest point to `p`; the answer of IrregularGrid::closest_point, tie rule included.
// `work` gets the top cells and cells visited plus the triangles measured.
fn irr_closest_point(p: vec3<f32>, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(inf(), MISS, 0.0, 0.0);
    let s = scene.shift;
    let top_cell = scene.cell_size * f32(1u << s);
    let top_dims = vec3<i32>(scene.dims >> vec3<u32>(s));
    let l = PointLattice(scene.bounds_min, top_cell, top_dims, point_cell_margin(top_cell));
    // The point's voxel (as the ray walks map a point), then its top cell.
    let voxel = clamp(world_to_grid(p), vec3<i32>(0), vec3<i32>(scene.dims) - 1);
    let c = min(voxel >> vec3<u32>(s), top_dims - 1);
    lattice_point_search(l, p, c, 0, &best, work);
    return best;
}
