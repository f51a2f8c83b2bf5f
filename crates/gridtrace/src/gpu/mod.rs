//! The GPU backend: the paper's streaming ray tracer (its Figure 1) as wgpu compute kernels.
//!
//! Per image tile: `raygen` fills ray queue A with eye rays (rays that miss the grid are finished
//! at once); then per bounce `traverse` finds closest hits, `shade` writes colour and emits
//! shadow rays and reflection rays into compacted queues (atomic counters), `occlusion` runs the
//! shadow queue (any hit), and `resolve` adds the unoccluded contributions. Every dispatch after
//! ray generation is indirect, sized on the GPU by `indirect` from the queue lengths, so
//! finished rays cost nothing later: today's form of the paper's ray masks and early-Z.

mod context;
pub mod layout;

use std::collections::BTreeMap;
use std::time::Instant;

use glam::Vec3;
use wgpu::util::DeviceExt;

pub use context::GpuContext;
use layout::*;

use crate::accel::{AccelKind, Hit, Ray};
use crate::render::{Image, Mode, RenderOptions, RenderStats};
use crate::scene::{Camera, PointLight, PreparedScene};
use crate::{Error, Result};

/// WGSL sources: the shared file and one per kernel.
pub mod shaders {
    pub const COMMON: &str = include_str!("shaders/common.wgsl");
    pub const RAYGEN: &str = include_str!("shaders/raygen.wgsl");
    pub const TRAVERSE: &str = include_str!("shaders/traverse.wgsl");
    pub const OCCLUSION: &str = include_str!("shaders/occlusion.wgsl");
    pub const SHADE: &str = include_str!("shaders/shade.wgsl");
    pub const RESOLVE: &str = include_str!("shaders/resolve.wgsl");
    pub const INDIRECT: &str = include_str!("shaders/indirect.wgsl");
    /// Every kernel with its name.
    pub const KERNELS: [(&str, &str); 6] = [
        ("raygen", RAYGEN),
        ("traverse", TRAVERSE),
        ("occlusion", OCCLUSION),
        ("shade", SHADE),
        ("resolve", RESOLVE),
        ("indirect", INDIRECT),
    ];
}

const WORKGROUP: u32 = 64;
/// Largest tile in pixels: bounds queue memory and keeps each submission short for watchdogs.
pub const MAX_TILE_PIXELS: u32 = 1 << 20;
/// Uniform offsets must be multiples of this (WebGPU's minimum alignment).
const UNIFORM_STRIDE: u64 = 256;
/// Bounces per frame at most: eye + two reflection levels.
const MAX_PASSES: usize = 3;

/// GPU time per stage (from timestamp queries when the adapter has them).
#[derive(Debug, Default, Clone)]
pub struct GpuTimings {
    /// Milliseconds per stage name, summed over bounces and tiles.
    pub stages_ms: BTreeMap<&'static str, f64>,
    /// Sum of all stages (GPU time) or wall time of the submissions when there are no queries.
    pub total_ms: f64,
    /// Whether the figures come from timestamp queries.
    pub from_timestamps: bool,
}

/// Statistics of one GPU frame.
#[derive(Debug, Default, Clone)]
pub struct GpuRenderStats {
    pub render: RenderStats,
    pub timings: GpuTimings,
    pub tiles: u32,
}

struct Pipelines {
    raygen: wgpu::ComputePipeline,
    traverse: wgpu::ComputePipeline,
    traverse_heat: wgpu::ComputePipeline,
    occlusion: wgpu::ComputePipeline,
    shade: wgpu::ComputePipeline,
    resolve: wgpu::ComputePipeline,
    indirect: wgpu::ComputePipeline,
}

/// Queues and per-tile buffers, sized for a tile of `tile_pixels` and `max_lights` lights.
struct WorkBuffers {
    tile_pixels: u32,
    max_lights: u32,
    queue_a: wgpu::Buffer,
    queue_b: wgpu::Buffer,
    hits: wgpu::Buffer,
    shadow: wgpu::Buffer,
    resolve: wgpu::Buffer,
    accum: wgpu::Buffer,
    lights: wgpu::Buffer,
    /// One bind group per bounce (queues A/B swap roles every bounce).
    bind_groups: Vec<wgpu::BindGroup>,
}

/// A scene resident on the GPU. Camera and lights change per frame; nothing else is uploaded
/// again.
pub struct GpuRenderer {
    ctx: GpuContext,
    layout: wgpu::BindGroupLayout,
    pipelines: Pipelines,
    scene_uniform: wgpu::Buffer,
    camera_uniform: wgpu::Buffer,
    pass_uniform: wgpu::Buffer,
    cells: wgpu::Buffer,
    refs: wgpu::Buffer,
    tris: wgpu::Buffer,
    tri_shade: wgpu::Buffer,
    materials: wgpu::Buffer,
    counters: wgpu::Buffer,
    indirect: wgpu::Buffer,
    indirect_group: wgpu::BindGroup,
    query: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    work: Option<WorkBuffers>,
    scene_consts: SceneUniform,
    scene_bytes: Vec<(&'static str, u64)>,
}

fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn uniform_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Number of 64-wide workgroups for `n` items as a 2-D dispatch (the kernels use `flat_index`).
fn dispatch_size(n: u32) -> (u32, u32) {
    let g = n.div_ceil(WORKGROUP);
    let x = g.min(32768);
    (x, if x == 0 { 0 } else { g.div_ceil(x) })
}

/// Checks every scene array (`(name, bytes)`) against the device's per-binding limits before
/// anything is allocated: a scene too large for the device is an error that names the array and
/// the limit, not a validation panic or a lost device.
pub fn check_scene_fits(arrays: &[(&'static str, u64)], limits: &wgpu::Limits, adapter: &str) -> Result<()> {
    let max_binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    for &(name, bytes) in arrays {
        if bytes > max_binding {
            return Err(Error::Gpu(format!(
                "scene array '{name}' needs {bytes} bytes; the device allows {max_binding} per storage buffer \
                 (limit max_storage_buffer_binding_size / max_buffer_size on '{adapter}')"
            )));
        }
    }
    Ok(())
}

impl GpuRenderer {
    /// Uploads the scene (grid, references, triangles, shading data, materials) once.
    pub fn new(ctx: GpuContext, scene: &PreparedScene) -> Result<GpuRenderer> {
        let dev = &ctx.device;
        let limits = ctx.limits();
        let g = &scene.accel.grid;
        let tri_shade: Vec<TriShade> = scene
            .tri_vertices
            .iter()
            .zip(&scene.tri_material)
            .map(|(v, &m)| TriShade {
                n0: scene.normals[v[0] as usize].to_array(),
                n1: scene.normals[v[1] as usize].to_array(),
                n2: scene.normals[v[2] as usize].to_array(),
                material: m,
            })
            .collect();
        let materials: Vec<GpuMaterial> = scene
            .materials
            .iter()
            .map(|m| GpuMaterial {
                diffuse: m.diffuse.to_array(),
                reflectivity: m.reflectivity,
            })
            .collect();
        // Check every scene array against the device's binding limit before allocating.
        let arrays: [(&'static str, &[u8]); 5] = [
            ("cells", bytemuck::cast_slice(&g.cells)),
            ("refs", bytemuck::cast_slice(&g.refs)),
            ("triangles", bytemuck::cast_slice(&scene.accel.tris)),
            ("tri_shade", bytemuck::cast_slice(&tri_shade)),
            ("materials", bytemuck::cast_slice(&materials)),
        ];
        let sizes: Vec<(&'static str, u64)> = arrays.iter().map(|(n, d)| (*n, d.len() as u64)).collect();
        check_scene_fits(&sizes, &limits, &ctx.info.name)?;
        let storage = |label: &str, data: &[u8]| {
            // Zero-length bindings are invalid; give empty arrays one element of padding.
            let contents: &[u8] = if data.is_empty() { &[0u8; 16] } else { data };
            dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            })
        };
        let [cells, refs, tris, tri_shade_buf, materials_buf] = arrays.map(|(n, d)| storage(n, d));
        let scene_bytes = arrays.iter().map(|(n, d)| (*n, d.len() as u64)).collect();

        let bounds = g.bounds;
        let scene_consts = SceneUniform {
            bounds_min: bounds.min.to_array(),
            ray_epsilon: scene.ray_epsilon,
            bounds_max: bounds.max.to_array(),
            n_lights: 0,
            cell_size: g.cell_size.to_array(),
            n_tris: scene.accel.tris.len() as u32,
            inv_cell_size: g.inv_cell_size.to_array(),
            _pad0: 0,
            dims: g.dims.to_array(),
            _pad1: 0,
            background: scene.background.to_array(),
            _pad2: 0,
            ambient: scene.ambient.to_array(),
            _pad3: 0,
        };
        let uniform = |label: &str, size: u64| {
            dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let scene_uniform = uniform("scene uniform", std::mem::size_of::<SceneUniform>() as u64);
        let camera_uniform = uniform(
            "camera uniform",
            std::mem::size_of::<crate::scene::CameraFrame>() as u64,
        );
        let pass_uniform = uniform("pass uniform", UNIFORM_STRIDE * MAX_PASSES as u64);
        let counters = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("counters"),
            size: (COUNTER_SLOTS * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let indirect = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("indirect args"),
            size: 24,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT,
            mapped_at_creation: false,
        });

        let mut entries = vec![uniform_entry(0), uniform_entry(1), uniform_entry(2)];
        entries.extend((3..=8).map(|b| storage_entry(b, true)));
        entries.extend((9..=15).map(|b| storage_entry(b, false)));
        let layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gridtrace"),
            entries: &entries,
        });
        let pipeline_layout = dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("gridtrace"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let indirect_layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("indirect args"),
            entries: &[storage_entry(0, false)],
        });
        let indirect_pipeline_layout = dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("indirect"),
            bind_group_layouts: &[Some(&layout), Some(&indirect_layout)],
            immediate_size: 0,
        });
        let indirect_group = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("indirect args"),
            layout: &indirect_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: indirect.as_entire_binding(),
            }],
        });
        let scope = dev.push_error_scope(wgpu::ErrorFilter::Validation);
        let make = |name: &str, src: &str, constants: &[(&str, f64)], layout: &wgpu::PipelineLayout| {
            let module = dev.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(format!("{}\n{}", shaders::COMMON, src).into()),
            });
            dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: Some(layout),
                module: &module,
                entry_point: Some("main"),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants,
                    ..Default::default()
                },
                cache: None,
            })
        };
        let pipelines = Pipelines {
            raygen: make("raygen", shaders::RAYGEN, &[], &pipeline_layout),
            traverse: make("traverse", shaders::TRAVERSE, &[], &pipeline_layout),
            traverse_heat: make(
                "traverse (heat)",
                shaders::TRAVERSE,
                &[("COUNT_WORK", 1.0)],
                &pipeline_layout,
            ),
            occlusion: make("occlusion", shaders::OCCLUSION, &[], &pipeline_layout),
            shade: make("shade", shaders::SHADE, &[], &pipeline_layout),
            resolve: make("resolve", shaders::RESOLVE, &[], &pipeline_layout),
            indirect: make("indirect", shaders::INDIRECT, &[], &indirect_pipeline_layout),
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Gpu(format!("creating the kernels failed: {e}")));
        }
        let query = ctx.timestamps.then(|| {
            let n = 2 * 64;
            (
                dev.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("stage times"),
                    ty: wgpu::QueryType::Timestamp,
                    count: n,
                }),
                dev.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamps"),
                    size: n as u64 * 8,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
            )
        });
        ctx.queue
            .write_buffer(&scene_uniform, 0, bytemuck::bytes_of(&scene_consts));
        ctx.check_errors()?;
        Ok(GpuRenderer {
            ctx,
            layout,
            pipelines,
            scene_uniform,
            camera_uniform,
            pass_uniform,
            cells,
            refs,
            tris,
            tri_shade: tri_shade_buf,
            materials: materials_buf,
            counters,
            indirect,
            indirect_group,
            query,
            work: None,
            scene_consts,
            scene_bytes,
        })
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// Bytes of each GPU array: the scene's and the current work buffers'.
    pub fn memory(&self) -> Vec<(&'static str, u64)> {
        let mut v = self.scene_bytes.clone();
        if let Some(w) = &self.work {
            v.push(("ray queues", w.queue_a.size() + w.queue_b.size()));
            v.push(("hits", w.hits.size()));
            v.push(("shadow queue", w.shadow.size()));
            v.push(("resolve", w.resolve.size()));
            v.push(("accum", w.accum.size()));
        }
        v
    }

    /// Largest tile (pixels) whose buffers fit the device's binding limit with `lights` lights.
    fn tile_capacity(&self, lights: u32) -> u32 {
        let limits = self.ctx.limits();
        let max_binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let per_pixel_shadow = std::mem::size_of::<RayRec>() as u64 * lights.max(1) as u64;
        let by_shadow = max_binding / per_pixel_shadow;
        let by_rays = max_binding / std::mem::size_of::<RayRec>() as u64;
        (MAX_TILE_PIXELS as u64).min(by_shadow).min(by_rays).max(1) as u32
    }

    /// Makes sure the work buffers hold `tile_pixels` and `lights`; recreates them if not.
    fn ensure_work(&mut self, tile_pixels: u32, lights: u32) {
        if let Some(w) = &self.work
            && w.tile_pixels >= tile_pixels
            && w.max_lights >= lights
        {
            return;
        }
        let dev = &self.ctx.device;
        let buf = |label: &str, size: u64, extra: wgpu::BufferUsages| {
            dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC
                    | extra,
                mapped_at_creation: false,
            })
        };
        let n = tile_pixels as u64;
        let rec = std::mem::size_of::<RayRec>() as u64;
        let max_lights = lights.max(1);
        let queue_a = buf("ray queue A", n * rec, wgpu::BufferUsages::empty());
        let queue_b = buf("ray queue B", n * rec, wgpu::BufferUsages::empty());
        let hits = buf("hits", n * 16, wgpu::BufferUsages::empty());
        let shadow = buf("shadow queue", n * rec * max_lights as u64, wgpu::BufferUsages::empty());
        let resolve = buf("resolve", n * 8, wgpu::BufferUsages::empty());
        let accum = buf("accum", n * 16, wgpu::BufferUsages::empty());
        let lights_buf = buf(
            "lights",
            std::mem::size_of::<PointLight>() as u64 * max_lights as u64,
            wgpu::BufferUsages::empty(),
        );
        let bind_groups = (0..MAX_PASSES)
            .map(|d| {
                let (qin, qout) = if d % 2 == 0 {
                    (&queue_a, &queue_b)
                } else {
                    (&queue_b, &queue_a)
                };
                let pass = wgpu::BufferBinding {
                    buffer: &self.pass_uniform,
                    offset: d as u64 * UNIFORM_STRIDE,
                    size: wgpu::BufferSize::new(std::mem::size_of::<PassUniform>() as u64),
                };
                let buffers: [wgpu::BindingResource; 16] = [
                    wgpu::Buffer::as_entire_binding(&self.scene_uniform),
                    wgpu::Buffer::as_entire_binding(&self.camera_uniform),
                    wgpu::BindingResource::Buffer(pass),
                    wgpu::Buffer::as_entire_binding(&self.cells),
                    wgpu::Buffer::as_entire_binding(&self.refs),
                    wgpu::Buffer::as_entire_binding(&self.tris),
                    wgpu::Buffer::as_entire_binding(&self.tri_shade),
                    wgpu::Buffer::as_entire_binding(&self.materials),
                    wgpu::Buffer::as_entire_binding(&lights_buf),
                    wgpu::Buffer::as_entire_binding(qin),
                    wgpu::Buffer::as_entire_binding(qout),
                    wgpu::Buffer::as_entire_binding(&hits),
                    wgpu::Buffer::as_entire_binding(&shadow),
                    wgpu::Buffer::as_entire_binding(&resolve),
                    wgpu::Buffer::as_entire_binding(&accum),
                    wgpu::Buffer::as_entire_binding(&self.counters),
                ];
                let entries: Vec<wgpu::BindGroupEntry> = buffers
                    .into_iter()
                    .enumerate()
                    .map(|(i, resource)| wgpu::BindGroupEntry {
                        binding: i as u32,
                        resource,
                    })
                    .collect();
                dev.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("gridtrace"),
                    layout: &self.layout,
                    entries: &entries,
                })
            })
            .collect();
        self.work = Some(WorkBuffers {
            tile_pixels,
            max_lights,
            queue_a,
            queue_b,
            hits,
            shadow,
            resolve,
            accum,
            lights: lights_buf,
            bind_groups,
        });
    }

    fn write_pass_uniforms(&self, tile_offset: u32, tile_pixels: u32, mode: Mode, accel: AccelKind) {
        for d in 0..MAX_PASSES as u32 {
            let p = PassUniform {
                depth: d,
                in_slot: d % 2,
                out_slot: 1 - d % 2,
                tile_offset,
                tile_pixels,
                mode: match mode {
                    Mode::Cast => 0,
                    Mode::Shadow => 1,
                    Mode::Trace => 2,
                    Mode::Heat => 3,
                },
                accel: (accel == AccelKind::ProximityCloud) as u32,
                max_depth: mode.reflection_depth(),
            };
            self.ctx
                .queue
                .write_buffer(&self.pass_uniform, d as u64 * UNIFORM_STRIDE, bytemuck::bytes_of(&p));
        }
    }

    /// Renders one frame with the given camera and lights (the scene's own need not be used).
    pub fn render(
        &mut self,
        camera: &Camera,
        lights: &[PointLight],
        opts: &RenderOptions,
    ) -> Result<(Image, GpuRenderStats)> {
        opts.validate()?;
        check_accel(opts.accel)?;
        camera.validate().map_err(Error::Scene)?;
        let n_lights = lights.len() as u32;
        let pixels = opts.width * opts.height;
        let tile = self.tile_capacity(n_lights).min(pixels);
        self.ensure_work(tile, n_lights);
        let t0 = Instant::now();
        let frame = camera.frame(opts.width, opts.height);
        let q = &self.ctx.queue;
        q.write_buffer(&self.camera_uniform, 0, bytemuck::bytes_of(&frame));
        let consts = SceneUniform {
            n_lights,
            ..self.scene_consts
        };
        q.write_buffer(&self.scene_uniform, 0, bytemuck::bytes_of(&consts));
        {
            let w = self.work.as_ref().unwrap();
            if !lights.is_empty() {
                q.write_buffer(&w.lights, 0, bytemuck::cast_slice(lights));
            }
        }
        let mut img = Image::new(opts.width, opts.height);
        let mut stats = GpuRenderStats::default();
        let mut offset = 0u32;
        while offset < pixels {
            let tp = tile.min(pixels - offset);
            self.write_pass_uniforms(offset, tp, opts.mode, opts.accel);
            let (accum, counters, times) = self.run_tile(tp, opts.mode)?;
            for (i, px) in accum.chunks_exact(4).enumerate() {
                img.pixels[offset as usize + i] = Vec3::new(px[0], px[1], px[2]);
            }
            stats.render.rays.eye += tp as u64;
            stats.render.rays.shadow += counters[SLOT_SHADOW_TOTAL] as u64;
            stats.render.rays.reflection += counters[SLOT_REFLECT_TOTAL] as u64;
            for (k, v) in times {
                *stats.timings.stages_ms.entry(k).or_default() += v;
            }
            stats.tiles += 1;
            offset += tp;
        }
        let wall_ms = t0.elapsed().as_secs_f64() * 1e3;
        stats.timings.from_timestamps = self.query.is_some();
        stats.timings.total_ms = if self.query.is_some() {
            stats.timings.stages_ms.values().sum()
        } else {
            wall_ms
        };
        stats.render.render_ms = stats.timings.total_ms;
        if opts.mode == Mode::Heat {
            let cost: f64 = img.pixels.iter().map(|p| p.x as f64).sum();
            stats.render.counters.cells = cost as u64;
        }
        Ok((img, stats))
    }

    /// Records and runs one tile's kernels; returns accum (RGBA f32), counters and stage times.
    fn run_tile(&mut self, tp: u32, mode: Mode) -> Result<(Vec<f32>, Vec<u32>, Vec<(&'static str, f64)>)> {
        let w = self.work.as_ref().unwrap();
        let p = &self.pipelines;
        let dev = &self.ctx.device;
        let mut enc = dev.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        enc.clear_buffer(&self.counters, 0, None);
        let mut stages: Vec<&'static str> = Vec::new();
        let query = self.query.as_ref();
        let mut pass = |enc: &mut wgpu::CommandEncoder,
                        name: &'static str,
                        pipeline: &wgpu::ComputePipeline,
                        bg: &wgpu::BindGroup,
                        dispatch: Option<(u32, u32)>,
                        indirect_offset: u64| {
            let qi = stages.len() as u32 * 2;
            let timestamp_writes = query
                .filter(|_| qi + 1 < 128)
                .map(|(qs, _)| wgpu::ComputePassTimestampWrites {
                    query_set: qs,
                    beginning_of_pass_write_index: Some(qi),
                    end_of_pass_write_index: Some(qi + 1),
                });
            if timestamp_writes.is_some() {
                stages.push(name);
            }
            let mut cp = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(name),
                timestamp_writes,
            });
            cp.set_pipeline(pipeline);
            cp.set_bind_group(0, bg, &[]);
            if name == "indirect" {
                cp.set_bind_group(1, &self.indirect_group, &[]);
            }
            match dispatch {
                Some((x, y)) => cp.dispatch_workgroups(x, y, 1),
                None => cp.dispatch_workgroups_indirect(&self.indirect, indirect_offset),
            }
        };
        let (gx, gy) = dispatch_size(tp);
        pass(&mut enc, "raygen", &p.raygen, &w.bind_groups[0], Some((gx, gy)), 0);
        for d in 0..=mode.reflection_depth() as usize {
            let bg = &w.bind_groups[d];
            pass(&mut enc, "indirect", &p.indirect, bg, Some((1, 1)), 0);
            if mode == Mode::Heat {
                pass(&mut enc, "traverse", &p.traverse_heat, bg, None, 0);
                break;
            }
            pass(&mut enc, "traverse", &p.traverse, bg, None, 0);
            pass(&mut enc, "shade", &p.shade, bg, None, 0);
            if mode.shadows() {
                pass(&mut enc, "indirect", &p.indirect, bg, Some((1, 1)), 0);
                pass(&mut enc, "occlusion", &p.occlusion, bg, None, 12);
                pass(&mut enc, "resolve", &p.resolve, bg, None, 0);
            }
            // This bounce's input queue becomes the next one's output: empty it, and the
            // shadow queue.
            enc.clear_buffer(&self.counters, (d % 2) as u64 * 4, Some(4));
            enc.clear_buffer(&self.counters, SLOT_SHADOW as u64 * 4, Some(4));
        }
        if let Some((qs, buf)) = query
            && !stages.is_empty()
        {
            enc.resolve_query_set(qs, 0..stages.len() as u32 * 2, buf, 0);
        }
        self.ctx.queue.submit([enc.finish()]);
        let accum: Vec<f32> = bytemuck::cast_slice(&self.ctx.read_buffer(&w.accum, tp as u64 * 16)?).to_vec();
        let counters: Vec<u32> =
            bytemuck::cast_slice(&self.ctx.read_buffer(&self.counters, (COUNTER_SLOTS * 4) as u64)?).to_vec();
        let mut times = Vec::new();
        if let Some((_, buf)) = query
            && !stages.is_empty()
        {
            let raw = self.ctx.read_buffer(buf, stages.len() as u64 * 16)?;
            let ts: &[u64] = bytemuck::cast_slice(&raw);
            let period_ns = self.ctx.queue.get_timestamp_period() as f64;
            for (i, name) in stages.iter().enumerate() {
                let dt = ts[2 * i + 1].saturating_sub(ts[2 * i]) as f64 * period_ns * 1e-6;
                times.push((*name, dt));
            }
        }
        Ok((accum, counters, times))
    }

    /// Closest hits for a batch of rays (processed in bounded chunks).
    pub fn intersect(&mut self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind) -> Result<Vec<Hit>> {
        self.batch(rays, t_min, t_max, kind, false).map(|(h, _)| h)
    }

    /// Any-hit occlusion for a batch of rays.
    pub fn occluded(&mut self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind) -> Result<Vec<bool>> {
        self.batch(rays, t_min, t_max, kind, true).map(|(_, o)| o)
    }

    fn batch(
        &mut self,
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        kind: AccelKind,
        occlusion: bool,
    ) -> Result<(Vec<Hit>, Vec<bool>)> {
        check_accel(kind)?;
        let chunk = self.tile_capacity(1) as usize;
        self.ensure_work(
            chunk.min(rays.len().max(1)) as u32,
            self.work.as_ref().map_or(1, |w| w.max_lights),
        );
        let cap = self.work.as_ref().unwrap().tile_pixels as usize;
        let mut hits = Vec::new();
        let mut occ = Vec::new();
        for part in rays.chunks(cap.max(1)) {
            let recs: Vec<RayRec> = part
                .iter()
                .enumerate()
                .map(|(i, r)| RayRec {
                    origin: r.origin.to_array(),
                    pixel: i as u32,
                    dir: r.dir.to_array(),
                    t_max,
                    weight: [1.0; 3],
                    t_min,
                })
                .collect();
            let n = recs.len() as u32;
            self.write_pass_uniforms(0, n, Mode::Cast, kind);
            let w = self.work.as_ref().unwrap();
            let q = &self.ctx.queue;
            let mut counts = [0u32; COUNTER_SLOTS];
            if occlusion {
                q.write_buffer(&w.shadow, 0, bytemuck::cast_slice(&recs));
                counts[SLOT_SHADOW] = n;
            } else {
                q.write_buffer(&w.queue_a, 0, bytemuck::cast_slice(&recs));
                counts[SLOT_QUEUE_A] = n;
            }
            q.write_buffer(&self.counters, 0, bytemuck::cast_slice(&counts));
            let mut enc = self.ctx.device.create_command_encoder(&Default::default());
            for (pipeline, offset) in [
                (&self.pipelines.indirect, None),
                (
                    if occlusion {
                        &self.pipelines.occlusion
                    } else {
                        &self.pipelines.traverse
                    },
                    Some(if occlusion { 12 } else { 0 }),
                ),
            ] {
                let mut cp = enc.begin_compute_pass(&Default::default());
                cp.set_pipeline(pipeline);
                cp.set_bind_group(0, &w.bind_groups[0], &[]);
                match offset {
                    None => {
                        cp.set_bind_group(1, &self.indirect_group, &[]);
                        cp.dispatch_workgroups(1, 1, 1)
                    }
                    Some(o) => cp.dispatch_workgroups_indirect(&self.indirect, o),
                }
            }
            q.submit([enc.finish()]);
            if occlusion {
                let raw = self
                    .ctx
                    .read_buffer(&w.shadow, n as u64 * std::mem::size_of::<RayRec>() as u64)?;
                let out: &[RayRec] = bytemuck::cast_slice(&raw);
                occ.extend(out.iter().map(|r| r.weight[0] == 0.0));
            } else {
                let raw = self.ctx.read_buffer(&w.hits, n as u64 * 16)?;
                let out: &[GpuHit] = bytemuck::cast_slice(&raw);
                hits.extend(out.iter().map(|h| {
                    if h.tri == u32::MAX {
                        Hit::MISS
                    } else {
                        Hit {
                            t: h.t,
                            tri: h.tri,
                            u: h.u,
                            v: h.v,
                        }
                    }
                }));
            }
        }
        Ok((hits, occ))
    }
}

/// The GPU kernels traverse the grid (with or without proximity clouds) only.
pub fn check_accel(kind: AccelKind) -> Result<()> {
    if kind == AccelKind::Bvh {
        return Err(Error::InvalidInput(
            "the bvh acceleration runs on the CPU only: use backend cpu (or auto), or accel grid or pc".into(),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene larger than the device allows is an error naming the array and the limit (checked
    /// with artificially small limits: no software adapter's limits can be exceeded in a test).
    #[test]
    fn scene_too_large_names_the_limit() {
        let limits = wgpu::Limits {
            max_storage_buffer_binding_size: 1 << 20,
            max_buffer_size: 1 << 30,
            ..wgpu::Limits::default()
        };
        assert!(check_scene_fits(&[("cells", 1 << 20), ("refs", 12)], &limits, "tiny").is_ok());
        let e = check_scene_fits(&[("cells", 12), ("refs", (1 << 20) + 4)], &limits, "tiny")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("'refs'") && e.contains("max_storage_buffer_binding_size") && e.contains("tiny"),
            "{e}"
        );
        let limits = wgpu::Limits {
            max_buffer_size: 1000,
            ..limits
        };
        let e = check_scene_fits(&[("triangles", 1001)], &limits, "tiny")
            .unwrap_err()
            .to_string();
        assert!(e.contains("'triangles'") && e.contains("max_buffer_size"), "{e}");
    }
}
