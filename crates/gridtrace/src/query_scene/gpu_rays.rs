//! The ray queries over the two levels on the GPU (`gpu::walks::two_level`): closest hits and
//! occlusion, each ray with its own interval and mask. The meshes' structures are the CPU's
//! bottom levels (built once, in each mesh's own space), laid out one after another and
//! uploaded once; the top level (nodes and instance records) is uploaded again after a move
//! (`set_transforms`, `set_mask`, an instance added of a mesh already there), and nothing else.
//! A mesh added or removed uploads the meshes again. For `hwrt` the two levels are the
//! driver's (`gpu::walks::hwrt::instances`): a BLAS a mesh, built once at the upload, and a
//! TLAS that a move rebuilds alone (its instances' bytes, and the instance table where a mask
//! changed).
//!
//! The wire: rows that share one interval and mask go up as 24 bytes a ray, the interval and
//! mask in the batch's uniform; rows with their own go up as 36 (origin, t_near, direction,
//! t_far, mask: `OptionRows`), 12 bytes a ray more. The answers come down as 16 bytes a ray
//! (t, the triangle's number among every instance's, u, v) for closest hits, one bit for
//! occlusion, and are named here (instance id, face, world normal) as the CPU's two levels
//! name theirs (`TwoLevel::name`).

use std::sync::Arc;

use super::QueryScene;
use super::batch::{RayHits, RayOptions, STAND_IN, ray_of, write_gpu_hits};
use super::geometry::SceneMesh;
use super::gpu_all_hits::{DeviceAnswer, DeviceHits};
use super::rays::{RowRays, occlusion_into};
use super::two_level::{NamedHit, TwoLevel};
use crate::accel::{Accel, Hit};
use crate::gpu::layout::GpuHit;
use crate::gpu::walks::hwrt::instances::{DriverInstances, Placement, instance_table};
use crate::gpu::walks::two_level::{self, BottomLevels, Instance, TopLevel};
use crate::gpu::{AllHits, Answer, ChunkAnswers, GpuContext, GpuRenderer, WireSource};
use crate::{Error, Result};
use glam::Vec3;

/// What the scene's GPU holds and has written (`QueryScene::gpu_uploads`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GpuUploads {
    /// Bytes of the meshes' structures on the device (and their triangles).
    pub mesh_bytes: u64,
    /// How many times the meshes' structures were uploaded: once, and again only after a mesh
    /// was added or removed.
    pub mesh_uploads: u32,
    /// Nodes of the top level on the device, and instance records after them (64 bytes each;
    /// `hwrt`: no nodes, the driver's TLAS instances, 64 bytes each, and its instance table).
    pub top_nodes: u32,
    pub top_records: u32,
    /// `hwrt` (the driver's instances): BLASes built (one a mesh, at the meshes' upload) and
    /// TLAS builds (that upload and each move); 0 for the other structures.
    pub blas_builds: u32,
    pub tlas_builds: u32,
    /// Bytes written to the device's scene arrays by this scene's renderer (meshes, top
    /// levels), as the renderer counts its writes (`GpuRenderer::scene_upload_bytes`).
    pub written_bytes: u64,
}

/// The scene on the GPU: the renderer of its two levels, and what it was made from.
pub(super) struct GpuTwoLevel {
    renderer: GpuRenderer,
    /// The meshes whose structures are on the device, in their order there.
    meshes: Vec<Arc<SceneMesh>>,
    /// The meshes' headers and triangle counts (their arrays dropped once uploaded).
    bottoms: BottomLevels,
    /// The two levels whose top is on the device, and that top's layout.
    two: Arc<TwoLevel>,
    top: TopLevel,
    /// `hwrt`: the meshes' BLASes and the TLAS's builds.
    driver: Option<DriverInstances>,
    uploads: GpuUploads,
}

/// The meshes' structures of `two`, in its order.
fn accels(two: &TwoLevel) -> Vec<&Accel> {
    two.meshes().map(|(_, a)| a).collect()
}

/// The top level of `two` laid out over `bottoms` (no instances: `None`), and for a walk by
/// ray query (`hwrt`) the TLAS's instances, its top level the instance table.
fn top_of(two: &TwoLevel, bottoms: &BottomLevels) -> Result<Option<(TopLevel, Option<Vec<Placement>>)>> {
    let Some(tree) = two.top().as_bvh() else {
        return Ok(None);
    };
    let instances: Vec<Instance> = two
        .placed
        .iter()
        .map(|p| Instance {
            to_local: p.to_local,
            mask: p.mask,
            mesh: p.mesh,
        })
        .collect();
    if bottoms.spec.tlas.is_some() {
        let (top, placements) = instance_table(&instances, bottoms)?;
        return Ok(Some((top, Some(placements))));
    }
    Ok(Some((TopLevel::new(&tree, &instances, bottoms)?, None)))
}

impl GpuTwoLevel {
    /// Uploads `two`'s meshes and top level to `ctx`'s device (`uploads`: the counts so far).
    fn upload(
        ctx: Arc<GpuContext>,
        two: &Arc<TwoLevel>,
        bottoms: BottomLevels,
        scene: &QueryScene,
        mut uploads: GpuUploads,
    ) -> Result<GpuTwoLevel> {
        let (top, placements) = top_of(two, &bottoms)?.expect("a scene with no instance does not reach the GPU");
        let (driver, device) = match placements {
            Some(p) => {
                let tris: Vec<&[crate::accel::TriAccel]> = accels(two).iter().map(|a| &a.tris[..]).collect();
                let (d, device) = DriverInstances::build(&ctx, &tris, &p)?;
                (Some(d), Some(device))
            }
            None => (None, None),
        };
        let renderer = GpuRenderer::two_level(ctx, &bottoms, &top, &scene.opts.gpu_variants, device)?;
        uploads.mesh_bytes = bottoms.bytes() + driver.as_ref().map_or(0, |d| d.input_bytes);
        uploads.mesh_uploads += 1;
        if let Some(d) = &driver {
            uploads.blas_builds += d.blas_builds;
            uploads.tlas_builds += 1;
        }
        let mut g = GpuTwoLevel {
            renderer,
            meshes: two.meshes().map(|(m, _)| m.clone()).collect(),
            bottoms: BottomLevels {
                arrays: Vec::new(),
                tris: Vec::new(),
                ..bottoms
            },
            two: two.clone(),
            top,
            driver,
            uploads,
        };
        g.count_top();
        Ok(g)
    }

    /// Brings the top level up to `two` (same meshes): uploads it alone (`hwrt`: rebuilds the
    /// TLAS, and writes the instance table where it changed).
    fn move_to(&mut self, two: &Arc<TwoLevel>) -> Result<()> {
        let (top, placements) = top_of(two, &self.bottoms)?.expect("a scene with no instance does not reach the GPU");
        match (placements, self.driver.as_mut()) {
            (Some(p), Some(d)) => {
                // By bytes: the table's words are no floats (an all-ones mask reads as NaN).
                if bytemuck::cast_slice::<_, u8>(&top.recs) != bytemuck::cast_slice::<_, u8>(&self.top.recs) {
                    self.renderer.set_top_level(&top)?;
                }
                self.renderer.rebuild_tlas(|ctx, tlas| d.set_instances(ctx, tlas, &p))?;
                self.uploads.tlas_builds += 1;
            }
            _ => {
                self.renderer.set_top_level(&top)?;
            }
        }
        self.top = top;
        self.two = two.clone();
        self.count_top();
        Ok(())
    }

    fn count_top(&mut self) {
        self.uploads.top_nodes = self.top.nodes as u32;
        self.uploads.top_records = self.top.order.len() as u32;
        self.uploads.written_bytes = self.renderer.scene_upload_bytes();
    }

    /// Whether the device holds the structures of exactly `two`'s meshes, in its order.
    fn same_meshes(&self, two: &TwoLevel) -> bool {
        self.meshes.len() == two.meshes().count()
            && self
                .meshes
                .iter()
                .zip(two.meshes())
                .all(|(a, (b, _))| Arc::ptr_eq(a, b))
    }
}

/// Rows with their own interval and mask, 36 bytes a ray on the wire (origin, t_near,
/// direction, t_far, mask), a row that cannot hit anything as `STAND_IN` with an empty
/// interval.
struct OptionRows<'a> {
    rows: &'a [[f32; 6]],
    o: &'a RayOptions<'a>,
}

impl WireSource for OptionRows<'_> {
    fn len(&self) -> usize {
        self.rows.len()
    }

    fn stride(&self) -> usize {
        9
    }

    fn write(&self, first: usize, out: wgpu::WriteOnly<'_, [u8]>) -> bool {
        let (out, _) = out.into_chunks::<36>();
        let count = out.len();
        out.write_iter(self.rows[first..first + count].iter().enumerate().map(|(k, r)| {
            let (t_near, t_far, mask) = self.o.of(first + k);
            let (r, t_far) = match ray_of(r) {
                Some(_) => (*r, t_far),
                None => {
                    let (o, d) = (STAND_IN.origin, STAND_IN.dir);
                    ([o.x, o.y, o.z, d.x, d.y, d.z], -1.0)
                }
            };
            let words: [u32; 9] = [
                r[0].to_bits(),
                r[1].to_bits(),
                r[2].to_bits(),
                t_near.to_bits(),
                r[3].to_bits(),
                r[4].to_bits(),
                r[5].to_bits(),
                t_far.to_bits(),
                mask,
            ];
            bytemuck::cast::<[u32; 9], [u8; 36]>(words)
        }));
        true
    }

    fn invalid(&self) -> Error {
        Error::InvalidInput("a scene's rays go to the GPU whole, bad ones as stand-ins".into())
    }
}

impl QueryScene {
    /// Whether the ray queries of `two` run on the GPU's two levels: a backend that traces on
    /// a GPU, and meshes whose structure the GPU carries under a top level
    /// (`two_level::walk_for`: every structure but `hwrt` today).
    pub(super) fn gpu_carries(&self, two: &TwoLevel) -> bool {
        let walk = self.opts.gpu_variants.bvh_walk();
        let mut specs = two.meshes().map(|(_, a)| two_level::walk_for(&a.structure, walk));
        // One walk for every mesh (`bottom_levels` lays out meshes of one structure).
        let first = specs.next().flatten();
        self.traces_on_gpu()
            && !two.placed.is_empty()
            && first.is_some_and(|f| specs.all(|s| s.is_some_and(|s| std::ptr::eq(s, f))))
    }

    /// Whether the GPU's two levels of `two` are walked by ray query (`hwrt`'s driver
    /// instances), which find closest and any hits only: their counts and lists of hits take
    /// the merged mesh's GPU walk where it answers the rays, else the CPU's two levels
    /// (`all_hits_on_gpu`).
    pub(super) fn gpu_walks_by_ray_query(&self, two: &TwoLevel) -> bool {
        let walk = self.opts.gpu_variants.bvh_walk();
        two.meshes()
            .any(|(_, a)| two_level::walk_for(&a.structure, walk).is_some_and(|w| w.tlas.is_some()))
    }

    /// What the last ray batch on the GPU's two levels took; `None` before the first.
    pub(super) fn two_level_batch_stats(&self) -> Option<crate::gpu::GpuQueryStats> {
        self.gpu
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
            .map(|g| g.renderer.last_query_stats().clone())
    }

    /// What the scene's GPU holds and has written; `None` before its first GPU ray query.
    pub fn gpu_uploads(&self) -> Option<GpuUploads> {
        self.gpu
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
            .map(|g| g.uploads)
    }

    /// Runs `f` on the GPU's two levels, brought up to `two` first: the top level alone where
    /// the device holds `two`'s meshes already, else everything.
    fn on_gpu_two_level<T>(&self, two: &Arc<TwoLevel>, f: impl FnOnce(&mut GpuTwoLevel) -> Result<T>) -> Result<T> {
        let mut slot = self.gpu.lock().unwrap_or_else(|p| p.into_inner());
        let mut g = match slot.take() {
            Some(g) if Arc::ptr_eq(&g.two, two) => g,
            Some(mut g) if g.same_meshes(two) => {
                g.move_to(two)?;
                g
            }
            old => {
                let (ctx, uploads) = match old {
                    Some(g) => (g.renderer.context().clone(), g.uploads),
                    None => {
                        // The scene's device (`QueryPlacement`): under `auto` one that could
                        // not be opened is a fault, which sends the scene to the CPU.
                        let mut notes = Vec::new();
                        let placement = self.placement.placement(self.opts.backend, &mut notes)?;
                        let ctx = placement.device.ok_or_else(|| Error::Gpu(notes.join("; ")))?;
                        (ctx, GpuUploads::default())
                    }
                };
                let bottoms = two_level::bottom_levels(&accels(two), self.opts.gpu_variants.bvh_walk())?
                    .ok_or_else(|| Error::Gpu("the scene's meshes have no GPU walk of two levels".into()))?;
                GpuTwoLevel::upload(ctx, two, bottoms, self, uploads)?
            }
        };
        let r = f(&mut g);
        if r.is_ok() {
            self.answered_on_gpu(g.renderer.last_query_stats());
        }
        *slot = Some(g);
        r
    }

    /// Closest hits of `rays` on the GPU's two levels, into `out` (every entry written).
    pub(super) fn gpu_cast(&self, two: &Arc<TwoLevel>, rays: &[[f32; 6]], o: &RayOptions) -> Result<RayHits> {
        let mut out = RayHits::zeroed(rays.len());
        self.on_gpu_two_level(two, |g| {
            let GpuTwoLevel { renderer, top, two, .. } = g;
            let take = |first: usize, answers: ChunkAnswers<'_>| {
                if let ChunkAnswers::HitsUv(hits) = answers {
                    let valid = |i: usize| ray_of(&rays[i]).is_some();
                    write_gpu_hits(&mut out, first, hits, valid, &named_by(top, two));
                }
            };
            cast(renderer, rays, o, Answer::Hits { uv: true }, take)
        })?;
        Ok(out)
    }

    /// Whether each ray hits anything, on the GPU's two levels.
    pub(super) fn gpu_occluded(&self, two: &Arc<TwoLevel>, rays: &[[f32; 6]], o: &RayOptions) -> Result<Vec<bool>> {
        let mut out = vec![false; rays.len()];
        self.on_gpu_two_level(two, |g| {
            cast(&mut g.renderer, rays, o, Answer::Occlusion, |first, answers| {
                occlusion_into(&mut out, rays, first, answers)
            })
        })?;
        Ok(out)
    }
}

impl QueryScene {
    /// Counts or lists of every hit of `rays` with `o` on the GPU's two levels
    /// (`gpu_all_hits.rs`): 24 bytes a ray up where they share one interval and mask, else 36.
    pub(super) fn gpu_all_hits(
        &self,
        two: &Arc<TwoLevel>,
        rays: &[[f32; 6]],
        o: &RayOptions,
        answer: AllHits,
    ) -> Result<DeviceAnswer> {
        self.on_gpu_two_level(two, |g| {
            let GpuTwoLevel { renderer, top, two, .. } = g;
            let mut out = DeviceHits::new(rays, answer);
            let take = |first: usize, counts: &[u32], hits: &[GpuHit]| out.take(first, counts, hits);
            let firsts = &top.first_answer;
            match o.uniform() {
                Some((t_near, t_far, mask)) => {
                    renderer.all_hits(&RowRays { rows: rays }, (t_near, t_far), mask, firsts, answer, take)
                }
                None => renderer.all_hits(
                    &OptionRows { rows: rays, o },
                    (0.0, f32::INFINITY),
                    u32::MAX,
                    firsts,
                    answer,
                    take,
                ),
            }?;
            Ok(out.answer(|h| {
                let (named, _) = name(top, two, &crate::gpu::gpu_hit(*h));
                (named.id, named.prim, [named.u, named.v], named.t)
            }))
        })
    }

    /// A scan's closest hits on the GPU's two levels, the rays made on the device
    /// (`gpu_scan.rs`).
    pub(super) fn gpu_scan(&self, two: &Arc<TwoLevel>, s: &crate::gpu::ScanRays, range_only: bool) -> Result<RayHits> {
        let mut out = RayHits::misses(s.len());
        self.on_gpu_two_level(two, |g| {
            let GpuTwoLevel { renderer, top, two, .. } = g;
            super::gpu_scan::scan_with(renderer, s, range_only, |first, answers| {
                super::gpu_scan::take_scan_answers(&mut out, first, answers, &named_by(top, two))
            })
        })?;
        Ok(out)
    }
}

/// `name` as `write_gpu_hits` takes it: a hit's row written in world terms.
fn named_by<'a>(
    top: &'a TopLevel,
    two: &'a TwoLevel,
) -> impl Fn(&Hit, &mut f32, &mut u32, &mut u32, &mut [f32; 2], &mut [f32; 3]) + Sync + 'a {
    move |h, t, id, p, uv, n| {
        let (named, normal) = name(top, two, h);
        (*t, *id, *p) = (named.t, named.id, named.prim);
        *uv = [named.u, named.v];
        *n = normal.to_array();
    }
}

/// A GPU hit (its triangle numbered among every instance's, `top`) in world terms: the
/// instance's id, the face, u, v and the world-space unit normal.
#[inline]
fn name(top: &TopLevel, two: &TwoLevel, h: &Hit) -> (NamedHit, Vec3) {
    let (who, tri) = top.name(h.tri);
    two.name(who as usize, &Hit { tri, ..*h })
}

/// Casts `rays` with `o` for `answer`: 24 bytes a ray when the rays share one interval and
/// mask, else 36.
fn cast(
    renderer: &mut GpuRenderer,
    rays: &[[f32; 6]],
    o: &RayOptions,
    answer: Answer,
    take: impl FnMut(usize, ChunkAnswers<'_>),
) -> Result<()> {
    match o.uniform() {
        Some((t_near, t_far, mask)) => {
            renderer.cast_masked(&RowRays { rows: rays }, (t_near, t_far), mask, answer, take)
        }
        None => renderer.cast_masked(
            &OptionRows { rows: rays, o },
            (0.0, f32::INFINITY),
            u32::MAX,
            answer,
            take,
        ),
    }
}
