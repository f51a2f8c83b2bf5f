//! The machine a benchmark ran on: CPU model, cores and threads, OS and kernel, the adapter.

use gridtrace::gpu::GpuContext;
use serde::Serialize;

/// The machine the benchmark ran on.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    pub cpu_model: String,
    pub logical_cores: usize,
    pub threads: usize,
    pub os: String,
    pub adapter: Option<String>,
    pub adapter_is_software: Option<bool>,
}

impl Machine {
    pub fn detect(gpu: Option<&GpuContext>) -> Machine {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let cpu_model = cpuinfo
            .lines()
            .find(|l| l.starts_with("model name"))
            .and_then(|l| l.split(':').nth(1))
            .map(|s| s.trim().to_string())
            .unwrap_or_else(|| std::env::consts::ARCH.to_string());
        let pretty = std::fs::read_to_string("/etc/os-release")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("PRETTY_NAME="))
                    .map(|l| l["PRETTY_NAME=".len()..].trim_matches('"').to_string())
            })
            .unwrap_or_else(|| std::env::consts::OS.to_string());
        let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease").unwrap_or_default();
        let os = if kernel.trim().is_empty() {
            pretty
        } else {
            format!("{pretty}, kernel {}", kernel.trim())
        };
        Machine {
            cpu_model,
            logical_cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            threads: rayon::current_num_threads(),
            os,
            adapter: gpu.map(|g| g.describe()),
            adapter_is_software: gpu.map(|g| g.is_software()),
        }
    }
}
