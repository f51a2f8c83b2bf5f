//! The scene on the GPU: grid cells, BVH nodes or the irregular grid's arrays, references, triangles, per-triangle shading data,
//! materials and the scene constants, uploaded once per renderer. Camera and lights are not
//! here; they change per frame.

use std::borrow::Cow;

use glam::{UVec3, Vec3};
use wgpu::util::DeviceExt;

use super::bvh::gpu_nodes;
use super::constants::BVH_STACK;
use super::context::GpuContext;
use super::layout::{GpuBvhNode, GpuMaterial, SceneUniform, TriShade};
use crate::accel::{Aabb, AccelKind, Cell, IrrCell, Structure, TriAccel};
use crate::scene::PreparedScene;
use crate::{Error, Result};

/// Which walk the scene's kernels take.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum GpuStructure {
    /// The 3D-DDA over `cells`, with or without proximity-cloud jumps.
    Grid,
    /// The BVH walk over `bvh_nodes`.
    Bvh,
    /// The irregular grid's walk over `irr_entries`, `irr_voxels` and `irr_cells`.
    Irregular,
}

impl GpuStructure {
    pub const ALL: [GpuStructure; 3] = [GpuStructure::Grid, GpuStructure::Bvh, GpuStructure::Irregular];

    /// Whether a scene uploaded with this structure can run traversal `accel` (as
    /// `Accel::serves`: the grid serves `grid` and `pc`, every other structure its own kind).
    pub fn serves(self, accel: AccelKind) -> bool {
        match self {
            GpuStructure::Grid => accel.uses_grid(),
            GpuStructure::Bvh => accel == AccelKind::Bvh,
            GpuStructure::Irregular => accel == AccelKind::Irregular,
        }
    }

    /// The scene arrays only this structure reads: another structure's scene binds one unused
    /// element in their place, which is not the scene's memory.
    fn own_arrays(self) -> &'static [&'static str] {
        match self {
            GpuStructure::Grid => &["cells"],
            GpuStructure::Bvh => &["bvh_nodes"],
            GpuStructure::Irregular => &["irr_entries", "irr_voxels", "irr_cells"],
        }
    }
}

/// What the kernels read of the prepared scene's acceleration structure. The structures a scene
/// was not prepared with get one unused element each (bindings cannot be empty).
struct AccelArrays<'a> {
    structure: GpuStructure,
    cells: Cow<'a, [Cell]>,
    /// Grid and irregular grid: the cells' triangle lists. BVH: triangle indices in leaf order.
    refs: &'a [u32],
    bvh_nodes: Vec<GpuBvhNode>,
    irr_entries: Cow<'a, [u32]>,
    irr_voxels: Cow<'a, [u32]>,
    irr_cells: Cow<'a, [IrrCell]>,
    tris: &'a [TriAccel],
    bounds: Aabb,
    /// The lattice the walk counts planes on (`SceneUniform`): the grid's cells or the
    /// irregular grid's virtual voxels; zero for a BVH.
    dims: UVec3,
    /// World-space size of one cell or voxel per axis, and its reciprocal.
    cell_size: Vec3,
    inv_cell_size: Vec3,
    /// Irregular grid: `IrregularGrid::shift`.
    shift: u32,
}

/// One unused element, for the bindings of a structure the scene was not prepared with.
fn unused<T: Clone + bytemuck::Zeroable>() -> Cow<'static, [T]> {
    Cow::Owned(vec![T::zeroed()])
}

/// The one place the GPU backend reads `scene.accel`: when its types change, only this function
/// changes.
fn accel_arrays(scene: &PreparedScene) -> Result<AccelArrays<'_>> {
    let tris = &scene.accel.tris[..];
    match &scene.accel.structure {
        Structure::Grid(g) => Ok(AccelArrays {
            structure: GpuStructure::Grid,
            cells: Cow::Borrowed(&g.cells),
            refs: &g.refs,
            bvh_nodes: vec![bytemuck::Zeroable::zeroed()],
            irr_entries: unused(),
            irr_voxels: unused(),
            irr_cells: unused(),
            tris,
            bounds: g.bounds,
            dims: g.dims,
            cell_size: g.cell_size,
            inv_cell_size: g.inv_cell_size,
            shift: 0,
        }),
        Structure::Bvh(b) => {
            if b.bvh.depth >= BVH_STACK as usize {
                // The builder bounds the depth below the stack (`STACK`); checked all the same,
                // since an overflow would lose hits silently.
                return Err(Error::InvalidInput(format!(
                    "the BVH is {} levels deep; the GPU walk's stack holds {BVH_STACK}",
                    b.bvh.depth
                )));
            }
            Ok(AccelArrays {
                structure: GpuStructure::Bvh,
                cells: unused(),
                refs: &b.bvh.prims,
                bvh_nodes: gpu_nodes(&b.bvh)?,
                irr_entries: unused(),
                irr_voxels: unused(),
                irr_cells: unused(),
                tris,
                bounds: scene.accel.bounds(),
                dims: UVec3::ZERO,
                cell_size: Vec3::ZERO,
                inv_cell_size: Vec3::ZERO,
                shift: 0,
            })
        }
        Structure::Brute(_) => Err(Error::Gpu(
            "the 'brute' structure has no GPU walk yet: trace it on the CPU (--backend cpu)".into(),
        )),
        Structure::Irregular(g) => Ok(AccelArrays {
            structure: GpuStructure::Irregular,
            cells: unused(),
            refs: &g.refs,
            bvh_nodes: vec![bytemuck::Zeroable::zeroed()],
            irr_entries: Cow::Borrowed(&g.entries),
            irr_voxels: Cow::Borrowed(&g.voxel_map),
            irr_cells: Cow::Borrowed(&g.cells),
            tris,
            bounds: g.bounds,
            dims: g.voxel_dims(),
            cell_size: g.voxel_size,
            // The CPU walk's own reciprocal, bit for bit.
            inv_cell_size: g.inv_voxel_size,
            shift: g.shift,
        }),
    }
}

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

/// The scene's buffers on the device.
pub(crate) struct SceneBuffers {
    /// The walk the kernels take.
    pub structure: GpuStructure,
    pub cells: wgpu::Buffer,
    pub bvh_nodes: wgpu::Buffer,
    pub irr_entries: wgpu::Buffer,
    pub irr_voxels: wgpu::Buffer,
    pub irr_cells: wgpu::Buffer,
    pub refs: wgpu::Buffer,
    pub tris: wgpu::Buffer,
    pub tri_shade: wgpu::Buffer,
    pub materials: wgpu::Buffer,
    /// `SceneUniform`, rewritten per frame with the frame's light count.
    pub uniform: wgpu::Buffer,
    /// The scene constants without lights (`n_lights` = 0).
    pub consts: SceneUniform,
    /// Bytes of each scene array, for `GpuRenderer::memory`.
    pub bytes: Vec<(&'static str, u64)>,
}

impl SceneBuffers {
    /// Checks the scene against the device's limits and uploads it.
    pub fn upload(ctx: &GpuContext, scene: &PreparedScene) -> Result<SceneBuffers> {
        let dev = &ctx.device;
        let accel = accel_arrays(scene)?;
        let tri_shade = tri_shade(scene);
        let materials: Vec<GpuMaterial> = scene
            .materials
            .iter()
            .map(|m| GpuMaterial {
                diffuse: m.diffuse.to_array(),
                reflectivity: m.reflectivity,
            })
            .collect();
        let arrays: [(&'static str, &[u8]); 9] = [
            ("cells", bytemuck::cast_slice(&accel.cells)),
            ("bvh_nodes", bytemuck::cast_slice(&accel.bvh_nodes)),
            ("irr_entries", bytemuck::cast_slice(&accel.irr_entries)),
            ("irr_voxels", bytemuck::cast_slice(&accel.irr_voxels)),
            ("irr_cells", bytemuck::cast_slice(&accel.irr_cells)),
            ("refs", bytemuck::cast_slice(accel.refs)),
            ("triangles", bytemuck::cast_slice(accel.tris)),
            ("tri_shade", bytemuck::cast_slice(&tri_shade)),
            ("materials", bytemuck::cast_slice(&materials)),
        ];
        let mut bytes: Vec<(&'static str, u64)> = arrays.iter().map(|(n, d)| (*n, d.len() as u64)).collect();
        check_scene_fits(&bytes, &ctx.limits(), &ctx.info.name)?;
        // The other structures' placeholders are not the scene's memory.
        let placeholders: Vec<&str> = GpuStructure::ALL
            .into_iter()
            .filter(|&st| st != accel.structure)
            .flat_map(GpuStructure::own_arrays)
            .copied()
            .collect();
        bytes.retain(|(n, _)| !placeholders.contains(n));
        let storage = |label: &str, data: &[u8]| {
            // Zero-length bindings are invalid; give empty arrays one element of padding.
            let contents: &[u8] = if data.is_empty() { &[0u8; 16] } else { data };
            dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            })
        };
        let [
            cells,
            bvh_nodes,
            irr_entries,
            irr_voxels,
            irr_cells,
            refs,
            tris,
            tri_shade,
            materials,
        ] = arrays.map(|(n, d)| storage(n, d));

        let consts = SceneUniform {
            bounds_min: accel.bounds.min.to_array(),
            ray_epsilon: scene.ray_epsilon,
            bounds_max: accel.bounds.max.to_array(),
            n_lights: 0,
            cell_size: accel.cell_size.to_array(),
            n_tris: accel.tris.len() as u32,
            inv_cell_size: accel.inv_cell_size.to_array(),
            _pad0: 0,
            dims: accel.dims.to_array(),
            shift: accel.shift,
            background: scene.background.to_array(),
            _pad2: 0,
            ambient: scene.ambient.to_array(),
            _pad3: 0,
        };
        let uniform = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("scene uniform"),
            size: std::mem::size_of::<SceneUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        ctx.queue.write_buffer(&uniform, 0, bytemuck::bytes_of(&consts));
        Ok(SceneBuffers {
            structure: accel.structure,
            cells,
            bvh_nodes,
            irr_entries,
            irr_voxels,
            irr_cells,
            refs,
            tris,
            tri_shade,
            materials,
            uniform,
            consts,
            bytes,
        })
    }
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
