//! `GpuRenderer`: a scene resident on a device, with the per-frame uniforms and the work
//! buffers (`work.rs`: ray queues, hits, accumulation) that the tile loop (`wavefront.rs`) and
//! the ray queries (`queries.rs`) share.

use crate::util::Instant;
use std::mem::size_of;
use std::sync::Arc;

use super::bindings::{self, INDIRECT_BINDINGS, IndirectSlot};
use super::constants::{COUNTER_SLOTS, accel_code, mode_code};
use super::context::{GpuContext, max_binding_bytes};
use super::kernels::{Kernels, PassRecorder};
use super::layout::{GpuTri, IndirectArgs, PassUniform, RayRec};
use super::scene::{SceneBuffers, tri_shade};
use super::timing::{GpuQueryStats, StageTimer, Timestamps};
use super::variants::GpuVariants;
use super::walks::grid::build::GpuBuildStats;
use super::walks::two_level::{BottomLevels, TOP_LEVEL_ARRAY, TopLevel};
use super::walks::{self, DeviceBuilder, DeviceStructure};
use super::work::{Bound, MAX_PASSES, PASS_UNIFORM_STRIDE_BYTES, WorkBuffers, WorkUse};
use crate::accel::AccelKind;
use crate::render::{Ablation, Mode};
use crate::scene::{CameraFrame, PreparedScene};
use crate::{Error, Result};

/// Largest tile in pixels: bounds queue memory and keeps each submission short for watchdogs.
pub const MAX_TILE_PIXELS: u32 = 1 << 20;
/// Rays of one scan submission at most (`scan.rs`): 64 VLP-16s (1.84M rays) go in one, with a
/// queue of 88 MB and hits of 29 MB on the device (where the bindings allow:
/// `chunk_capacity`); a hardware GPU traces them in milliseconds, far inside any watchdog.
pub const MAX_SCAN_RAYS: u32 = 1 << 22;
/// Bytes of one tile's pass uniforms (every bounce's), as the frame's tile list holds them.
pub(super) const TILE_UNIFORM_BYTES: u64 = PASS_UNIFORM_STRIDE_BYTES * MAX_PASSES as u64;
pub(super) const COUNTERS_BYTES: u64 = (COUNTER_SLOTS * size_of::<u32>()) as u64;
/// A scene resident on the GPU. Camera and lights change per frame; nothing else is uploaded
/// again. Renderers on one context share its device and compiled kernels.
pub struct GpuRenderer {
    pub(super) ctx: Arc<GpuContext>,
    pub(super) kernels: Arc<Kernels>,
    pub(super) scene: SceneBuffers,
    pub(super) camera_uniform: wgpu::Buffer,
    /// `MAX_PASSES` pass uniforms, `PASS_UNIFORM_STRIDE_BYTES` apart.
    pass_uniform: wgpu::Buffer,
    pub(super) counters: wgpu::Buffer,
    indirect_args: wgpu::Buffer,
    indirect_group: wgpu::BindGroup,
    timestamps: Option<Timestamps>,
    pub(super) work: Option<WorkBuffers>,
    /// Every tile's pass uniforms for one frame (`TILE_UNIFORM_BYTES` each), copied into
    /// `pass_uniform` in the command stream before the tile's passes: so all tiles of a frame
    /// go in one submission. Grown as frames need.
    pub(super) tile_uniforms: Option<wgpu::Buffer>,
    /// Spare frame readbacks (image, counters, timestamps; each mapped once per frame): a
    /// frame takes one and gives it back once read, so frames in flight have one each
    /// (`wavefront.rs`). At most `SPARE_READBACKS` are kept.
    readbacks: Vec<wgpu::Buffer>,
    /// The ray batches' kept buffers: uploads, readbacks, wire rays and answers (`queries.rs`).
    pub(super) batches: super::batch_buffers::Batches,
    /// What the last ray batch took (`last_query_stats`).
    pub(super) last_query: GpuQueryStats,
    /// Largest tile in pixels (`MAX_TILE_PIXELS`; tests lower it to make many tiles).
    max_tile_pixels: u32,
    /// Rays of a scan's submission at most (`scan.rs`); tests lower it.
    pub(super) max_scan_rays: u32,
    /// The structure's builder on the device, for a structure the GPU rebuilds when the mesh
    /// moves (`update_vertices`), once it has.
    device_builder: Option<DeviceBuilder>,
    /// The traversal its walks run: the uploaded scene's (`Accel::kind`), or what
    /// `set_traversal` switched it to.
    pub(super) kind: AccelKind,
}

/// What `GpuRenderer::update_vertices` did, and its times.
#[derive(Debug, Clone, Default)]
pub struct GpuUpdateStats {
    /// Writing the moved triangles and normals to the device (wall clock, host side).
    pub upload_ms: f64,
    /// The grid's build on the device, when it was built there.
    pub build: Option<GpuBuildStats>,
    /// Uploading a structure the CPU updated (BVH, irregular grid; wall clock).
    pub structure_upload_ms: f64,
}

impl GpuRenderer {
    /// Uploads the scene (grid, references, triangles, shading data, materials) once, in the
    /// kernels and layouts `variants` choose (same images and hits, other speed:
    /// `GpuVariants::default()` is today's); compiles the kernels unless an earlier renderer on
    /// `ctx` did.
    pub fn new(ctx: Arc<GpuContext>, prepared: &PreparedScene, variants: &GpuVariants) -> Result<GpuRenderer> {
        let scene = SceneBuffers::upload(&ctx, prepared, variants)?;
        let mut renderer = Self::with_scene(ctx, scene, prepared.accel.kind(), variants)?;
        // A scene whose grid was left to the GPU: build it now.
        if prepared.accel.structure_stale {
            renderer.update_vertices(prepared)?;
        }
        Ok(renderer)
    }

    /// A renderer of a scene of two levels (`walks::two_level`), for ray batches only: each
    /// mesh's structure as `bottoms` lays it out, uploaded once, and the top level `top`,
    /// which `set_top_level` replaces when instances move.
    /// `device`: the TLAS of a walk by ray query (`hwrt`'s driver instances), built by the
    /// caller.
    pub(crate) fn two_level(
        ctx: Arc<GpuContext>,
        bottoms: &BottomLevels,
        top: &TopLevel,
        variants: &GpuVariants,
        device: Option<DeviceStructure>,
    ) -> Result<GpuRenderer> {
        let scene = SceneBuffers::upload_two_level(&ctx, bottoms, top, variants, device)?;
        Self::with_scene(ctx, scene, bottoms.kind, variants)
    }

    /// Rebuilds the top-level acceleration structure a walk by ray query binds (`hwrt`'s
    /// driver instances moved) with `rebuild`, which may replace it and returns the bytes it
    /// uploaded (counted in `scene_upload_bytes`); group 1 is bound again.
    pub(crate) fn rebuild_tlas(
        &mut self,
        rebuild: impl FnOnce(&GpuContext, &mut Option<wgpu::Tlas>) -> Result<u64>,
    ) -> Result<u64> {
        let bytes = rebuild(&self.ctx, &mut self.scene.tlas)?;
        self.scene.rebind(&self.ctx.device);
        self.scene.uploaded_bytes += bytes;
        Ok(bytes)
    }

    /// Uploads a new top level over the one a renderer of two levels has (instances moved,
    /// masks changed); the meshes' arrays stay. Returns the bytes written.
    pub(crate) fn set_top_level(&mut self, top: &TopLevel) -> Result<u64> {
        self.scene
            .write_array(&self.ctx, TOP_LEVEL_ARRAY.0, bytemuck::cast_slice(&top.recs))
    }

    /// Bytes written to the scene's arrays since the renderer was made: the first upload, and
    /// every later write (a scene of two levels: its top levels).
    pub fn scene_upload_bytes(&self) -> u64 {
        self.scene.uploaded_bytes
    }

    fn with_scene(
        ctx: Arc<GpuContext>,
        scene: SceneBuffers,
        kind: AccelKind,
        variants: &GpuVariants,
    ) -> Result<GpuRenderer> {
        let dev = &ctx.device;
        let uniform = |label: &str, size: u64| {
            dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let camera_uniform = uniform("camera uniform", size_of::<CameraFrame>() as u64);
        let pass_uniform = uniform("pass uniform", PASS_UNIFORM_STRIDE_BYTES * MAX_PASSES as u64);
        let counters = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("counters"),
            size: COUNTERS_BYTES,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let indirect_args = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("indirect args"),
            size: size_of::<IndirectArgs>() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT,
            mapped_at_creation: false,
        });
        let kernels = Kernels::of(&ctx, variants)?;
        let indirect_group = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("indirect args"),
            layout: &kernels.indirect_layout,
            entries: &bindings::group_entries(&INDIRECT_BINDINGS, |slot| match slot {
                IndirectSlot::Args => indirect_args.as_entire_binding(),
            }),
        });
        let timestamps = Timestamps::new(&ctx);
        ctx.check_errors()?;
        Ok(GpuRenderer {
            kind,
            ctx,
            kernels,
            scene,
            camera_uniform,
            pass_uniform,
            counters,
            indirect_args,
            indirect_group,
            timestamps,
            work: None,
            tile_uniforms: None,
            readbacks: Vec::new(),
            batches: Default::default(),
            last_query: GpuQueryStats::default(),
            max_tile_pixels: MAX_TILE_PIXELS,
            max_scan_rays: MAX_SCAN_RAYS,
            device_builder: None,
        })
    }

    /// The scene's vertices moved (`PreparedScene::update_vertices`): uploads the new triangles
    /// and normals, and brings the structure up to date: a structure with a device build (the
    /// grid's, `walks::rebuild_on_device`; with the scene's `RebuildOn::Device` the CPU never
    /// builds it) is built here on the device, any other structure, which the CPU updated, is
    /// uploaded again. The triangles must be the ones
    /// this renderer was made with, moved.
    pub fn update_vertices(&mut self, scene: &PreparedScene) -> Result<GpuUpdateStats> {
        let tris = &scene.accel.tris;
        if tris.len() as u32 != self.scene.consts.n_tris {
            return Err(Error::InvalidInput(format!(
                "the scene has {} triangles; this GPU renderer was made for {}",
                tris.len(),
                self.scene.consts.n_tris
            )));
        }
        let mut stats = GpuUpdateStats::default();
        if !self.scene.spec().device_build {
            let t0 = Instant::now();
            self.scene = SceneBuffers::upload(&self.ctx, scene, &self.kernels.variants)?;
            self.work = None;
            self.ctx.wait()?;
            stats.structure_upload_ms = t0.elapsed().as_secs_f64() * 1e3;
            return Ok(stats);
        }
        let t0 = Instant::now();
        let q = &self.ctx.queue;
        q.write_buffer(&self.scene.tris, 0, bytemuck::cast_slice(&GpuTri::all(tris)));
        q.write_buffer(&self.scene.tri_shade, 0, bytemuck::cast_slice(&tri_shade(scene)));
        stats.upload_ms = t0.elapsed().as_secs_f64() * 1e3;
        let built = walks::rebuild_on_device(&mut self.device_builder, &self.ctx, &self.scene.tris, scene)?;
        // The structure's bind group names the old buffers when the build made new ones.
        let dev = &self.ctx.device;
        for &(name, buffer) in &built.arrays {
            self.scene.replace_array(dev, name, buffer);
        }
        let c = &mut self.scene.consts;
        built.lattice.write_to(c);
        c.ray_epsilon = scene.ray_epsilon;
        // Queries read the uniform as it is (frames rewrite it with their light count).
        self.ctx
            .queue
            .write_buffer(&self.scene.uniform, 0, bytemuck::bytes_of(&self.scene.consts));
        for (name, bytes) in built.memory {
            if let Some(e) = self.scene.bytes.iter_mut().find(|e| e.0 == name) {
                e.1 = bytes;
            }
        }
        stats.build = Some(built.stats);
        Ok(stats)
    }

    /// The device it traces on (shared: a `DeviceImage` for `render_to_device` is made on it).
    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// The GPU variants this renderer's kernels were compiled with.
    pub fn variants(&self) -> GpuVariants {
        self.kernels.variants
    }

    /// The traversal its walks run (`Accel::kind` of the scene it was given).
    pub fn kind(&self) -> AccelKind {
        self.kind
    }

    /// Serves `kind` from now on: another traversal of the uploaded structure (the grid's
    /// `grid` and `pc`, which differ only in a uniform), so nothing is uploaded. An error for a
    /// kind of another structure, which needs a scene prepared and uploaded for it.
    pub fn set_traversal(&mut self, kind: AccelKind) -> Result<()> {
        kind.check_walks(self.scene.spec().structure, "GPU scene uploaded")?;
        self.kind = kind;
        Ok(())
    }

    /// Bytes of each GPU array: the scene's and the current work buffers'.
    pub fn memory(&self) -> Vec<(&'static str, u64)> {
        let mut v = self.scene.bytes.clone();
        if let Some(w) = &self.work {
            v.push(("ray queues", w.queue_a.size() + w.queue_b.size()));
            v.push(("hits", w.hits.size()));
            v.push(("shadow queue", w.shadow.size()));
            v.push(("resolve", w.resolve.size()));
            v.push(("accum", w.accum.size()));
            v.push(("packed pixels", w.packed.size()));
        }
        v
    }

    /// Whether the stage times come from timestamp queries.
    pub(super) fn timed(&self) -> bool {
        self.timestamps.is_some()
    }

    /// A recorder for one submission over a tile (or batch) of `tile_pixels`; `timed` takes
    /// timestamps when the device has them.
    pub(super) fn recorder(&self, tile_pixels: u32, timed: bool, ablation: Ablation) -> PassRecorder<'_> {
        PassRecorder {
            kernels: &self.kernels,
            indirect_args: &self.indirect_args,
            indirect_group: &self.indirect_group,
            packed_group: self.work.as_ref().map(|w| &w.packed_group),
            batch_group: None,
            winding_group: None,
            walk: &self.scene.walk,
            structure_group: &self.scene.structure_group,
            shadow_closest_hit: ablation.shadow_closest_hit,
            tile_pixels,
            timer: StageTimer::new(self.timestamps.as_ref().filter(|_| timed)),
        }
    }

    /// Largest tile (pixels) whose buffers fit the device's binding limit with `lights` lights.
    pub(super) fn tile_capacity(&self, lights: u32) -> u32 {
        let max_binding = max_binding_bytes(&self.ctx.limits());
        let per_pixel_shadow = size_of::<RayRec>() as u64 * lights.max(1) as u64;
        let by_shadow = max_binding / per_pixel_shadow;
        let by_rays = max_binding / size_of::<RayRec>() as u64;
        (self.max_tile_pixels as u64).min(by_shadow).min(by_rays).max(1) as u32
    }

    /// Lowers the largest tile to `pixels` (at least 1): tests make a small frame of many
    /// tiles with it, as a 4096x4096 frame is on any device.
    #[doc(hidden)]
    pub fn set_max_tile_pixels(&mut self, pixels: u32) {
        self.max_tile_pixels = pixels.clamp(1, MAX_TILE_PIXELS);
    }

    /// Makes sure the work buffers hold `tile_pixels` and `lights` in the buffers `uses` names;
    /// recreates them if not (keeping full size the buffers earlier work used).
    pub(super) fn ensure_work(&mut self, tile_pixels: u32, lights: u32, uses: WorkUse) {
        if self.work.as_ref().is_some_and(|w| w.hold(tile_pixels, lights, uses)) {
            return;
        }
        let uses = self.work.as_ref().map_or(uses, |w| w.uses.and(uses));
        let bound = Bound {
            device: &self.ctx.device,
            kernels: &self.kernels,
            scene: &self.scene,
            camera_uniform: &self.camera_uniform,
            pass_uniform: &self.pass_uniform,
            counters: &self.counters,
        };
        self.work = Some(WorkBuffers::new(&bound, tile_pixels, lights, uses));
    }

    /// The pass uniform buffer the kernels bind (a frame's tiles copy theirs into it).
    pub(super) fn pass_uniform(&self) -> &wgpu::Buffer {
        &self.pass_uniform
    }

    /// `write_pass_uniforms` into `dst` from byte `base` on (`TILE_UNIFORM_BYTES` of them).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn write_pass_uniforms_to(
        &self,
        dst: &wgpu::Buffer,
        base: u64,
        tile_offset: u32,
        tile_pixels: u32,
        mode: Mode,
        accel: AccelKind,
        ablation: Ablation,
    ) -> u64 {
        let mut bytes = 0;
        for d in 0..MAX_PASSES as u32 {
            let p = PassUniform {
                depth: d,
                in_slot: d % 2,
                out_slot: 1 - d % 2,
                tile_offset,
                tile_pixels,
                mode: mode_code(mode),
                accel: accel_code(accel),
                max_depth: mode.reflection_depth(),
                compact: !ablation.no_compaction as u32,
                _pad0: 0,
                _pad1: 0,
                _pad2: 0,
            };
            self.ctx
                .queue
                .write_buffer(dst, base + d as u64 * PASS_UNIFORM_STRIDE_BYTES, bytemuck::bytes_of(&p));
            bytes += size_of::<PassUniform>() as u64;
        }
        bytes
    }
}

/// Frame readbacks kept for the next frames: two frames in flight and one being prepared.
const SPARE_READBACKS: usize = 3;

impl GpuRenderer {
    /// A frame readback of at least `size` bytes: a spare if one is large enough, else a new
    /// one of `size` (a smaller spare is dropped for it).
    pub(super) fn take_readback(&mut self, size: u64) -> wgpu::Buffer {
        if let Some(i) = self.readbacks.iter().position(|b| b.size() >= size) {
            return self.readbacks.swap_remove(i);
        }
        if self.readbacks.len() >= SPARE_READBACKS {
            self.readbacks.pop();
        }
        self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A frame readback read out (unmapped), kept for a later frame.
    pub(super) fn give_back_readback(&mut self, buffer: wgpu::Buffer) {
        if self.readbacks.len() < SPARE_READBACKS {
            self.readbacks.push(buffer);
        }
    }
}

/// Makes sure `slot` holds a buffer of at least `size` bytes: kept between frames, replaced by
/// one of exactly `size` when a frame needs more.
pub(super) fn grow(
    device: &wgpu::Device,
    slot: &mut Option<wgpu::Buffer>,
    size: u64,
    label: &str,
    usage: wgpu::BufferUsages,
) {
    if slot.as_ref().is_some_and(|b| b.size() >= size) {
        return;
    }
    *slot = Some(device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage,
        mapped_at_creation: false,
    }));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin;

    /// A second renderer on the same context reuses the first one's kernels (skipped without an
    /// adapter: the integration tests in tests/gpu.rs are the ones that insist on one).
    #[test]
    fn renderers_share_kernels() {
        let Ok(ctx) = GpuContext::new() else {
            eprintln!("no GPU adapter: skipping");
            return;
        };
        let ctx = Arc::new(ctx);
        let scene = builtin::knot_box().prepare(crate::Resolution::default()).unwrap();
        let a = GpuRenderer::new(ctx.clone(), &scene, &GpuVariants::default()).unwrap();
        let b = GpuRenderer::new(ctx.clone(), &scene, &GpuVariants::default()).unwrap();
        assert!(Arc::ptr_eq(&a.kernels, &b.kernels));
        let other = GpuRenderer::new(Arc::new(GpuContext::new().unwrap()), &scene, &GpuVariants::default()).unwrap();
        assert!(!Arc::ptr_eq(&a.kernels, &other.kernels));
    }
}
