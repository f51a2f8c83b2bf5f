//! `bench --suite hardware`: the one prepared run for a GPU machine
//! (`gridtrace_bench::hardware`).

use std::path::PathBuf;
use std::time::Instant;

use gridtrace_bench::{self as bench, scenes};

use super::{BenchArgs, BenchBackendArg, open_gpu};

/// `--suite hardware`.
pub(super) fn run_hardware_suite(a: &BenchArgs) -> gridtrace::Result<()> {
    let t0 = Instant::now();
    let plan = if a.quick {
        bench::hardware::Plan::quick()
    } else {
        bench::hardware::Plan::full()
    };
    let gpu = std::sync::Arc::new(open_gpu(BenchBackendArg::Gpu)?.expect("the GPU backend opens a device or fails"));
    let data_dir = scenes::find_data_dir(a.data_dir.as_deref());
    let variants = gridtrace::gpu::GpuVariants::suite();
    let mut log = |s: &str| println!("{s}");
    let dir = a.out.clone().unwrap_or_else(|| PathBuf::from("hardware-suite"));
    let report = bench::hardware::run(&plan, gpu, data_dir.as_deref(), &variants, &dir, &mut log)?;
    println!("wrote {0}/hardware.json and {0}/hardware.md", dir.display());
    for m in &report.mismatches {
        println!("MISMATCH: {m}");
    }
    for s in &report.skipped {
        println!("skipped: {s}");
    }
    println!("hardware suite finished in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
}
