//! The compute kernels: shader modules, bind group layouts, pipeline layouts and pipelines. They
//! depend on the device and the GPU variants only, not on the scene, so they are built once per
//! `GpuContext` and `GpuVariants` (`Kernels::of`; the walking kernels once per walk,
//! `Kernels::walk`) and shared by every renderer on it with those variants. Also the one helper that records
//! a kernel's compute pass, for the tile loop and the ray queries alike.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use super::bindings::{
    self, Access, BATCH_AFTER_WALK_GROUP, BATCH_BINDINGS, BATCH_GROUP, Binding, FRAME_GROUP, FrameSlot,
    INDIRECT_BINDINGS, INDIRECT_GROUP, PACK_BINDINGS, PACK_GROUP, STRUCTURE_GROUP, WINDING_BINDINGS, WINDING_GROUP,
};
use super::constants::{WORKGROUP, dispatch_groups};
use super::context::GpuContext;
use super::shaders;
use super::timing::StageTimer;
use super::variants::GpuVariants;
use super::walks::WalkSpec;
use crate::{Error, Result};

/// A pipeline: a kernel, or a kernel compiled with other override constants. The walking
/// kernels (traverse, occlusion, closest point) are compiled once per structure
/// (`WalkPipelines`).
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
    /// `occlusion` finding closest hits: the `shadow_closest_hit` ablation.
    OcclusionClosest,
    /// The tile's pixels to 8-bit sRGB (`PixelFormat::Srgb8`).
    Pack,
    /// The nearest point of the mesh to each point of the input queue (`gpu::points`).
    ClosestPoint,
    /// A ray batch's chunk: its wire rays into queue records (`batch.wgsl`, `queries.rs`).
    BatchRays,
    /// A ray batch's chunk: the walk's output into the answers asked for.
    BatchAnswers,
    /// Every hit of each ray of a batch's chunk, counted (`all_hits.rs`).
    AllHits,
    /// The same, listed where the prefix sum of the counts places each ray's hits.
    AllHitsList,
    /// The running sum of a chunk's hit counts.
    PrefixSum,
    /// The winding number of each point of a batch's chunk (`winding.rs`).
    Winding,
}

/// What a kernel that walks no structure binds as group 1 (a walking kernel binds its
/// structure's arrays there).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Group1 {
    None,
    /// The indirect arguments, written as storage by the one kernel that computes them.
    IndirectArgs,
    /// The packed pixels the pack kernel writes.
    Packed,
    /// A ray batch's wire rays, answers and constants (a walking kernel binds them as group
    /// 2, after its structure's arrays: the all-hits kernels).
    Batch,
    /// A batch's buffers, and the fast winding tree as group 2.
    BatchWinding,
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
    /// Compiled with the scene's structure's walk (group 1 is its arrays).
    walks: bool,
    /// Pipeline label.
    label: &'static str,
    /// Stage name in `GpuTimings` (the heat pipeline counts as `traverse`).
    stage: &'static str,
    source: &'static str,
    /// Pipeline-overridable constants (`override` in WGSL).
    overrides: &'static [(&'static str, f64)],
    launch: Launch,
    /// Its group 1 when it walks no structure (its pipeline layout has it).
    group1: Group1,
}

mod specs;
use specs::SPECS;

impl KernelSpec {
    /// Its file's name in `shaders::KERNELS`, which keys `bindings::FRAME_USE`.
    fn file(&self) -> &'static str {
        shaders::KERNELS
            .iter()
            .find(|(_, src)| *src == self.source)
            .map(|(name, _)| *name)
            .expect("every kernel's source is in shaders::KERNELS")
    }
}

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

/// One structure's walking pipelines (traverse, its heat variant, occlusion and its closest-hit
/// ablation, and closest point where the walk searches points) and the layout of its group 1.
pub(crate) struct WalkPipelines {
    pub spec: &'static WalkSpec,
    /// Layout of group 1: the structure's arrays, in `spec.arrays` order.
    pub layout: wgpu::BindGroupLayout,
    /// Indexed by `kernel as usize` (`None` for the kernels that do not walk, and for those
    /// compiled on first use).
    pipelines: Vec<Option<wgpu::ComputePipeline>>,
    /// The walking kernels that bind a batch's buffers too (the all-hits kernels), compiled
    /// when first run (`Kernels::prepare`): most scenes never count or list hits, and a browser
    /// compiles every pipeline it is given at upload.
    on_demand: std::sync::OnceLock<Vec<Option<wgpu::ComputePipeline>>>,
}

impl KernelSpec {
    /// Whether a walk's pipeline of this kernel is compiled on first use (`on_demand`).
    fn on_demand(&self) -> bool {
        self.walks && self.group1 == Group1::Batch
    }
}

/// The compiled kernels of one device and one choice of variants.
pub(crate) struct Kernels {
    /// The variants they were compiled with.
    pub variants: GpuVariants,
    /// Each kernel's rows of group 0 (those of `FRAME_BINDINGS` its module uses,
    /// `bindings::frame_rows`) and their layout, indexed by `kernel as usize`: looked up once
    /// here, then used for the layouts and every bounce's bind groups (`frame_groups`).
    frame_rows: Vec<Vec<Binding<FrameSlot>>>,
    frame_layouts: Vec<wgpu::BindGroupLayout>,
    /// Layout of group 1 of the indirect kernel (`INDIRECT_BINDINGS`).
    pub indirect_layout: wgpu::BindGroupLayout,
    /// Layout of group 1 of the pack kernel (`PACK_BINDINGS`).
    pub pack_layout: wgpu::BindGroupLayout,
    /// Layout of group 1 of the ray batches' kernels (`BATCH_BINDINGS`).
    pub batch_layout: wgpu::BindGroupLayout,
    /// Layout of group 2 of the winding kernel (`WINDING_BINDINGS`).
    pub winding_layout: wgpu::BindGroupLayout,
    /// The kernels that walk no structure, in `SPECS` order (`None` for those that walk).
    pipelines: Vec<Option<wgpu::ComputePipeline>>,
    /// Each walk's pipelines (by `WalkSpec::name`), compiled when a scene of it is first
    /// uploaded.
    walks: Mutex<HashMap<&'static str, Arc<WalkPipelines>>>,
}

/// Every variant's kernels of one device (the context caches one of these).
#[derive(Default)]
struct KernelSets(Mutex<HashMap<GpuVariants, Arc<Kernels>>>);

/// Compiles the kernels `include` selects into pipelines with `layout`; `source` gives each
/// kernel's module. Validation errors are returned, not raised on the device.
fn compile(
    dev: &wgpu::Device,
    variants: &GpuVariants,
    layout_of: impl Fn(&KernelSpec) -> wgpu::PipelineLayout,
    source: impl Fn(&KernelSpec) -> String,
    include: impl Fn(&KernelSpec) -> bool,
) -> Result<Vec<Option<wgpu::ComputePipeline>>> {
    let (pipelines, error) = super::context::validated(dev, || {
        SPECS
            .iter()
            .map(|s| {
                include(s).then(|| {
                    let desc = wgpu::ShaderModuleDescriptor {
                        label: Some(s.label),
                        source: wgpu::ShaderSource::Wgsl(source(s).into()),
                    };
                    let module = if variants.checks {
                        dev.create_shader_module(desc)
                    } else {
                        // SAFETY: `checks=off` drops bounds checks and loop bounding (integer
                        // division keeps its guards), which is sound because no kernel indexes out
                        // of bounds or loops without end:
                        // - every per-ray kernel returns (or, with appends, does nothing) for an
                        //   invocation at or past its queue's length, and the queues, hits, resolve
                        //   and accumulation buffers hold a whole tile (`ensure_work` sizes them by
                        //   `tile_pixels`, the shadow queue by `tile_pixels * max_lights`; a tile's
                        //   pixels and `tile_offset + i` are within the frame the camera uniform
                        //   describes);
                        // - the walks index their arrays with what the upload wrote: the grid's
                        //   cells are clamped to its dims, a cell's and a leaf's references lie in
                        //   `refs` and name triangles below `n_tris` (the builders' invariants,
                        //   checked by the layout tests and the mirror walks), BVH children name
                        //   nodes that exist, and the stacks' pushes are guarded by their depth
                        //   (private: `sp < BVH_STACK`; short: a ring index `% SHORT_STACK`, at most
                        //   SHORT_STACK_MAX, times WORKGROUP plus the lane); the top level of two
                        //   levels (`walks/two_level/`) reads its nodes and the records its leaves
                        //   name, and hands the bottom walk a header the upload wrote (a mesh's
                        //   root, or its triangles' range within `tris`), its stack guarded by
                        //   `sp < TOP_STACK`;
                        // - the counters are indexed by the prelude's slot constants, the materials
                        //   by the scene's own material ids, the lights below `n_lights`;
                        // - every loop is bounded: the DDA by the grid's cells, the BVH walks by
                        //   their nodes (each entered at most once per ray), the light loops by
                        //   `n_lights`, the top level's walk by its nodes (each entered at most
                        //   once) and its leaves' records, the closest-point searches by the grid's rings (clamped
                        //   into its dims, every step at least one cell), the tree's nodes (each
                        //   entered at most once; their stacks guarded by `sp < BVH_STACK`) or the
                        //   irregular grid's rings of top cells and voxel-map rows (clamped into
                        //   its top dims and `2^level`), and no loop's exit depends on a value it
                        //   never changes.
                        // tests/gpu_variants.rs renders and queries every structure with
                        // `checks=off` and compares the results with the checked kernels';
                        // tests/gpu_closest.rs does so for the closest points.
                        unsafe {
                            dev.create_shader_module_trusted(
                                desc,
                                wgpu::ShaderRuntimeChecks {
                                    bounds_checks: false,
                                    force_loop_bounding: false,
                                    ..wgpu::ShaderRuntimeChecks::checked()
                                },
                            )
                        }
                    };
                    let constants: Vec<(&str, f64)> = s.overrides.iter().copied().chain(variants.overrides()).collect();
                    dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(s.label),
                        layout: Some(&layout_of(s)),
                        module: &module,
                        entry_point: Some("main"),
                        compilation_options: wgpu::PipelineCompilationOptions {
                            constants: &constants,
                            // Every kernel that reads workgroup memory writes it first (`append`,
                            // the short stacks), so `checks=off` skips zeroing it.
                            zero_initialize_workgroup_memory: variants.checks,
                        },
                        cache: None,
                    })
                })
            })
            .collect()
    });
    if let Some(e) = error {
        return Err(Error::Gpu(format!("creating the kernels failed ({variants}): {e}")));
    }
    Ok(pipelines)
}

impl Kernels {
    /// The kernels of `ctx`'s device for `variants`, compiled on first use and shared by every
    /// renderer on it with the same variants.
    pub fn of(ctx: &GpuContext, variants: &GpuVariants) -> Result<Arc<Kernels>> {
        let sets = ctx.cached(|_| Ok(KernelSets::default()))?;
        // Held while compiling: a second renderer with these variants waits for the first's.
        let mut sets = sets.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(k) = sets.get(variants) {
            return Ok(k.clone());
        }
        variants.supported_on(ctx).map_err(Error::Gpu)?;
        let k = Arc::new(Kernels::new(&ctx.device, variants)?);
        sets.insert(*variants, k.clone());
        Ok(k)
    }

    /// Compiles every kernel that walks no structure.
    pub fn new(dev: &wgpu::Device, variants: &GpuVariants) -> Result<Kernels> {
        let frame_rows: Vec<_> = SPECS.iter().map(|s| bindings::frame_rows(s.file())).collect();
        let frame_layouts: Vec<_> = SPECS
            .iter()
            .zip(&frame_rows)
            .map(|(s, rows)| {
                dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some(s.label),
                    entries: &bindings::layout_entries(rows),
                })
            })
            .collect();
        let indirect_layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("indirect args"),
            entries: &bindings::layout_entries(&INDIRECT_BINDINGS),
        });
        let pack_layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("packed pixels"),
            entries: &bindings::layout_entries(&PACK_BINDINGS),
        });
        let batch_layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ray batch"),
            entries: &bindings::layout_entries(&BATCH_BINDINGS),
        });
        let winding_layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("winding tree"),
            entries: &bindings::layout_entries(&WINDING_BINDINGS),
        });
        let layout = |groups: &[Option<&wgpu::BindGroupLayout>]| {
            dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("gridtrace"),
                bind_group_layouts: groups,
                immediate_size: 0,
            })
        };
        let pipelines = compile(
            dev,
            variants,
            |s| {
                let frame = Some(&frame_layouts[s.kernel as usize]);
                match s.group1 {
                    Group1::None => layout(&[frame]),
                    Group1::IndirectArgs => layout(&[frame, Some(&indirect_layout)]),
                    Group1::Packed => layout(&[frame, Some(&pack_layout)]),
                    Group1::Batch => layout(&[frame, Some(&batch_layout)]),
                    Group1::BatchWinding => layout(&[frame, Some(&batch_layout), Some(&winding_layout)]),
                }
            },
            |s| shaders::module_source_for(s.source, variants),
            |s| !s.walks,
        )?;
        Ok(Kernels {
            variants: *variants,
            frame_rows,
            frame_layouts,
            indirect_layout,
            pack_layout,
            batch_layout,
            winding_layout,
            pipelines,
            walks: Mutex::new(HashMap::new()),
        })
    }

    /// The walking pipelines of the walk `spec` describes, compiled on first use.
    pub fn walk(&self, dev: &wgpu::Device, spec: &'static WalkSpec) -> Result<Arc<WalkPipelines>> {
        let mut walks = self.walks.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(w) = walks.get(spec.name) {
            return Ok(w.clone());
        }
        let rows: Vec<Binding<usize>> = spec
            .arrays
            .iter()
            .enumerate()
            .map(|(i, (_, name))| Binding {
                index: i as u32,
                name,
                access: Access::StorageRead,
                slot: i,
            })
            .collect();
        let mut entries = bindings::layout_entries(&rows);
        if spec.tlas.is_some() {
            // A walk by ray query binds its top-level structure after its arrays.
            entries.push(wgpu::BindGroupLayoutEntry {
                binding: rows.len() as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::AccelerationStructure { vertex_return: false },
                count: None,
            });
        }
        let layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(spec.structure.name()),
            entries: &entries,
        });
        let pipelines = compile(
            dev,
            &self.variants,
            |s| {
                dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some(spec.structure.name()),
                    bind_group_layouts: &[Some(&self.frame_layouts[s.kernel as usize]), Some(&layout)],
                    immediate_size: 0,
                })
            },
            |s| shaders::walk_module_source(s.source, spec),
            // The closest-point kernel only with a walk that searches points.
            |s| s.walks && !s.on_demand() && (spec.points() || s.kernel != Kernel::ClosestPoint),
        )?;
        let w = Arc::new(WalkPipelines {
            spec,
            layout,
            pipelines,
            on_demand: std::sync::OnceLock::new(),
        });
        walks.insert(spec.name, w.clone());
        Ok(w)
    }

    /// Compiles `walk`'s pipelines of the kernels compiled on first use (the all-hits kernels:
    /// group 0, the structure's arrays, the batch's buffers), unless compiled already.
    pub fn prepare(&self, dev: &wgpu::Device, walk: &WalkPipelines) -> Result<()> {
        if walk.on_demand.get().is_some() {
            return Ok(());
        }
        let pipelines = compile(
            dev,
            &self.variants,
            |s| {
                dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some(walk.spec.structure.name()),
                    bind_group_layouts: &[
                        Some(&self.frame_layouts[s.kernel as usize]),
                        Some(&walk.layout),
                        Some(&self.batch_layout),
                    ],
                    immediate_size: 0,
                })
            },
            |s| shaders::walk_module_source(s.source, walk.spec),
            KernelSpec::on_demand,
        )?;
        // A second caller's set, compiled at the same time, is the same.
        let _ = walk.on_demand.set(pipelines);
        Ok(())
    }
}

/// One bounce's group 0 for every kernel: the same buffers, each kernel's bind group holding the
/// rows its layout has (indexed by `kernel as usize`).
pub(crate) struct FrameGroups(Vec<wgpu::BindGroup>);

impl Kernels {
    /// One bounce's group 0 for every kernel, binding what `resource` names for each slot.
    pub fn frame_groups<'a>(
        &self,
        dev: &wgpu::Device,
        resource: impl Fn(FrameSlot) -> wgpu::BindingResource<'a>,
    ) -> FrameGroups {
        FrameGroups(
            SPECS
                .iter()
                .zip(self.frame_rows.iter().zip(&self.frame_layouts))
                .map(|(s, (rows, layout))| {
                    dev.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some(s.label),
                        layout,
                        entries: &bindings::group_entries(rows, &resource),
                    })
                })
                .collect(),
        )
    }
}

/// Records compute passes into one submission: binds each kernel's groups and sizes its
/// dispatch as its spec says, and takes its timestamps.
pub(crate) struct PassRecorder<'a> {
    pub kernels: &'a Kernels,
    /// The indirect-args buffer and its group-1 bind group.
    pub indirect_args: &'a wgpu::Buffer,
    pub indirect_group: &'a wgpu::BindGroup,
    /// The packed-pixels group of the pack kernel (the frame's work buffers hold it).
    pub packed_group: Option<&'a wgpu::BindGroup>,
    /// The ray batch's group 1 (`queries.rs`), for its two kernels.
    pub batch_group: Option<&'a wgpu::BindGroup>,
    /// The fast winding tree's group (`winding.rs`), for the winding kernel.
    pub winding_group: Option<&'a wgpu::BindGroup>,
    /// The scene's structure's walking pipelines and its group 1.
    pub walk: &'a WalkPipelines,
    pub structure_group: &'a wgpu::BindGroup,
    /// The `shadow_closest_hit` ablation: occlusion runs its closest-hit pipeline.
    pub shadow_closest_hit: bool,
    /// Pixels of the tile (sizes `Launch::PerPixel` kernels).
    pub tile_pixels: u32,
    pub timer: StageTimer<'a>,
}

impl PassRecorder<'_> {
    /// One compute pass running `kernel` with its group 0 of `frame`.
    pub fn pass(&mut self, enc: &mut wgpu::CommandEncoder, kernel: Kernel, frame: &FrameGroups) {
        let kernel = match (kernel, self.shadow_closest_hit) {
            (Kernel::Occlusion, true) => Kernel::OcclusionClosest,
            (k, _) => k,
        };
        let spec = spec_of(kernel);
        let timestamp_writes = self.timer.pass_writes(spec.stage);
        let mut cp = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(spec.stage),
            timestamp_writes,
        });
        let pipelines = if spec.on_demand() {
            self.walk
                .on_demand
                .get()
                .expect("`Kernels::prepare` compiles them before they run")
        } else if spec.walks {
            &self.walk.pipelines
        } else {
            &self.kernels.pipelines
        };
        cp.set_pipeline(
            pipelines[kernel as usize]
                .as_ref()
                .expect("every kernel is compiled for its set"),
        );
        cp.set_bind_group(FRAME_GROUP, &frame.0[kernel as usize], &[]);
        if spec.walks {
            cp.set_bind_group(STRUCTURE_GROUP, self.structure_group, &[]);
        }
        match spec.group1 {
            Group1::None => {}
            Group1::IndirectArgs => cp.set_bind_group(INDIRECT_GROUP, self.indirect_group, &[]),
            Group1::Packed => cp.set_bind_group(
                PACK_GROUP,
                self.packed_group
                    .expect("the pack kernel runs with the frame's packed pixels"),
                &[],
            ),
            Group1::Batch => cp.set_bind_group(
                // A walking kernel's group 1 is its structure's arrays.
                if spec.walks {
                    BATCH_AFTER_WALK_GROUP
                } else {
                    BATCH_GROUP
                },
                self.batch_group.expect("the batch kernels run with a batch's buffers"),
                &[],
            ),
            Group1::BatchWinding => {
                let batch = self
                    .batch_group
                    .expect("the winding kernel runs with a batch's buffers");
                cp.set_bind_group(BATCH_GROUP, batch, &[]);
                let tree = self
                    .winding_group
                    .expect("the winding kernel runs with an uploaded tree");
                cp.set_bind_group(WINDING_GROUP, tree, &[]);
            }
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

    /// The walking kernels are exactly traverse, occlusion (with their heat and closest-hit
    /// forms) and closest point, whose modules include a walk file; their overrides survive.
    #[test]
    fn walking_kernels_are_traverse_occlusion_and_closest_point() {
        for s in &SPECS {
            assert_eq!(s.walks, shaders::walks(s.stage), "{}", s.label);
            let overrides: Vec<_> = s.overrides.iter().map(|o| o.0).collect();
            assert_eq!(overrides.contains(&"COUNT_WORK"), s.kernel == Kernel::TraverseHeat);
            assert_eq!(
                overrides.contains(&"SHADOW_CLOSEST"),
                s.kernel == Kernel::OcclusionClosest
            );
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
        // The grid build's scan: a workgroup per 1024 cells (its `SCAN_BLOCK`) of 2^26.
        let block = 1024;
        let (x, y) = dispatch_groups(1 << 26, block);
        assert!(x <= 65535 && y <= 65535 && x as u64 * y as u64 * block as u64 >= 1 << 26);
    }
}
