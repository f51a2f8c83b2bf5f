//! Times the uniform grid's build and its distance transform alone on a mesh file, best of N,
//! and counts the shapes of the triangles' candidate cell ranges:
//! `cargo run --release -p gridtrace --example grid_build_phases -- MESH [REPS]`
//! (`RAYON_NUM_THREADS=1` for one thread).
use std::time::Instant;

use gridtrace::accel::grid::{Grid, proximity::chebyshev_distance_transform};
use gridtrace::accel::{Resolution, TriAccel};

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: grid_build_phases MESH [REPS]");
    let reps: usize = args.get(2).map_or(20, |r| r.parse().expect("REPS is a count"));
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    let tris = TriAccel::from_mesh(&mesh);
    let best = |f: &mut dyn FnMut()| {
        (0..reps)
            .map(|_| {
                let t0 = Instant::now();
                f();
                t0.elapsed().as_secs_f64() * 1e3
            })
            .fold(f64::INFINITY, f64::min)
    };
    let grid = Grid::build(&tris, Resolution::default())?;
    let occ: Vec<bool> = grid.cells.iter().map(|c| c.count > 0).collect();
    if std::env::var_os("DT_ONLY").is_some() {
        for _ in 0..reps {
            std::hint::black_box(chebyshev_distance_transform(grid.stats.dims, &occ));
        }
        return Ok(());
    }
    let build = best(&mut || {
        Grid::build(&tris, Resolution::default()).unwrap();
    });
    let dt = best(&mut || {
        std::hint::black_box(chebyshev_distance_transform(grid.stats.dims, &occ));
    });
    let full = vec![true; occ.len()];
    let dt_full = best(&mut || {
        std::hint::black_box(chebyshev_distance_transform(grid.stats.dims, &full));
    });
    println!("distance transform with every cell occupied (no rounds): {dt_full:.2} ms");
    shapes(&grid, &tris);
    let max_d = grid.cells.iter().map(|c| c.dist).max().unwrap_or(0);
    println!(
        "{} tris, dims {:?}, max dist {max_d}: build {build:.2} ms, distance transform {dt:.2} ms ({} threads)",
        tris.len(),
        grid.stats.dims,
        rayon::current_num_threads()
    );
    Ok(())
}

/// How many triangles have a candidate cell range that is one cell (0-D), a row (1-D), a slab
/// (2-D) or a block (3-D), and their candidate cells: rows and single cells need no exact test.
fn shapes(grid: &Grid, tris: &[TriAccel]) {
    let mut hist = [0usize; 4];
    let mut cand = [0usize; 4];
    for t in tris {
        let [a, b, c] = t.vertices();
        let m = grid.cell_size * 1e-3;
        let lo = ((a.min(b).min(c) - m - grid.bounds.min) * grid.inv_cell_size)
            .max(glam::Vec3::ZERO)
            .as_uvec3()
            .min(grid.dims - 1);
        let hi = ((a.max(b).max(c) + m - grid.bounds.min) * grid.inv_cell_size)
            .max(glam::Vec3::ZERO)
            .as_uvec3()
            .min(grid.dims - 1);
        let e = hi - lo + 1;
        let k = (e.x > 1) as usize + (e.y > 1) as usize + (e.z > 1) as usize;
        hist[k] += 1;
        cand[k] += (e.x * e.y * e.z) as usize;
    }
    println!("range dims histogram (0-D..3-D): {hist:?}, candidate cells {cand:?}");
}
