// The ring search of the closest-point queries over a lattice (the grid's cells, the irregular
// grid's top cells), written once for the walks that include this file; each defines
// `point_ring_cell(l, p, cell, best, work) -> i32`, which searches one cell and returns how many
// cells its row may advance (1, or more where the cell knows the next ones are empty).
//
// Ring `r` around cell `c`, clipped to the lattice: the rows of its two z faces and two y faces
// along x (clipped to the ball of the best distance), and the two cells of its x faces in the
// other rows.
fn lattice_point_ring(l: PointLattice, p: vec3<f32>, c: vec3<i32>, r: i32,
                      best: ptr<function, GpuHit>, work: ptr<function, u32>) {
    let lo = max(c - r, vec3<i32>(0));
    let hi = min(c + r, l.dims - 1);
    for (var z = lo.z; z <= hi.z; z++) {
        let dz = lattice_slab_dist(l, p, 2, z);
        if (dz * dz > (*best).t) { continue; }
        for (var y = lo.y; y <= hi.y; y++) {
            let dy = lattice_slab_dist(l, p, 1, y);
            let yz = dz * dz + dy * dy;
            if (yz > (*best).t) { continue; }
            if (abs(z - c.z) == r || abs(y - c.y) == r) {
                var x = lo.x;
                while (x <= hi.x) {
                    let dx = lattice_slab_dist(l, p, 0, x);
                    if (dx * dx + yz > (*best).t) {
                        // Past the point, every later cell of the row is farther still.
                        if (l.min.x + f32(x) * l.cell.x > p.x) { break; }
                        x += 1;
                        continue;
                    }
                    x += point_ring_cell(l, p, vec3<i32>(x, y, z), best, work);
                }
            } else {
                if (c.x - r >= 0) { point_ring_cell(l, p, vec3<i32>(c.x - r, y, z), best, work); }
                if (c.x + r < l.dims.x) { point_ring_cell(l, p, vec3<i32>(c.x + r, y, z), best, work); }
            }
        }
    }
}
