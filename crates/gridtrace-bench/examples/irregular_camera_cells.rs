//! Where the irregular grid's triangle tests happen on the camera rays of the paper's bunny in a
//! room: in the cell the ray starts in, in the cell of its hit, or in cells between, over every
//! fourth pixel of a 512 x 512 frame:
//! `cargo run --release -p gridtrace-bench --example irregular_camera_cells -- [PARAMS]`
//! (`PARAMS` as `--irregular` spells them; the mesh folder found as `gridtrace bench`
//! finds it: `GRIDTRACE_DATA_DIR`, else `shared/data/meshes` beside the checkout).
use gridtrace::accel::{AccelKind, Hit, IrregularParams, TraversalCounters};

fn main() -> gridtrace::Result<()> {
    let params: IrregularParams = match std::env::args().nth(1) {
        Some(p) => p.parse().map_err(gridtrace::Error::InvalidInput)?,
        None => IrregularParams::default(),
    };
    let data = gridtrace_bench::scenes::find_data_dir(None)
        .ok_or_else(|| gridtrace::Error::InvalidInput("no mesh data folder found: set GRIDTRACE_DATA_DIR".into()))?;
    let scene = gridtrace_bench::scenes::bunny_room(&data)?;
    let prepared = scene.prepare_for(AccelKind::Irregular, &params.to_params())?;
    let grid = prepared.accel.irregular().expect("an irregular grid");
    let tris = &prepared.accel.tris;
    let frame = scene.camera.frame(512, 512);
    let (mut rays, mut first, mut last, mut between, mut steps) = (0u64, 0u64, 0u64, 0u64, 0u64);
    let mut starts_non_empty = 0u64;
    for y in (0..512).step_by(4) {
        for x in (0..512).step_by(4) {
            let ray = frame.ray(x, y);
            let mut best = Hit::MISS;
            best.t = f32::INFINITY;
            // Tests made in each non-empty cell visited, in order.
            let mut visits: Vec<u64> = Vec::new();
            let mut counters = TraversalCounters::default();
            let mut first_cell_tested = None;
            grid.walk(&ray, &mut counters, |refs, t_cell_exit, c| {
                first_cell_tested.get_or_insert(c.cells == 1);
                for &t in refs {
                    if let Some(h) = tris[t as usize].intersect(ray.origin, ray.dir, 0.0, best.t) {
                        best.t = h.t;
                        best.tri = t;
                    }
                }
                visits.push(refs.len() as u64);
                best.tri != u32::MAX && best.t <= t_cell_exit
            });
            rays += 1;
            steps += counters.cells;
            if first_cell_tested == Some(true) {
                starts_non_empty += 1;
                first += visits[0];
            }
            let skip_first = usize::from(first_cell_tested == Some(true));
            if let Some((l, rest)) = visits[skip_first..].split_last() {
                last += l;
                between += rest.iter().sum::<u64>();
            }
        }
    }
    let per = |n: u64| n as f64 / rays as f64;
    println!(
        "{} cells; per camera ray: {:.2} steps, {:.2} triangle tests: {:.2} in the cell it starts in \
         (non-empty for {:.0}% of the rays), {:.2} in the cell of its hit (or its last), {:.2} between",
        grid.cell_count(),
        per(steps),
        per(first + last + between),
        per(first),
        100.0 * per(starts_non_empty),
        per(last),
        per(between)
    );
    Ok(())
}
