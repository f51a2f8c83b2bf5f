//! The GPU grid build's pipelines: one per stage, compiled once per device
//! (`GpuContext::build_kernels`), over one bind group layout that every stage shares.

use std::mem::size_of;

use super::GridBuildUniform;
use crate::{Error, Result};

/// The build's shared file: its own bindings and structs (the kernels do not include the
/// tracer's `common.wgsl`).
const COMMON: &str = include_str!("common.wgsl");
const REFS: &str = include_str!("refs.wgsl");
const SCAN: &str = include_str!("scan.wgsl");
const SORT: &str = include_str!("sort.wgsl");
const DISTANCE: &str = include_str!("distance.wgsl");
/// Every kernel file of the build (the layout tests parse each module).
pub const KERNEL_SOURCES: [&str; 4] = [REFS, SCAN, SORT, DISTANCE];

/// The whole module of one grid-build kernel: the prelude, `common.wgsl` and the kernel.
pub fn module_source(kernel: &str) -> String {
    format!("{}\n{}\n{}", crate::gpu::walks::wgsl_prelude(), COMMON, kernel)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Stage {
    Count,
    Place,
    ScanCells,
    ScanSums,
    AddCells,
    AddSums,
    Sort,
    Distance,
}

pub(super) struct StageSpec {
    pub stage: Stage,
    /// Stage name in the build's timings.
    pub name: &'static str,
    source: &'static str,
    entry: &'static str,
    overrides: &'static [(&'static str, f64)],
}

/// Every pipeline of the build, in `Stage` order.
pub(super) const STAGES: [StageSpec; 8] = [
    StageSpec {
        stage: Stage::Count,
        name: "count",
        source: REFS,
        entry: "main",
        overrides: &[],
    },
    StageSpec {
        stage: Stage::Place,
        name: "place",
        source: REFS,
        entry: "main",
        overrides: &[("PLACE", 1.0)],
    },
    StageSpec {
        stage: Stage::ScanCells,
        name: "scan",
        source: SCAN,
        entry: "scan",
        overrides: &[("CELLS", 1.0)],
    },
    StageSpec {
        stage: Stage::ScanSums,
        name: "scan",
        source: SCAN,
        entry: "scan",
        overrides: &[],
    },
    StageSpec {
        stage: Stage::AddCells,
        name: "scan",
        source: SCAN,
        entry: "add",
        overrides: &[("CELLS", 1.0)],
    },
    StageSpec {
        stage: Stage::AddSums,
        name: "scan",
        source: SCAN,
        entry: "add",
        overrides: &[],
    },
    StageSpec {
        stage: Stage::Sort,
        name: "sort",
        source: SORT,
        entry: "main",
        overrides: &[],
    },
    StageSpec {
        stage: Stage::Distance,
        name: "distance",
        source: DISTANCE,
        entry: "main",
        overrides: &[],
    },
];

/// The build's pipelines, compiled once per device (`GpuContext::build_kernels`).
pub(crate) struct BuildKernels {
    pub(super) layout: wgpu::BindGroupLayout,
    /// In `STAGES` order.
    pub(super) pipelines: Vec<wgpu::ComputePipeline>,
}

impl BuildKernels {
    pub fn new(dev: &wgpu::Device) -> Result<BuildKernels> {
        let storage = |binding: u32, read_only: bool| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let mut entries = vec![
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(size_of::<GridBuildUniform>() as u64),
                },
                count: None,
            },
            storage(1, true),
        ];
        entries.extend((2..=7).map(|b| storage(b, false)));
        let layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("grid build"),
            entries: &entries,
        });
        let pipeline_layout = dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("grid build"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let (pipelines, error) = crate::gpu::context::validated(dev, || {
            STAGES
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    debug_assert_eq!(s.stage as usize, i);
                    let module = dev.create_shader_module(wgpu::ShaderModuleDescriptor {
                        label: Some(s.name),
                        source: wgpu::ShaderSource::Wgsl(module_source(s.source).into()),
                    });
                    dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(s.name),
                        layout: Some(&pipeline_layout),
                        module: &module,
                        entry_point: Some(s.entry),
                        compilation_options: wgpu::PipelineCompilationOptions {
                            constants: s.overrides,
                            ..Default::default()
                        },
                        cache: None,
                    })
                })
                .collect()
        });
        if let Some(e) = error {
            return Err(Error::Gpu(format!("creating the grid-build kernels failed: {e}")));
        }
        Ok(BuildKernels { layout, pipelines })
    }
}
