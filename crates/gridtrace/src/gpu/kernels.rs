//! The compute kernels: shader modules, bind group layouts, pipeline layouts and pipelines. They
//! depend on the device only, not on the scene, so they are built once per `GpuContext`
//! (`GpuContext::kernels`) and shared by every renderer on it. Also the one helper that records
//! a kernel's compute pass, for the tile loop and the ray queries alike.

use super::bindings::{self, FRAME_BINDINGS, FRAME_GROUP, INDIRECT_BINDINGS, INDIRECT_GROUP};
use super::constants::{MAX_GROUPS_X, WORKGROUP};
use super::layout::IndirectArgs;
use super::scene::GpuStructure;
use super::shaders;
use super::timing::StageTimer;
use crate::{Error, Result};

/// A pipeline: a kernel, or a kernel compiled with other override constants.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kernel {
    Raygen,
    Traverse,
    /// `traverse` that also writes each ray's traversal work to its pixel (heat mode).
    TraverseHeat,
    Occlusion,
    Shade,
    Resolve,
    Indirect,
    /// `traverse` compiled to walk the BVH (and the same three for heat and occlusion).
    TraverseBvh,
    TraverseBvhHeat,
    OcclusionBvh,
    /// `occlusion` finding closest hits: the `shadow_closest_hit` ablation, for each walk.
    OcclusionClosest,
    OcclusionBvhClosest,
    /// `traverse` and `occlusion` compiled to walk the irregular grid, as the BVH's four.
    TraverseIrregular,
    TraverseIrregularHeat,
    OcclusionIrregular,
    OcclusionIrregularClosest,
}

impl Kernel {
    /// The pipeline that runs this kernel on a scene walked as `structure`: the traversal
    /// kernels have one per walk, specialised by the `BVH` and `IRREGULAR` overrides so that
    /// none carries another's code and registers.
    pub fn walking(self, structure: GpuStructure) -> Kernel {
        match (self, structure) {
            (Kernel::Traverse, GpuStructure::Bvh) => Kernel::TraverseBvh,
            (Kernel::TraverseHeat, GpuStructure::Bvh) => Kernel::TraverseBvhHeat,
            (Kernel::Occlusion, GpuStructure::Bvh) => Kernel::OcclusionBvh,
            (Kernel::OcclusionClosest, GpuStructure::Bvh) => Kernel::OcclusionBvhClosest,
            (Kernel::Traverse, GpuStructure::Irregular) => Kernel::TraverseIrregular,
            (Kernel::TraverseHeat, GpuStructure::Irregular) => Kernel::TraverseIrregularHeat,
            (Kernel::Occlusion, GpuStructure::Irregular) => Kernel::OcclusionIrregular,
            (Kernel::OcclusionClosest, GpuStructure::Irregular) => Kernel::OcclusionIrregularClosest,
            (k, _) => k,
        }
    }
}

/// How many invocations a kernel's dispatch has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Launch {
    /// One per pixel of the tile, sized on the host.
    PerPixel,
    /// A single invocation.
    Once,
    /// Sized on the GPU by the indirect kernel: the dispatch arguments at this byte offset of
    /// the indirect-args buffer.
    Indirect { offset_bytes: u64 },
}

struct KernelSpec {
    kernel: Kernel,
    /// Pipeline label.
    label: &'static str,
    /// Stage name in `GpuTimings` (the heat pipeline counts as `traverse`).
    stage: &'static str,
    source: &'static str,
    /// Pipeline-overridable constants (`override` in WGSL).
    overrides: &'static [(&'static str, f64)],
    launch: Launch,
    /// Writes the indirect arguments, so binds them as group 1 (its pipeline layout has it).
    writes_indirect_args: bool,
}

const RAY_QUEUE: Launch = Launch::Indirect {
    offset_bytes: IndirectArgs::RAYS_OFFSET,
};
const SHADOW_QUEUE: Launch = Launch::Indirect {
    offset_bytes: IndirectArgs::SHADOW_OFFSET,
};

const fn spec(kernel: Kernel, label: &'static str, stage: &'static str, source: &'static str) -> KernelSpec {
    KernelSpec {
        kernel,
        label,
        stage,
        source,
        overrides: &[],
        launch: RAY_QUEUE,
        writes_indirect_args: false,
    }
}

/// Every pipeline, in `Kernel` order (`kernel as usize` indexes it; a test checks).
const SPECS: [KernelSpec; 16] = [
    KernelSpec {
        launch: Launch::PerPixel,
        ..spec(Kernel::Raygen, "raygen", "raygen", shaders::RAYGEN)
    },
    spec(Kernel::Traverse, "traverse", "traverse", shaders::TRAVERSE),
    KernelSpec {
        overrides: &[("COUNT_WORK", 1.0)],
        ..spec(Kernel::TraverseHeat, "traverse (heat)", "traverse", shaders::TRAVERSE)
    },
    KernelSpec {
        launch: SHADOW_QUEUE,
        ..spec(Kernel::Occlusion, "occlusion", "occlusion", shaders::OCCLUSION)
    },
    spec(Kernel::Shade, "shade", "shade", shaders::SHADE),
    spec(Kernel::Resolve, "resolve", "resolve", shaders::RESOLVE),
    KernelSpec {
        launch: Launch::Once,
        writes_indirect_args: true,
        ..spec(Kernel::Indirect, "indirect", "indirect", shaders::INDIRECT)
    },
    KernelSpec {
        overrides: &[("BVH", 1.0)],
        ..spec(Kernel::TraverseBvh, "traverse (bvh)", "traverse", shaders::TRAVERSE)
    },
    KernelSpec {
        overrides: &[("BVH", 1.0), ("COUNT_WORK", 1.0)],
        ..spec(
            Kernel::TraverseBvhHeat,
            "traverse (bvh, heat)",
            "traverse",
            shaders::TRAVERSE,
        )
    },
    KernelSpec {
        launch: SHADOW_QUEUE,
        overrides: &[("BVH", 1.0)],
        ..spec(Kernel::OcclusionBvh, "occlusion (bvh)", "occlusion", shaders::OCCLUSION)
    },
    KernelSpec {
        launch: SHADOW_QUEUE,
        overrides: &[("SHADOW_CLOSEST", 1.0)],
        ..spec(
            Kernel::OcclusionClosest,
            "occlusion (closest hit)",
            "occlusion",
            shaders::OCCLUSION,
        )
    },
    KernelSpec {
        launch: SHADOW_QUEUE,
        overrides: &[("BVH", 1.0), ("SHADOW_CLOSEST", 1.0)],
        ..spec(
            Kernel::OcclusionBvhClosest,
            "occlusion (bvh, closest hit)",
            "occlusion",
            shaders::OCCLUSION,
        )
    },
    KernelSpec {
        overrides: &[("IRREGULAR", 1.0)],
        ..spec(
            Kernel::TraverseIrregular,
            "traverse (irregular)",
            "traverse",
            shaders::TRAVERSE,
        )
    },
    KernelSpec {
        overrides: &[("IRREGULAR", 1.0), ("COUNT_WORK", 1.0)],
        ..spec(
            Kernel::TraverseIrregularHeat,
            "traverse (irregular, heat)",
            "traverse",
            shaders::TRAVERSE,
        )
    },
    KernelSpec {
        launch: SHADOW_QUEUE,
        overrides: &[("IRREGULAR", 1.0)],
        ..spec(
            Kernel::OcclusionIrregular,
            "occlusion (irregular)",
            "occlusion",
            shaders::OCCLUSION,
        )
    },
    KernelSpec {
        launch: SHADOW_QUEUE,
        overrides: &[("IRREGULAR", 1.0), ("SHADOW_CLOSEST", 1.0)],
        ..spec(
            Kernel::OcclusionIrregularClosest,
            "occlusion (irregular, closest hit)",
            "occlusion",
            shaders::OCCLUSION,
        )
    },
];

fn spec_of(kernel: Kernel) -> &'static KernelSpec {
    let spec = &SPECS[kernel as usize];
    debug_assert_eq!(spec.kernel, kernel);
    spec
}

/// Workgroups for `n` items as a 2-D dispatch (the kernels use `flat_index`); mirrors `groups`
/// in indirect.wgsl.
fn dispatch_size(n: u32) -> (u32, u32) {
    dispatch_groups(n, WORKGROUP)
}

/// Workgroups for `n` items, `per_group` to a workgroup, as a 2-D dispatch of at most
/// `MAX_GROUPS_X` in x (so under WebGPU's 65535 per dimension).
pub(super) fn dispatch_groups(n: u32, per_group: u32) -> (u32, u32) {
    let g = n.div_ceil(per_group);
    let x = g.min(MAX_GROUPS_X);
    (x, if x == 0 { 0 } else { g.div_ceil(x) })
}

/// The compiled kernels of one device.
pub(crate) struct Kernels {
    /// Layout of group 0 (`FRAME_BINDINGS`).
    pub frame_layout: wgpu::BindGroupLayout,
    /// Layout of group 1 (`INDIRECT_BINDINGS`).
    pub indirect_layout: wgpu::BindGroupLayout,
    /// In `SPECS` order.
    pipelines: Vec<wgpu::ComputePipeline>,
}

impl Kernels {
    /// Compiles every kernel; a validation error is returned, not raised on the device.
    pub fn new(dev: &wgpu::Device) -> Result<Kernels> {
        let frame_layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gridtrace"),
            entries: &bindings::layout_entries(&FRAME_BINDINGS),
        });
        let indirect_layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("indirect args"),
            entries: &bindings::layout_entries(&INDIRECT_BINDINGS),
        });
        let frame_only = dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("gridtrace"),
            bind_group_layouts: &[Some(&frame_layout)],
            immediate_size: 0,
        });
        let with_indirect = dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("indirect"),
            bind_group_layouts: &[Some(&frame_layout), Some(&indirect_layout)],
            immediate_size: 0,
        });
        let scope = dev.push_error_scope(wgpu::ErrorFilter::Validation);
        let pipelines = SPECS
            .iter()
            .map(|s| {
                let module = dev.create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some(s.label),
                    source: wgpu::ShaderSource::Wgsl(shaders::module_source(s.source).into()),
                });
                dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(s.label),
                    layout: Some(if s.writes_indirect_args {
                        &with_indirect
                    } else {
                        &frame_only
                    }),
                    module: &module,
                    entry_point: Some("main"),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants: s.overrides,
                        ..Default::default()
                    },
                    cache: None,
                })
            })
            .collect();
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Gpu(format!("creating the kernels failed: {e}")));
        }
        Ok(Kernels {
            frame_layout,
            indirect_layout,
            pipelines,
        })
    }
}

/// Records compute passes into one submission: binds each kernel's groups and sizes its
/// dispatch as its spec says, and takes its timestamps.
pub(crate) struct PassRecorder<'a> {
    pub kernels: &'a Kernels,
    /// The indirect-args buffer and its group-1 bind group.
    pub indirect_args: &'a wgpu::Buffer,
    pub indirect_group: &'a wgpu::BindGroup,
    /// The scene's walk: picks the traversal kernels' pipelines (`Kernel::walking`).
    pub structure: GpuStructure,
    /// The `shadow_closest_hit` ablation: occlusion runs its closest-hit pipeline.
    pub shadow_closest_hit: bool,
    /// Pixels of the tile (sizes `Launch::PerPixel` kernels).
    pub tile_pixels: u32,
    pub timer: StageTimer<'a>,
}

impl PassRecorder<'_> {
    /// One compute pass running `kernel` with `frame` as group 0.
    pub fn pass(&mut self, enc: &mut wgpu::CommandEncoder, kernel: Kernel, frame: &wgpu::BindGroup) {
        let kernel = match (kernel, self.shadow_closest_hit) {
            (Kernel::Occlusion, true) => Kernel::OcclusionClosest,
            (k, _) => k,
        }
        .walking(self.structure);
        let spec = spec_of(kernel);
        let timestamp_writes = self.timer.pass_writes(spec.stage);
        let mut cp = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(spec.stage),
            timestamp_writes,
        });
        cp.set_pipeline(&self.kernels.pipelines[kernel as usize]);
        cp.set_bind_group(FRAME_GROUP, frame, &[]);
        if spec.writes_indirect_args {
            cp.set_bind_group(INDIRECT_GROUP, self.indirect_group, &[]);
        }
        match spec.launch {
            Launch::PerPixel => {
                let (x, y) = dispatch_size(self.tile_pixels);
                cp.dispatch_workgroups(x, y, 1);
            }
            Launch::Once => cp.dispatch_workgroups(1, 1, 1),
            Launch::Indirect { offset_bytes } => cp.dispatch_workgroups_indirect(self.indirect_args, offset_bytes),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_are_in_kernel_order() {
        for (i, s) in SPECS.iter().enumerate() {
            assert_eq!(s.kernel as usize, i, "{}", s.label);
        }
    }

    /// Every traversal kernel on every structure runs the pipeline compiled for that walk (its
    /// override set, the others' not), and the other kernels are the same for all.
    #[test]
    fn walking_picks_each_structures_pipeline() {
        let overrides = |k: Kernel| spec_of(k).overrides.iter().map(|o| o.0).collect::<Vec<_>>();
        for structure in GpuStructure::ALL {
            let want = match structure {
                GpuStructure::Grid => None,
                GpuStructure::Bvh => Some("BVH"),
                GpuStructure::Irregular => Some("IRREGULAR"),
            };
            for k in [
                Kernel::Traverse,
                Kernel::TraverseHeat,
                Kernel::Occlusion,
                Kernel::OcclusionClosest,
            ] {
                let got = overrides(k.walking(structure));
                for walk in ["BVH", "IRREGULAR"] {
                    assert_eq!(
                        got.contains(&walk),
                        want == Some(walk),
                        "{k:?} on {structure:?}: {got:?}"
                    );
                }
                // Heat and the closest-hit ablation survive the specialisation.
                assert_eq!(got.contains(&"COUNT_WORK"), k == Kernel::TraverseHeat);
                assert_eq!(got.contains(&"SHADOW_CLOSEST"), k == Kernel::OcclusionClosest);
                assert_eq!(spec_of(k.walking(structure)).stage, spec_of(k).stage);
            }
            for k in [Kernel::Raygen, Kernel::Shade, Kernel::Resolve, Kernel::Indirect] {
                assert_eq!(k.walking(structure), k);
            }
        }
    }

    /// The host's dispatch sizes agree with indirect.wgsl's rule and stay under WebGPU's 65535.
    #[test]
    fn dispatch_sizes() {
        assert_eq!(dispatch_size(0), (0, 0));
        assert_eq!(dispatch_size(1), (1, 1));
        assert_eq!(dispatch_size(WORKGROUP), (1, 1));
        assert_eq!(dispatch_size(WORKGROUP + 1), (2, 1));
        let (x, y) = dispatch_size(u32::MAX);
        assert!(x <= 65535 && y <= 65535 && x as u64 * y as u64 * WORKGROUP as u64 >= u32::MAX as u64);
        // The grid build's scan: a workgroup per 1024 cells of 2^26.
        let block = crate::gpu::constants::SCAN_BLOCK;
        let (x, y) = dispatch_groups(1 << 26, block);
        assert!(x <= 65535 && y <= 65535 && x as u64 * y as u64 * block as u64 >= 1 << 26);
    }
}
