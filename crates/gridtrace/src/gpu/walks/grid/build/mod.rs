//! The uniform grid and its proximity cloud built on the GPU, for meshes whose vertices move
//! (Kalojanov and Slusallek 2009, with the sort replaced by a counting sort; see below). The
//! result has the CPU build's layout (`Grid`: cells of `start, count, dist` and one packed
//! reference list, ascending within a cell), so the same traversal kernels walk it, and a test
//! compares the two builds cell by cell.
//!
//! Stages, each a kernel in this folder (`*.wgsl`):
//! 1. `count` (per triangle): every cell the triangle overlaps (the CPU's exact test, on the
//!    same lattice, `GridLattice`) gets one more reference, by an atomic add;
//! 2. `scan`: exclusive prefix sums of the counts give the cells' `start`s and the total;
//! 3. `place` (per triangle): the same test again, each triangle written into its cells' next
//!    free slots (an atomic cursor per cell);
//! 4. `sort` (per cell): the cell's slots into ascending triangle order;
//! 5. `distance`: the chessboard distance transform, one pass per axis.
//!
//! Why a counting sort and not Kalojanov's radix sort of (cell, triangle) pairs: the sort key
//! is the cell index, and the key histogram a radix sort would build *is* the per-cell count
//! of stage 1; sorting by the whole key in one counting pass needs no pair array (8 bytes per
//! reference written and read back four to seven times, once per radix digit) and no sort
//! library. No maintained wgpu sort or scan crate targets wgpu 30 (those found, such as
//! `wgpu_sort`, pin older wgpu versions and need subgroup operations that lavapipe and WebGPU do
//! not guarantee), so the scan is this module's own, in plain WGSL. The price of the atomic
//! placement is a scheduling-dependent order inside a cell, which stage 4 undoes.
//!
//! The lattice (bounds and dimensions) comes from the host, computed by the same function as
//! the CPU build's: it decides buffer sizes, which the host must know before it records the
//! build, and it makes both builds test the very same cell boxes.

use crate::util::Instant;
use std::mem::size_of;
use std::sync::Arc;

use wgpu::util::DeviceExt;

use bytemuck::{Pod, Zeroable};

mod pipelines;

pub(crate) use pipelines::BuildKernels;
pub use pipelines::{KERNEL_SOURCES, module_source};
use pipelines::{STAGES, Stage};

use crate::accel::{Cell, Grid, GridLattice, Resolution, TriAccel};
use crate::gpu::constants::{WORKGROUP, dispatch_groups};
use crate::gpu::context::{GpuContext, check_scene_fits};
use crate::gpu::layout::GpuTri;
use crate::gpu::timing::{GpuTimings, StageTimer, Timestamps};
use crate::{Error, Result};

/// Elements one workgroup of the GPU grid build's scan sums (256 invocations, 4 each); the
/// host sizes the scan's levels by it.
pub const SCAN_BLOCK: u32 = 1024;
/// Cells one triangle may span in the GPU grid build; a grid with a larger triangle is built
/// on the CPU instead. One invocation walks a triangle's cells, and lavapipe (Mesa's llvmpipe)
/// stops an invocation's loops after 65535 iterations in total, silently: measured, a triangle
/// over 64,000 cells got only its first 22,000 or so. A quarter of that budget leaves room;
/// at the automatic resolution only floor-like triangles of million-triangle scenes come near.
pub const MAX_CELLS_PER_TRI: u32 = 16384;
/// Longest line of cells the GPU distance transform takes (about three loop iterations per
/// cell; see `MAX_CELLS_PER_TRI`). The automatic resolution stays under 1024.
pub const MAX_GPU_LINE: u32 = 16384;
/// Cells with more references keep the GPU placing order (insertion sort is quadratic: 256
/// references take at most 32,640 steps, within the budget above).
pub const SORT_MAX_REFS: u32 = 256;
/// Invocations per workgroup of the grid build's scan kernels (`scan.wgsl`'s `partial`
/// array); the other kernels have `WORKGROUP`.
pub const SCAN_GROUP: u32 = 256;
// A scan block is four elements per invocation of a workgroup (`scan.wgsl`).
const _: () = assert!(SCAN_BLOCK == 4 * SCAN_GROUP);

/// The uniform of one GPU grid-build dispatch (`common.wgsl` here): the lattice, the
/// sizes, and the scan level or distance axis it works on. 80 bytes, one per 256-byte slot.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GridBuildUniform {
    pub bounds_min: [f32; 3],
    pub n_tris: u32,
    pub cell_size: [f32; 3],
    pub n_cells: u32,
    pub inv_cell_size: [f32; 3],
    /// Slots of the references buffer; a build that needs more is run again, larger.
    pub refs_capacity: u32,
    pub margin: [f32; 3],
    /// Distance transform: the axis of this pass (0 = x).
    pub axis: u32,
    pub dims: [u32; 3],
    /// Elements of this scan level, or lines of this distance pass.
    pub n: u32,
    /// Scan: where this level's elements (`in_offset`) and block totals (`out_offset`) are in
    /// the sums buffer.
    pub in_offset: u32,
    pub out_offset: u32,
    /// Scan: 1 on the top level, whose single block total is the number of references.
    pub last: u32,
    pub _pad0: u32,
}

/// Bytes between two dispatches' parameters (dynamic uniform offsets must be multiples of the
/// device's alignment; 256 is WebGPU's largest).
const PARAMS_STRIDE: u64 = 256;
/// Words at the start of the sums buffer before the scan levels: word 0 is the total.
const STATUS_WORDS: u32 = 4;
/// References a first build of an unknown mesh allows per triangle before it has to grow the
/// buffer and run again (the automatic resolution gives 1.5-3 on the meshes we measured).
const INITIAL_REFS_PER_TRI: u64 = 4;

/// What one GPU build did and how long it took.
#[derive(Debug, Clone, Default)]
pub struct GpuBuildStats {
    pub dims: [u32; 3],
    pub references: u64,
    /// Per stage (`count`, `scan`, `place`, `sort`, `distance`) and in total: GPU time from
    /// timestamp queries where the device has them; else the total is the wall time from
    /// submission to the result being known (which includes one read-back).
    pub timings: GpuTimings,
    /// Submissions it took: 2 when the references outgrew their buffer and it ran again.
    pub attempts: u32,
    /// Why this grid was built on the CPU and uploaded instead (a triangle over
    /// `MAX_CELLS_PER_TRI` cells, a line over `MAX_GPU_LINE`); `None` for a GPU build.
    pub cpu_fallback: Option<String>,
}

/// A grid built, and rebuilt, on the device: its cells and references in the CPU build's
/// layout, and the scratch the build needs, kept between builds so that a rebuild per frame
/// allocates nothing unless the grid grows.
pub struct GpuGrid {
    ctx: Arc<GpuContext>,
    kernels: Arc<BuildKernels>,
    pub(crate) cells: wgpu::Buffer,
    pub(crate) refs: wgpu::Buffer,
    sums: wgpu::Buffer,
    dt_a: wgpu::Buffer,
    dt_b: wgpu::Buffer,
    stack: wgpu::Buffer,
    params: wgpu::Buffer,
    timestamps: Option<Timestamps>,
    lattice: Option<GridLattice>,
    references: u64,
}

/// A storage buffer of `bytes` (at least 16: empty bindings are invalid).
fn storage_buffer(dev: &wgpu::Device, label: &str, bytes: u64) -> wgpu::Buffer {
    dev.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16).next_multiple_of(4),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

/// The scan's levels above the cells: `(offset in sums, elements)` of each level of block
/// totals, the last of one element (the total).
fn scan_levels(n_cells: u32) -> Vec<(u32, u32)> {
    let mut levels = Vec::new();
    let mut offset = STATUS_WORDS;
    let mut n = n_cells.div_ceil(SCAN_BLOCK).max(1);
    loop {
        levels.push((offset, n));
        offset += n;
        if n == 1 {
            return levels;
        }
        n = n.div_ceil(SCAN_BLOCK);
    }
}

impl GpuGrid {
    /// An empty grid on `ctx`'s device (compiles the build kernels on first use).
    pub fn new(ctx: Arc<GpuContext>) -> Result<GpuGrid> {
        let kernels = ctx.cached(BuildKernels::new)?;
        let dev = &ctx.device;
        let params = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("grid build params"),
            size: PARAMS_STRIDE * 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let timestamps = Timestamps::new(&ctx);
        Ok(GpuGrid {
            cells: storage_buffer(dev, "cells", 0),
            refs: storage_buffer(dev, "refs", 0),
            sums: storage_buffer(dev, "scan sums", 0),
            dt_a: storage_buffer(dev, "distance x", 0),
            dt_b: storage_buffer(dev, "distance xy", 0),
            stack: storage_buffer(dev, "distance stack", 0),
            params,
            timestamps,
            lattice: None,
            references: 0,
            kernels,
            ctx,
        })
    }

    /// Uploads `tris` and builds the grid at `resolution` over them: for tests and benchmarks
    /// that start from triangles on the host.
    pub fn build_from(
        ctx: Arc<GpuContext>,
        tris: &[TriAccel],
        resolution: Resolution,
    ) -> Result<(GpuGrid, GpuBuildStats)> {
        let lattice = GridLattice::new(tris, resolution)?;
        // Zero-length buffers cannot be bound: an empty scene uploads one zero triangle.
        let gpu_tris = if tris.is_empty() {
            vec![<GpuTri as bytemuck::Zeroable>::zeroed()]
        } else {
            GpuTri::all(tris)
        };
        check_scene_fits(
            &[("triangles", std::mem::size_of_val(&gpu_tris[..]) as u64)],
            &ctx.limits(),
            &ctx.info.name,
        )?;
        let buf = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("triangles"),
            contents: bytemuck::cast_slice(&gpu_tris),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let mut grid = GpuGrid::new(ctx)?;
        let stats = grid.build(&buf, tris, &lattice)?;
        Ok((grid, stats))
    }

    /// The lattice of the last build.
    pub fn lattice(&self) -> Option<&GridLattice> {
        self.lattice.as_ref()
    }

    /// References of the last build.
    pub fn references(&self) -> u64 {
        self.references
    }

    /// Bytes of the grid's own arrays (cells and references) and of the build's scratch.
    pub fn memory(&self) -> Vec<(&'static str, u64)> {
        let cells = self.lattice.map_or(0, |l| l.cells() as u64);
        vec![
            ("cells", cells * size_of::<Cell>() as u64),
            ("refs", self.references * 4),
            (
                "build scratch",
                self.sums.size() + self.dt_a.size() + self.dt_b.size() + self.stack.size(),
            ),
        ]
    }

    /// Builds the grid over the triangles `host_tris`, uploaded in `tris`, on `lattice`
    /// (`GridLattice::new` over the same triangles). The previous grid is replaced; on an
    /// error it may be partly overwritten, and the caller must not trace it. The host's copy
    /// serves the rare grid the GPU build does not take (`GpuBuildStats::cpu_fallback`).
    pub fn build(
        &mut self,
        tris: &wgpu::Buffer,
        host_tris: &[TriAccel],
        lattice: &GridLattice,
    ) -> Result<GpuBuildStats> {
        let n_tris = host_tris.len() as u32;
        let n_cells = lattice.cells() as u64;
        if lattice.dims.max_element() > MAX_GPU_LINE {
            return self.build_on_cpu(
                host_tris,
                lattice,
                format!(
                    "the grid is {} cells long; the GPU distance transform takes lines up to {MAX_GPU_LINE}",
                    lattice.dims.max_element()
                ),
            );
        }
        if (tris.size() / size_of::<GpuTri>() as u64) < n_tris as u64 {
            return Err(Error::InvalidInput(format!(
                "the triangle buffer holds {} triangles, the build was asked for {n_tris}",
                tris.size() / size_of::<GpuTri>() as u64
            )));
        }
        let mut stats = GpuBuildStats {
            dims: lattice.dims.to_array(),
            ..Default::default()
        };
        // Start from the last build's references (a moving mesh changes them little), or a
        // guess; a build that outgrows the buffer is run again with room for all of them.
        let mut want_refs = (self.references + self.references / 4).max(n_tris as u64 * INITIAL_REFS_PER_TRI);
        loop {
            stats.attempts += 1;
            self.reserve(n_cells, want_refs)?;
            let t0 = Instant::now();
            let timer = self.record(tris, n_tris, lattice)?;
            let status = self.ctx.read_buffer(&self.sums, 8)?;
            let word =
                |i: usize| u32::from_le_bytes([status[4 * i], status[4 * i + 1], status[4 * i + 2], status[4 * i + 3]]);
            let total = word(0) as u64;
            if word(1) != 0 {
                return self.build_on_cpu(
                    host_tris,
                    lattice,
                    format!("a triangle spans more than {MAX_CELLS_PER_TRI} cells"),
                );
            }
            let wall_ms = t0.elapsed().as_secs_f64() * 1e3;
            let stages = timer.read(&self.ctx)?;
            self.ctx.check_errors()?;
            if total > self.refs.size() / 4 {
                if stats.attempts >= 2 {
                    return Err(Error::Gpu(format!(
                        "the grid build needed {total} references after growing its buffer to {}",
                        self.refs.size() / 4
                    )));
                }
                want_refs = total + total / 8;
                continue;
            }
            self.references = total;
            self.lattice = Some(*lattice);
            stats.references = total;
            let t = &mut stats.timings;
            t.from_timestamps = !stages.is_empty();
            for (name, ms) in stages {
                *t.stages_ms.entry(name).or_default() += ms;
            }
            t.total_ms = if t.from_timestamps {
                t.stages_ms.values().sum()
            } else {
                wall_ms
            };
            return Ok(stats);
        }
    }

    /// Builds on the CPU and uploads the result into the grid's buffers.
    fn build_on_cpu(&mut self, host_tris: &[TriAccel], lattice: &GridLattice, why: String) -> Result<GpuBuildStats> {
        let t0 = Instant::now();
        let grid = Grid::build_on(host_tris, *lattice, t0);
        self.reserve(grid.cells.len() as u64, grid.refs.len() as u64)?;
        self.ctx
            .queue
            .write_buffer(&self.cells, 0, bytemuck::cast_slice(&grid.cells));
        if !grid.refs.is_empty() {
            self.ctx
                .queue
                .write_buffer(&self.refs, 0, bytemuck::cast_slice(&grid.refs));
        }
        self.ctx.wait()?;
        self.references = grid.refs.len() as u64;
        self.lattice = Some(*lattice);
        Ok(GpuBuildStats {
            dims: lattice.dims.to_array(),
            references: self.references,
            timings: GpuTimings {
                total_ms: t0.elapsed().as_secs_f64() * 1e3,
                ..Default::default()
            },
            attempts: 1,
            cpu_fallback: Some(why),
        })
    }

    /// Makes the buffers hold `n_cells` cells and `n_refs` references (a renderer binding
    /// `cells` and `refs` sees a reallocation as a different buffer). Sizes over the device's
    /// limits are errors that name the array and the limit.
    fn reserve(&mut self, n_cells: u64, n_refs: u64) -> Result<()> {
        let levels = scan_levels(n_cells as u32);
        let sums_words = levels.last().map_or(STATUS_WORDS, |l| l.0 + l.1) as u64;
        let need = [
            ("cells", n_cells * size_of::<Cell>() as u64),
            ("refs", n_refs * 4),
            ("distance stack", n_cells * 8),
            ("distance x", n_cells * 4),
        ];
        check_scene_fits(&need, &self.ctx.limits(), &self.ctx.info.name)?;
        let dev = &self.ctx.device;
        let grow = |buf: &mut wgpu::Buffer, label: &str, bytes: u64| {
            if buf.size() < bytes {
                // Room to grow a little, so that a moving mesh does not reallocate every frame.
                *buf = storage_buffer(dev, label, bytes + bytes / 8);
            }
        };
        grow(&mut self.cells, "cells", need[0].1);
        grow(&mut self.refs, "refs", need[1].1.max(4));
        grow(&mut self.stack, "distance stack", need[2].1);
        grow(&mut self.dt_a, "distance x", need[3].1);
        grow(&mut self.dt_b, "distance xy", need[3].1);
        grow(&mut self.sums, "scan sums", sums_words * 4);
        // The dispatches: count, place, sort, three distance passes, and per scan level at
        // most a scan and an add.
        let params_bytes = (6 + 2 * levels.len() as u64 + 1) * PARAMS_STRIDE;
        if self.params.size() < params_bytes {
            self.params = dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some("grid build params"),
                size: params_bytes,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
        }
        Ok(())
    }

    /// Records and submits the build over `tris`.
    fn record(&self, tris: &wgpu::Buffer, n_tris: u32, lattice: &GridLattice) -> Result<StageTimer<'_>> {
        let dev = &self.ctx.device;
        let n_cells = lattice.cells() as u32;
        let refs_capacity = (self.refs.size() / 4).min(u32::MAX as u64) as u32;
        let plan = build_plan(n_tris, lattice, refs_capacity);

        let params_bytes = plan.len() as u64 * PARAMS_STRIDE;
        debug_assert!(params_bytes <= self.params.size(), "`reserve` sizes the params");
        let mut bytes = vec![0u8; params_bytes as usize];
        for (i, (_, p, _)) in plan.iter().enumerate() {
            let at = i * PARAMS_STRIDE as usize;
            bytes[at..at + size_of::<GridBuildUniform>()].copy_from_slice(bytemuck::bytes_of(p));
        }
        self.ctx.queue.write_buffer(&self.params, 0, &bytes);

        let entries = [
            (0, &self.params),
            (1, tris),
            (2, &self.cells),
            (3, &self.refs),
            (4, &self.sums),
            (5, &self.dt_a),
            (6, &self.dt_b),
            (7, &self.stack),
        ];
        let bind_group = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("grid build"),
            layout: &self.kernels.layout,
            entries: &entries
                .iter()
                .map(|&(binding, buffer)| wgpu::BindGroupEntry {
                    binding,
                    resource: if binding == 0 {
                        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer,
                            offset: 0,
                            size: wgpu::BufferSize::new(size_of::<GridBuildUniform>() as u64),
                        })
                    } else {
                        buffer.as_entire_binding()
                    },
                })
                .collect::<Vec<_>>(),
        });

        let mut timer = StageTimer::new(self.timestamps.as_ref());
        let mut enc = dev.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("grid build"),
        });
        enc.clear_buffer(&self.cells, 0, Some(n_cells as u64 * size_of::<Cell>() as u64));
        enc.clear_buffer(&self.sums, 0, Some(STATUS_WORDS as u64 * 4));
        for (i, (stage, _, (x, y))) in plan.iter().enumerate() {
            if *x == 0 {
                continue;
            }
            let spec = &STAGES[*stage as usize];
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(spec.name),
                timestamp_writes: timer.pass_writes(spec.name),
            });
            pass.set_pipeline(&self.kernels.pipelines[*stage as usize]);
            pass.set_bind_group(0, &bind_group, &[(i as u64 * PARAMS_STRIDE) as u32]);
            pass.dispatch_workgroups(*x, *y, 1);
        }
        timer.resolve(&mut enc);
        self.ctx.queue.submit([enc.finish()]);
        Ok(timer)
    }

    /// The grid's cells and references, read back (for tests and for the CPU to trace a grid
    /// the GPU built).
    pub fn read_back(&self) -> Result<(Vec<Cell>, Vec<u32>)> {
        let Some(lattice) = self.lattice else {
            return Ok((Vec::new(), Vec::new()));
        };
        let cells = self
            .ctx
            .read_buffer(&self.cells, lattice.cells() as u64 * size_of::<Cell>() as u64)?;
        let refs = self.ctx.read_buffer(&self.refs, self.references * 4)?;
        Ok((
            bytemuck::cast_slice(&cells).to_vec(),
            bytemuck::cast_slice(&refs).to_vec(),
        ))
    }
}

/// Every dispatch of a build over `n_tris` triangles into `lattice`, in order: its stage, its
/// parameters and its workgroups (count, the scan's levels up and back down, place, sort, the
/// distance transform's three axes).
fn build_plan(n_tris: u32, lattice: &GridLattice, refs_capacity: u32) -> Vec<(Stage, GridBuildUniform, (u32, u32))> {
    let n_cells = lattice.cells() as u32;
    let base = GridBuildUniform {
        bounds_min: lattice.bounds.min.to_array(),
        n_tris,
        cell_size: lattice.cell_size.to_array(),
        n_cells,
        inv_cell_size: lattice.inv_cell_size.to_array(),
        refs_capacity,
        margin: lattice.margin.to_array(),
        axis: 0,
        dims: lattice.dims.to_array(),
        n: 0,
        in_offset: 0,
        out_offset: 0,
        last: 0,
        _pad0: 0,
    };
    // Every dispatch: stage, parameters, workgroups. (The bind group is made per build: the
    // triangle buffer is the caller's and may change.)
    let mut plan: Vec<(Stage, GridBuildUniform, (u32, u32))> = Vec::new();
    let per_tri = dispatch_groups(n_tris, WORKGROUP);
    plan.push((Stage::Count, base, per_tri));
    let levels = scan_levels(n_cells);
    let top = levels.len() - 1;
    plan.push((
        Stage::ScanCells,
        GridBuildUniform {
            n: n_cells,
            out_offset: levels[0].0,
            last: (top == 0) as u32,
            ..base
        },
        dispatch_groups(n_cells, SCAN_BLOCK),
    ));
    for j in 0..top {
        let (offset, n) = levels[j];
        plan.push((
            Stage::ScanSums,
            GridBuildUniform {
                n,
                in_offset: offset,
                out_offset: levels[j + 1].0,
                last: (j + 1 == top) as u32,
                ..base
            },
            dispatch_groups(n, SCAN_BLOCK),
        ));
    }
    for j in (0..top).rev() {
        let (offset, n) = levels[j];
        // The scanned block totals one level up go back into the level. A level of one
        // block has nothing to add (and the level above it is the raw total, not scanned).
        if n > SCAN_BLOCK {
            plan.push((
                Stage::AddSums,
                GridBuildUniform {
                    n,
                    in_offset: offset,
                    out_offset: levels[j + 1].0,
                    ..base
                },
                dispatch_groups(n, SCAN_GROUP),
            ));
        }
    }
    if n_cells > SCAN_BLOCK {
        plan.push((
            Stage::AddCells,
            GridBuildUniform {
                n: n_cells,
                out_offset: levels[0].0,
                ..base
            },
            dispatch_groups(n_cells, SCAN_GROUP),
        ));
    }
    plan.push((Stage::Place, base, per_tri));
    plan.push((Stage::Sort, base, dispatch_groups(n_cells, WORKGROUP)));
    let d = lattice.dims;
    for (axis, lines) in [(0u32, d.y * d.z), (1, d.x * d.z), (2, d.x * d.y)] {
        plan.push((
            Stage::Distance,
            GridBuildUniform { axis, n: lines, ..base },
            dispatch_groups(lines, WORKGROUP),
        ));
    }
    plan
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scan_levels_end_in_one_total() {
        assert_eq!(scan_levels(1), vec![(STATUS_WORDS, 1)]);
        assert_eq!(scan_levels(SCAN_BLOCK), vec![(STATUS_WORDS, 1)]);
        assert_eq!(
            scan_levels(SCAN_BLOCK + 1),
            vec![(STATUS_WORDS, 2), (STATUS_WORDS + 2, 1)]
        );
        let l = scan_levels(1 << 26);
        assert_eq!(l.iter().map(|x| x.1).collect::<Vec<_>>(), vec![65536, 64, 1]);
    }
}
