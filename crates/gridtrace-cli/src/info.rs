//! `gridtrace info`: mesh, grid and memory statistics.

use clap::Args;
use gridtrace::accel::grid::dims_str;

use gridtrace::accel::irregular::IrregularStats;
use gridtrace::accel::{IrregularGrid, Structure};

use crate::common::{GridArgs, SceneArgs, describe_structure, fmt_bytes};

#[derive(Args)]
pub struct InfoArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// With a mesh file: count the floor that `render` adds under it too. By default `info`
    /// describes the file itself, so its triangle count is the file's.
    #[arg(long)]
    with_floor: bool,
    #[command(flatten)]
    grid: GridArgs,
}

pub fn run(a: InfoArgs) -> gridtrace::Result<()> {
    let (scene, name) = a.scene.load(a.with_floor)?;
    let prepared = crate::common::prepare(&scene, &name, a.grid.accel, &a.grid)?;
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
    match &prepared.accel.structure {
        Structure::Grid(g) => {
            let s = &g.stats;
            println!("grid             {} = {} cells", dims_str(s.dims), s.cells);
            println!("empty cells      {:.1}%", s.empty_fraction() * 100.0);
            println!(
                "references       {} ({:.2} per triangle, max {} in a cell)",
                s.references,
                s.refs_per_triangle(),
                s.max_refs_in_cell
            );
            println!("build            {:.2} ms", s.build_ms);
        }
        Structure::Bvh(_) => println!("structure        {}", describe_structure(&prepared.accel)),
        Structure::Irregular(g) => {
            let s = &g.stats;
            let v = g.voxel_dims();
            println!(
                "irregular grid   top {} cells, up to {} levels below (virtual {}x{}x{} voxels)",
                dims_str(s.top_dims),
                s.max_level,
                v.x,
                v.y,
                v.z
            );
            println!(
                "cells            {} ({} before merging), {:.1}% empty",
                s.cells,
                s.initial_cells,
                s.empty_cells as f64 * 100.0 / s.cells.max(1) as f64
            );
            println!(
                "references       {} ({:.2} per triangle)",
                s.references,
                s.refs_per_triangle()
            );
            println!("build            {:.2} ms", s.build_ms());
            for (phase, ms) in IrregularStats::PHASES.iter().zip(s.phase_ms) {
                println!("  {phase:<14} {ms:>9.2} ms");
            }
            // What `IrregularGrid::memory_bound` says before a build, beside what this one made.
            let m = IrregularGrid::memory_bound(&prepared.accel.tris, a.grid.irregular)?;
            println!(
                "bound            at most {} cells before merging, {} references, structure {}, build peak {}",
                m.initial_cells,
                m.references,
                fmt_bytes(m.structure_bytes as usize),
                fmt_bytes(m.build_peak_bytes as usize)
            );
        }
    }
    println!("memory:");
    let mut total = 0;
    for (k, b) in prepared.memory() {
        println!("  {k:<14} {:>12}", fmt_bytes(b));
        total += b;
    }
    println!("  {:<14} {:>12}", "total", fmt_bytes(total));
    if let Some(model) = prepared.paper_memory_model() {
        println!(
            "  {:<14} {:>12}   (paper's model M = n*96 + cells*16)",
            "paper model",
            fmt_bytes(model)
        );
    }
    Ok(())
}
