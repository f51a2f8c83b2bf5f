//! Times the irregular grid's build on a mesh file, each phase's best of N, and prints what it
//! made: `cargo run --release -p gridtrace --example irregular_build_phases -- MESH [REPS]
//! [PARAMS]` (`PARAMS` as `--irregular` spells them; `RAYON_NUM_THREADS=1` for one thread).
use gridtrace::accel::irregular::IrregularStats;
use gridtrace::accel::{IrregularGrid, IrregularParams, TriAccel};

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: irregular_build_phases MESH [REPS] [PARAMS]");
    let reps: usize = args.get(2).map_or(10, |r| r.parse().expect("REPS is a count"));
    let params: IrregularParams = match args.get(3) {
        Some(p) => p.parse().map_err(gridtrace::Error::InvalidInput)?,
        None => IrregularParams::default(),
    };
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    let tris = TriAccel::from_mesh(&mesh);
    let mut best = [f64::INFINITY; 6];
    let mut last = None;
    for _ in 0..reps.max(1) {
        let g = IrregularGrid::build(&tris, params)?;
        for (b, ms) in best
            .iter_mut()
            .zip(g.stats.phase_ms.iter().chain([g.stats.build_ms()].iter()))
        {
            *b = b.min(*ms);
        }
        last = Some(g.stats);
    }
    let s = last.expect("at least one build");
    println!(
        "{}: {} triangles, top {:?}, {} cells before merging, {} after ({} empty), {:.2} references per triangle",
        path,
        s.triangles,
        s.top_dims,
        s.initial_cells,
        s.cells,
        s.empty_cells,
        s.refs_per_triangle()
    );
    println!("best of {reps} on {} threads, ms:", rayon::current_num_threads());
    for (name, ms) in IrregularStats::PHASES.iter().chain(["build"].iter()).zip(best) {
        println!("  {name:<13} {ms:8.2}");
    }
    Ok(())
}
