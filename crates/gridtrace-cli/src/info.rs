//! `gridtrace info`: a scene's mesh statistics, those of the structure `--accel` picks (`auto`:
//! the BVH, which renders fastest on the CPU) and memory use; for a grid (`--accel grid` or
//! `pc`) the paper's memory model beside ours. The README's `info` line says the same.

use crate::common::{AccelArgs, SceneArgs, fmt_bytes};
use clap::Args;

#[derive(Args)]
pub struct InfoArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// With a mesh file: count the floor that `render` adds under it too. By default `info`
    /// describes the file itself, so its triangle count is the file's.
    #[arg(long)]
    with_floor: bool,
    #[command(flatten)]
    pub(crate) accel_args: AccelArgs,
}

pub fn run(a: InfoArgs) -> gridtrace::Result<()> {
    let (scene, name) = a.scene.load(a.with_floor)?;
    let mut notes = Vec::new();
    let accel = a
        .accel_args
        .accel_for(gridtrace::TracedOn::Cpu, gridtrace::Work::Render, &mut notes);
    for n in notes {
        eprintln!("note: {n}");
    }
    let prepared = crate::common::prepare(&scene, &name, accel, &a.accel_args)?;
    println!("scene            {name}");
    println!("vertices         {}", scene.mesh.positions.len());
    println!(
        "triangles        {} ({} degenerate dropped)",
        prepared.accel.tris.len(),
        prepared.degenerate_dropped
    );
    println!("materials        {}", prepared.materials.len());
    println!("lights           {}", prepared.lights.len());
    let b = prepared.accel.bounds();
    println!("bounds           {} .. {}", b.min, b.max);
    let picked = if a.accel_args.accel.choice == gridtrace::AccelChoice::Auto {
        " (auto's pick; --accel grid or pc for the grid and the paper's memory model)"
    } else {
        ""
    };
    println!("accel            {}{picked}", accel.name());
    for (label, value) in prepared.accel.info_lines()? {
        println!("{label:<16} {value}");
    }
    println!("memory:");
    let mut total = 0;
    for (k, b) in prepared.memory() {
        println!("  {k:<14} {:>12}", fmt_bytes(b));
        total += b;
    }
    println!("  {:<14} {:>12}", "total", fmt_bytes(total));
    match prepared.paper_memory_model() {
        Some(model) => println!(
            "  {:<14} {:>12}   (paper's model M = n*96 + cells*16)",
            "paper model",
            fmt_bytes(model)
        ),
        // The model counts a grid's cells: say so rather than leave the line out unexplained.
        None => println!(
            "  {:<14} {:>12}   (the paper's model is a uniform grid's: --accel grid or pc)",
            "paper model", "-"
        ),
    }
    Ok(())
}
