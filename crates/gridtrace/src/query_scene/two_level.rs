//! The scene's two levels on the CPU: each mesh's own structure, built once in the mesh's own
//! space (the bottom level: whichever structure the scene's `accel` names, `SceneMesh::bottom`),
//! and a BVH over the instances' world boxes (the top level, `top_level.rs`).
//!
//! A ray meets an instance by being carried into its mesh's space: origin and direction through
//! the inverse transform kept with the instance, the direction **not normalised**, so that `t`
//! along the carried ray is `t` along the world ray. The mesh's structure is then walked with
//! the closest hit so far as `t_max`, and the answer comes back in world terms: the same `t`,
//! the instance's id, the face's index within its mesh, its u and v, and the world-space
//! geometric normal (`geometry::normal_to_world`).
//!
//! Moving an instance or changing its mask rebuilds only this (the records and the top level:
//! `TwoLevel::build` finds every bottom level built); no mesh structure is touched.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::AtomicUsize;

use glam::{Affine3A, Vec3};

use super::geometry::{Geometry, SceneMesh, carry, normal_to_world};
use crate::Result;
use crate::accel::{Aabb, Hit, NoCounters, Ray};
use crate::query::{QueryOptions, TraceMesh};

/// One instance as the walk reads it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Placed {
    /// World to the mesh's own space (the transform's inverse, kept).
    pub to_local: Affine3A,
    pub id: u32,
    pub mask: u32,
    /// Index into `TwoLevel::meshes`.
    pub mesh: u32,
}

/// A hit of the two levels, named: `t` along the world ray, the instance's id, the face's
/// index within its mesh, u and v.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct NamedHit {
    pub t: f32,
    pub id: u32,
    pub prim: u32,
    pub u: f32,
    pub v: f32,
}

/// The instances (those whose mesh has a face to hit) and the top level over them.
pub(crate) struct TwoLevel {
    pub placed: Vec<Placed>,
    /// Each mesh once, however many instances place it; its bottom level built.
    meshes: Vec<Arc<SceneMesh>>,
    top: super::top_level::TopLevel,
    /// Whether every instance's mask is all ones (then a ray's mask of all ones sees every
    /// instance, and the entries need no filter).
    all_masks_full: bool,
}

impl TwoLevel {
    /// The records and the top level for `geometries`, building the bottom level of any mesh
    /// that has none yet (counted in `builds`).
    pub fn build(geometries: &BTreeMap<u32, Geometry>, opts: &QueryOptions, builds: &AtomicUsize) -> Result<TwoLevel> {
        let mut meshes: Vec<Arc<SceneMesh>> = Vec::new();
        let mut index: std::collections::HashMap<*const SceneMesh, u32> = std::collections::HashMap::new();
        let mut placed = Vec::with_capacity(geometries.len());
        let mut boxes = Vec::with_capacity(geometries.len());
        for (&id, g) in geometries {
            if g.mesh().bottom(opts, builds)?.is_none() {
                continue;
            }
            let mesh = *index.entry(Arc::as_ptr(g.mesh())).or_insert_with(|| {
                meshes.push(g.mesh().clone());
                (meshes.len() - 1) as u32
            });
            placed.push(Placed {
                to_local: g.to_local(),
                id,
                mask: g.mask(),
                mesh,
            });
            boxes.push(padded(g.world_bounds()));
        }
        Ok(TwoLevel {
            top: super::top_level::TopLevel::build(&boxes),
            all_masks_full: placed.iter().all(|p| p.mask == u32::MAX),
            placed,
            meshes,
        })
    }

    /// An error when a mesh's structure may not be traced by the CPU (`hwrt`'s rays:
    /// `Accel::check_cpu_traces`); `rays` false checks only that it is current (hit lists).
    pub fn check_cpu(&self, rays: bool) -> Result<()> {
        for m in &self.meshes {
            let a = &self.bottom(m).prepared().accel;
            if rays {
                a.check_cpu_traces()?
            } else {
                a.check_current()?
            }
        }
        Ok(())
    }

    #[inline(always)]
    fn bottom<'a>(&self, m: &'a SceneMesh) -> &'a TraceMesh {
        m.built().expect("TwoLevel::build built every bottom level it keeps")
    }

    #[inline(always)]
    fn mesh_of(&self, p: &Placed) -> &TraceMesh {
        self.bottom(&self.meshes[p.mesh as usize])
    }

    /// Bytes of the records and the top level (the meshes are the scene's: `memory_bytes`).
    pub fn records_bytes(&self) -> usize {
        std::mem::size_of_val(self.placed.as_slice())
            + std::mem::size_of_val(self.meshes.as_slice())
            + self.top.memory_bytes()
    }

    /// The closest hit in the ray's interval of instances whose mask shares a bit with the
    /// ray's, and the instance hit; with the world-space unit normal.
    #[inline]
    pub fn closest(&self, ray: &Ray) -> Option<(NamedHit, Vec3)> {
        let mut best = Hit::MISS;
        let mut who = usize::MAX;
        self.top.walk(ray, |i, _, t_max| {
            let p = &self.placed[i as usize];
            if p.mask & ray.mask == 0 {
                return t_max;
            }
            // Up to the closest hit so far, in the instances already walked.
            let local = carry(&p.to_local, ray).upto(t_max);
            let h = self.mesh_of(p).prepared().accel.intersect(&local, &mut NoCounters);
            if h.is_hit() && h.t < t_max {
                best = h;
                who = i as usize;
                h.t
            } else {
                t_max
            }
        });
        (who < self.placed.len()).then(|| self.name(who, &best))
    }

    /// A hit `h` of instance `who`'s mesh (its own triangle index) in world terms: the
    /// instance's id, the face's index among the mesh's faces as given, and the world-space
    /// unit normal (`named`, the face's normal looked up).
    #[inline]
    pub fn name(&self, who: usize, h: &Hit) -> (NamedHit, Vec3) {
        let n_local = self.mesh_of(&self.placed[who]).prepared().accel.tris[h.tri as usize].normal();
        self.named(who as u32, h, n_local)
    }

    /// A bottom-level hit `hit` of instance `i` on a face of own-space geometric normal
    /// `n_local` (any length) in world terms: its id, the face's index within its mesh, and
    /// the world-space unit normal.
    #[inline]
    pub fn named(&self, i: u32, hit: &Hit, n_local: Vec3) -> (NamedHit, Vec3) {
        let p = &self.placed[i as usize];
        let mesh = self.mesh_of(p);
        let n = (normal_to_world(&p.to_local) * n_local).normalize();
        let named = NamedHit {
            t: hit.t,
            id: p.id,
            prim: mesh.original_index(hit.tri),
            u: hit.u,
            v: hit.v,
        };
        (named, n)
    }

    /// The index among its mesh's faces as given of triangle `tri` of instance `i`'s structure.
    #[inline]
    pub fn prim_of(&self, i: u32, tri: u32) -> u32 {
        self.mesh_of(&self.placed[i as usize]).original_index(tri)
    }

    /// The fast winding tree of instance `i`'s mesh, over `accel_of(i).tris` (built on first
    /// use, once a mesh: `SceneMesh::winding`).
    #[inline]
    pub fn winding_of(&self, i: u32) -> &crate::accel::winding::FastWinding {
        self.meshes[self.placed[i as usize].mesh as usize]
            .winding()
            .expect("TwoLevel::build built every bottom level it keeps")
    }

    /// The structure of instance `i`'s mesh.
    #[inline]
    pub fn accel_of(&self, i: u32) -> &crate::accel::Accel {
        &self.mesh_of(&self.placed[i as usize]).prepared().accel
    }

    /// Appends to `out` `(t_enter, instance, ray)` for each ray `(ray, origin, dir)` of `rays`
    /// and each instance whose mask shares a bit with `mask` and whose box the ray enters
    /// within `[t_near, t_far]` (`t_enter` at least `t_near`), in no particular order (the
    /// streamed walk, `streamed_rays.rs`, then walks each instance's rays together).
    pub fn entries(
        &self,
        rays: impl Iterator<Item = (u32, Vec3, Vec3)>,
        t_near: f32,
        t_far: f32,
        mask: u32,
        out: &mut Vec<(f32, u32, u32)>,
    ) {
        let from = out.len();
        self.top.entered(rays, t_near, t_far, out);
        if !self.all_masks_full || mask != u32::MAX {
            let mut kept = from;
            for e in from..out.len() {
                let entry = out[e];
                if self.placed[entry.1 as usize].mask & mask != 0 {
                    out[kept] = entry;
                    kept += 1;
                }
            }
            out.truncate(kept);
        }
    }

    /// How many instances the scene places.
    pub fn instance_count(&self) -> usize {
        self.placed.len()
    }

    /// Each mesh once (`Placed::mesh` indexes it), with its structure.
    pub fn meshes(&self) -> impl Iterator<Item = (&Arc<SceneMesh>, &crate::accel::Accel)> {
        self.meshes.iter().map(|m| (m, &self.bottom(m).prepared().accel))
    }

    /// The top level over `placed` (their indices in its leaves).
    pub fn top(&self) -> &super::top_level::TopLevel {
        &self.top
    }

    /// Whether anything in the ray's interval is hit among instances whose mask shares a bit
    /// with the ray's.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        let mut any = false;
        self.top.walk(ray, |i, _, t_max| {
            let p = &self.placed[i as usize];
            if p.mask & ray.mask == 0 {
                return t_max;
            }
            let local = carry(&p.to_local, ray);
            if self.mesh_of(p).prepared().accel.occluded(&local, &mut NoCounters) {
                any = true;
                return f32::NEG_INFINITY;
            }
            t_max
        });
        any
    }

    /// Every hit in the ray's interval among instances whose mask shares a bit with the ray's,
    /// appended to `out` in no particular order; `scratch` is the bottom levels' list.
    #[inline]
    pub fn all_hits(&self, ray: &Ray, scratch: &mut Vec<Hit>, out: &mut Vec<NamedHit>) {
        self.top.walk(ray, |i, _, t_max| {
            let p = &self.placed[i as usize];
            if p.mask & ray.mask == 0 {
                return t_max;
            }
            let mesh = self.mesh_of(p);
            scratch.clear();
            mesh.prepared().accel.all_hits(&carry(&p.to_local, ray), scratch);
            out.extend(scratch.iter().map(|h| NamedHit {
                t: h.t,
                id: p.id,
                prim: mesh.original_index(h.tri),
                u: h.u,
                v: h.v,
            }));
            t_max
        });
    }
}

/// A world box widened by a thousandth of its largest side: the world box, made from the
/// own-space box's corners in float, may round inwards, and the ray carried into the instance
/// rounds apart from the world ray, so a hit on the own-space box's surface may lie a few ulps
/// outside the world box. 1e-3 is far more than both (it was sized for the slack the triangle
/// test had before the watertight test, and costs the walk nothing measurable).
fn padded(b: Aabb) -> Aabb {
    let pad = Vec3::splat(b.extent().max_element() * 1e-3 + f32::MIN_POSITIVE);
    Aabb {
        min: b.min - pad,
        max: b.max + pad,
    }
}
