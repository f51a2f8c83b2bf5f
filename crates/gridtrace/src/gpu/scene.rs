//! The scene on the GPU: the triangles, per-triangle shading data, materials and the scene
//! constants, and the structure's own arrays with their bind group (`walks`: each structure's
//! GPU side), uploaded once per renderer. Camera and lights are not here; they change per frame.

use std::sync::Arc;

use wgpu::util::DeviceExt;

use super::context::{GpuContext, check_scene_fits};
use super::kernels::{Kernels, WalkPipelines};
use super::layout::{GpuMaterial, GpuTri, SceneUniform, TriShade};
use super::variants::GpuVariants;
use super::walks::two_level::{BottomLevels, TopLevel};
use super::walks::{DeviceStructure, WalkSpec, device_structure, upload_of};
use crate::scene::PreparedScene;
use crate::{Error, Result};

/// Per-triangle shading data: the vertex normals and the material.
pub(crate) fn tri_shade(scene: &PreparedScene) -> Vec<TriShade> {
    use rayon::prelude::*;
    scene
        .tri_vertices
        .par_iter()
        .zip(&scene.tri_material)
        .map(|(v, &m)| TriShade {
            n0: scene.normals[v[0] as usize].to_array(),
            n1: scene.normals[v[1] as usize].to_array(),
            n2: scene.normals[v[2] as usize].to_array(),
            material: m,
        })
        .collect()
}

/// The scene's buffers on the device.
pub(crate) struct SceneBuffers {
    /// The structure's walk: its spec, pipelines and group 1's layout.
    pub walk: Arc<WalkPipelines>,
    /// The structure's arrays, in `walk.spec.arrays` order, and their bind group (group 1).
    pub structure: Vec<wgpu::Buffer>,
    /// The top-level acceleration structure of a walk by ray query (`WalkSpec::tlas`), bound
    /// after the arrays.
    pub tlas: Option<wgpu::Tlas>,
    pub structure_group: wgpu::BindGroup,
    pub tris: wgpu::Buffer,
    pub tri_shade: wgpu::Buffer,
    pub materials: wgpu::Buffer,
    /// `SceneUniform`, rewritten per frame with the frame's light count.
    pub uniform: wgpu::Buffer,
    /// The scene constants without lights (`n_lights` = 0).
    pub consts: SceneUniform,
    /// Bytes of each scene array, for `GpuRenderer::memory`.
    pub bytes: Vec<(&'static str, u64)>,
    /// Bytes written to the scene's arrays since they were made, the first upload included
    /// (`GpuRenderer::scene_upload_bytes`: a scene of two levels counts its moves here).
    pub uploaded_bytes: u64,
}

/// A storage buffer holding `data` (an empty array gets 16 bytes of padding: zero-length
/// bindings are invalid).
fn storage(dev: &wgpu::Device, label: &str, data: &[u8]) -> wgpu::Buffer {
    let contents: &[u8] = if data.is_empty() { &[0u8; 16] } else { data };
    dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
    })
}

/// What a scene's upload holds, before it is on the device: the walk and its arrays (in
/// `spec.arrays` order), group 0's shared arrays and the scene constants.
struct SceneArrays<'a> {
    spec: &'static WalkSpec,
    arrays: Vec<&'a [u8]>,
    /// Triangles, shading data, materials.
    shared: [(&'static str, &'a [u8]); 3],
    consts: SceneUniform,
    /// The triangles a ray may test at most (`WalkSpec::software_max_tris`).
    reachable_tris: usize,
}

impl SceneBuffers {
    /// Checks the scene against the device's limits and uploads it, in the layout and with the
    /// walk `variants` choose.
    pub fn upload(ctx: &GpuContext, scene: &PreparedScene, variants: &GpuVariants) -> Result<SceneBuffers> {
        let walk = upload_of(scene, variants.bvh_walk())?;
        let tri_shade = tri_shade(scene);
        let materials: Vec<GpuMaterial> = scene
            .materials
            .iter()
            .map(|m| GpuMaterial {
                diffuse: m.diffuse.to_array(),
                reflectivity: m.reflectivity,
            })
            .collect();
        let gpu_tris = GpuTri::all(&scene.accel.tris);
        let mut consts = SceneUniform {
            ray_epsilon: scene.ray_epsilon,
            n_lights: 0,
            n_tris: scene.accel.tris.len() as u32,
            background: scene.background.to_array(),
            ambient: scene.ambient.to_array(),
            ..bytemuck::Zeroable::zeroed()
        };
        walk.lattice.write_to(&mut consts);
        let parts = SceneArrays {
            spec: walk.spec,
            arrays: walk.arrays.iter().map(|a| &a[..]).collect(),
            shared: [
                ("triangles", bytemuck::cast_slice(&gpu_tris)),
                ("tri_shade", bytemuck::cast_slice(&tri_shade)),
                ("materials", bytemuck::cast_slice(&materials)),
            ],
            consts,
            reachable_tris: scene.accel.tris.len(),
        };
        Self::from_arrays(ctx, parts, variants, || device_structure(ctx, scene))
    }

    /// Uploads a scene of two levels (`walks::two_level`): the meshes' structures, laid out by
    /// `bottoms`, and the top level `top`; `device`, the TLAS of a walk by ray query (`hwrt`'s
    /// driver instances, built by the caller). Rays only: no shading data, one stand-in
    /// material.
    pub fn upload_two_level(
        ctx: &GpuContext,
        bottoms: &BottomLevels,
        top: &TopLevel,
        variants: &GpuVariants,
        device: Option<DeviceStructure>,
    ) -> Result<SceneBuffers> {
        let stand_in_shade = [TriShade {
            n0: [0.0; 3],
            n1: [0.0; 3],
            n2: [0.0; 3],
            material: 0,
        }];
        let stand_in_material = [GpuMaterial {
            diffuse: [0.0; 3],
            reflectivity: 0.0,
        }];
        let parts = SceneArrays {
            spec: bottoms.spec,
            arrays: bottoms
                .arrays
                .iter()
                .map(|a| &a[..])
                .chain([bytemuck::cast_slice(&top.recs)])
                .collect(),
            shared: [
                ("triangles", bytemuck::cast_slice(&bottoms.tris)),
                ("tri_shade", bytemuck::cast_slice(&stand_in_shade)),
                ("materials", bytemuck::cast_slice(&stand_in_material)),
            ],
            consts: SceneUniform {
                n_tris: bottoms.tris.len() as u32,
                ..bytemuck::Zeroable::zeroed()
            },
            reachable_tris: top.answers as usize,
        };
        Self::from_arrays(ctx, parts, variants, || Ok(device))
    }

    /// The upload itself: checks, the walk's pipelines, the buffers, the bind group, and the
    /// device's own structure (`device`) where the walk traces one.
    fn from_arrays(
        ctx: &GpuContext,
        parts: SceneArrays<'_>,
        variants: &GpuVariants,
        device: impl FnOnce() -> Result<Option<DeviceStructure>>,
    ) -> Result<SceneBuffers> {
        let dev = &ctx.device;
        let SceneArrays {
            spec,
            arrays,
            shared,
            consts,
            reachable_tris,
        } = parts;
        let named: Vec<(&'static str, &[u8])> = spec.arrays.iter().map(|a| a.0).zip(arrays).chain(shared).collect();
        let bytes: Vec<(&'static str, u64)> = named.iter().map(|(n, d)| (*n, d.len() as u64)).collect();
        check_scene_fits(&bytes, &ctx.limits(), &ctx.info.name)?;
        if let Some(max) = spec.software_max_tris.filter(|_| ctx.is_software())
            && reachable_tris > max as usize
        {
            return Err(Error::Gpu(format!(
                "'{}' on a software adapter ('{}') takes at most {max} triangles (its shader loops end after \
                 65,535 iterations); this scene has {reachable_tris}",
                spec.structure, ctx.info.name
            )));
        }
        if spec.tlas.is_some() {
            // Before compiling: the walk's module needs the feature this names.
            ctx.check_ray_queries(spec.structure.name())?;
        }
        let pipelines = Kernels::of(ctx, variants)?.walk(dev, spec)?;
        let structure: Vec<wgpu::Buffer> = named[..spec.arrays.len()]
            .iter()
            .map(|(label, data)| storage(dev, label, data))
            .collect();
        let device = device()?;
        let mut bytes = bytes;
        if let Some(d) = &device {
            bytes.push(("ray-query geometry", d.input_bytes));
        }
        let uploaded_bytes = bytes.iter().map(|b| b.1).sum();
        let tlas = device.map(|d| d.tlas);
        let structure_group = structure_group(dev, &pipelines, &structure, tlas.as_ref());
        let [tris, tri_shade, materials] = shared.map(|(n, d)| storage(dev, n, d));
        let uniform = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("scene uniform"),
            size: std::mem::size_of::<SceneUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        ctx.queue.write_buffer(&uniform, 0, bytemuck::bytes_of(&consts));
        Ok(SceneBuffers {
            walk: pipelines,
            structure,
            tlas,
            structure_group,
            tris,
            tri_shade,
            materials,
            uniform,
            consts,
            bytes,
            uploaded_bytes,
        })
    }

    /// The structure's walk.
    pub fn spec(&self) -> &'static WalkSpec {
        self.walk.spec
    }

    /// Writes `data` over the structure's array `label` from its start (a new buffer if it
    /// does not fit, rebound), counted in `uploaded_bytes`; returns the bytes written.
    pub fn write_array(&mut self, ctx: &GpuContext, label: &str, data: &[u8]) -> Result<u64> {
        let i = self
            .spec()
            .arrays
            .iter()
            .position(|a| a.0 == label)
            .ok_or_else(|| Error::Gpu(format!("the walk '{}' has no array '{label}'", self.spec().name)))?;
        if (data.len() as u64) <= self.structure[i].size() {
            ctx.queue.write_buffer(&self.structure[i], 0, data);
        } else {
            let b = storage(&ctx.device, label, data);
            self.replace_array(&ctx.device, label, &b);
        }
        if let Some(e) = self.bytes.iter_mut().find(|e| e.0 == label) {
            e.1 = data.len() as u64;
        }
        self.uploaded_bytes += data.len() as u64;
        Ok(data.len() as u64)
    }

    /// Binds group 1 again (its top-level acceleration structure replaced).
    pub fn rebind(&mut self, dev: &wgpu::Device) {
        self.structure_group = structure_group(dev, &self.walk, &self.structure, self.tlas.as_ref());
    }

    /// Replaces the structure's array `label` (the grid's GPU build writes new cells and
    /// references) and rebinds group 1. Returns whether anything changed.
    pub fn replace_array(&mut self, dev: &wgpu::Device, label: &str, buffer: &wgpu::Buffer) -> bool {
        let Some(i) = self.spec().arrays.iter().position(|a| a.0 == label) else {
            return false;
        };
        if self.structure[i] == *buffer {
            return false;
        }
        self.structure[i] = buffer.clone();
        self.structure_group = structure_group(dev, &self.walk, &self.structure, self.tlas.as_ref());
        true
    }
}

/// Group 1 of the walking kernels: the structure's arrays in binding order, then its top-level
/// acceleration structure where its walk traces by ray query.
fn structure_group(
    dev: &wgpu::Device,
    walk: &WalkPipelines,
    arrays: &[wgpu::Buffer],
    tlas: Option<&wgpu::Tlas>,
) -> wgpu::BindGroup {
    let mut entries: Vec<wgpu::BindGroupEntry> = arrays
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
    if let Some(t) = tlas {
        entries.push(wgpu::BindGroupEntry {
            binding: arrays.len() as u32,
            resource: t.as_binding(),
        });
    }
    dev.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(walk.spec.structure.name()),
        layout: &walk.layout,
        entries: &entries,
    })
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
