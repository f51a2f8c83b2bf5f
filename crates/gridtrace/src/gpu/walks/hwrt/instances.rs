//! `hwrt` over a `QueryScene`'s instances (two levels, `walks::two_level`): the driver's own
//! instances. One BLAS a mesh, built once from the mesh's own-space triangles (`BlasInput`,
//! three vertices a triangle in the tracer's order: the primitive index is the mesh's own
//! triangle, the barycentrics `intersect_tri`'s u and v), and one TLAS with an instance a scene
//! instance: its world-from-mesh 3x4 transform, its driver mask (`masks.rs`) and its index as
//! custom data (what the shader reads the instance table by). The driver carries the ray into
//! the mesh's space without normalising its direction, so `t` is world `t`, as the software
//! top level's.
//!
//! Beside the TLAS the walk reads one array of its own, the instance table (bound as the two
//! levels' "top level" array, `TopLevel::recs`' bytes, words): the mask class table
//! (`DRIVER_CLASSES` words), whether the masks are exact (word `DRIVER_EXACT_WORD`), then from
//! word `DRIVER_FIRST_RECORD` each instance's 32-bit mask and its first triangle's number in the
//! answers (each instance's triangles numbered after the previous instance's, in the instances'
//! order: the host names instance and face from it, `TopLevel::name`).
//!
//! A move (`set_transforms`, `set_mask`) rebuilds the TLAS alone, over the same BLASes, and
//! writes the table only where it changed (a mask, an instance added): the TLAS's build uploads
//! the driver's instance records, 64 bytes each (`TLAS_INSTANCE_BYTES`). The TLAS is rebuilt,
//! not updated: its build is over the instances only, and keeps the tree as good as the first.

use bytemuck::Zeroable;
use glam::Affine3A;

use super::build::{BlasInput, submit_checked};
use super::masks::{CLASSES, hardware_masks};
use crate::accel::{AccelKind, TriAccel};
use crate::gpu::context::GpuContext;
use crate::gpu::layout::GpuTri;
use crate::gpu::walks::two_level::records::{BottomLevels, Instance, TopLevel, TopRec, number_answers};
use crate::gpu::walks::{DeviceStructure, WalkSpec};
use crate::{Error, Result};

/// Where the instance table's "exact" word sits (after the class table).
pub const DRIVER_EXACT_WORD: u32 = CLASSES as u32;
/// Where the instances' records (mask, first answer) start in the table.
pub const DRIVER_FIRST_RECORD: u32 = 16;
/// What the TLAS build uploads an instance (wgpu-hal's Vulkan instance record:
/// `VkAccelerationStructureInstanceKHR`, a 3x4 transform, custom index and mask, binding-table
/// offset and flags, the BLAS's address).
pub const TLAS_INSTANCE_BYTES: u64 = 64;

/// One TLAS instance: its transform, its mesh and its driver mask.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Mesh to world.
    pub to_world: Affine3A,
    pub mesh: u32,
    pub mask: u8,
}

/// The meshes' side of the two levels for `hwrt`: no arrays of ours (the driver builds the
/// BLASes from the meshes' triangles, `DriverInstances::build`), each mesh's header its index.
pub fn bottom_levels(spec: &'static WalkSpec, kind: AccelKind, tri_counts: Vec<u32>) -> BottomLevels {
    BottomLevels {
        spec,
        kind,
        arrays: Vec::new(),
        tris: vec![GpuTri::zeroed()],
        headers: (0..tri_counts.len() as u32).map(|k| [k, 0]).collect(),
        tri_counts,
    }
}

/// The instance table of `instances` (as `TopLevel`: no nodes, one record an instance in the
/// instances' order) and the TLAS's instances.
pub fn instance_table(instances: &[Instance], bottoms: &BottomLevels) -> Result<(TopLevel, Vec<Placement>)> {
    let masks: Vec<u32> = instances.iter().map(|i| i.mask).collect();
    let hw = hardware_masks(&masks);
    let mut words = vec![0u32; DRIVER_FIRST_RECORD as usize];
    words[..CLASSES].copy_from_slice(&hw.classes);
    words[DRIVER_EXACT_WORD as usize] = hw.exact as u32;
    let (first_answer, answers) = number_answers(instances.iter().map(|i| i.mesh), bottoms)?;
    let mut placements = Vec::with_capacity(instances.len());
    for ((inst, &first), &mask) in instances.iter().zip(&first_answer).zip(&hw.instance) {
        words.extend([inst.mask, first]);
        placements.push(Placement {
            // The transform's inverse of the kept inverse: within rounding of the geometry's
            // own (the software walks carry rays by the kept inverse itself).
            to_world: inst.to_local.inverse(),
            mesh: inst.mesh,
            mask,
        });
    }
    let per_rec = size_of::<TopRec>() / 4;
    words.resize(words.len().div_ceil(per_rec) * per_rec, 0);
    let top = TopLevel {
        recs: bytemuck::cast_slice(&words).to_vec(),
        nodes: 0,
        order: (0..instances.len() as u32).collect(),
        first_answer,
        answers,
    };
    Ok((top, placements))
}

/// The meshes' BLASes on the device and what their TLAS has cost.
pub struct DriverInstances {
    /// Each mesh's BLAS (`None`: a mesh without triangles, whose instances are left out).
    blases: Vec<Option<wgpu::Blas>>,
    /// Instances the TLAS holds at most (a new one is made for more or fewer).
    capacity: u32,
    /// Bytes of the meshes' vertex buffers, uploaded once.
    pub input_bytes: u64,
    /// BLASes built (one a mesh, at the upload; a move builds none).
    pub blas_builds: u32,
}

impl DriverInstances {
    /// Builds each mesh's BLAS from its own-space triangles (`meshes`) and the TLAS of
    /// `placements`, in one submission; the TLAS to bind.
    pub fn build(
        ctx: &GpuContext,
        meshes: &[&[TriAccel]],
        placements: &[Placement],
    ) -> Result<(DriverInstances, DeviceStructure)> {
        ctx.check_ray_queries("hwrt")?;
        let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let inputs: Vec<Option<BlasInput>> = meshes
            .iter()
            .map(|tris| (!tris.is_empty()).then(|| BlasInput::new(ctx, tris)).transpose())
            .collect::<Result<_>>()?;
        let mut d = DriverInstances {
            blases: inputs.iter().map(|i| i.as_ref().map(|i| i.blas.clone())).collect(),
            capacity: 0,
            input_bytes: inputs.iter().flatten().map(|i| i.bytes).sum(),
            blas_builds: inputs.iter().flatten().count() as u32,
        };
        let mut tlas = None;
        let mut enc = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("hwrt instances build"),
        });
        d.fill(ctx, &mut tlas, placements)?;
        let tlas = tlas.expect("fill makes the TLAS");
        let entries: Vec<wgpu::BlasBuildEntry<'_>> = inputs.iter().flatten().map(BlasInput::entry).collect();
        enc.build_acceleration_structures(entries.iter(), std::iter::once(&tlas));
        submit_checked(ctx, scope, enc)?;
        let input_bytes = d.input_bytes;
        Ok((d, DeviceStructure { tlas, input_bytes }))
    }

    /// Rebuilds the TLAS `tlas` over `placements` (the BLASes stay; a new TLAS where the
    /// instances' count changed). Returns the bytes the build uploaded.
    pub fn set_instances(
        &mut self,
        ctx: &GpuContext,
        tlas: &mut Option<wgpu::Tlas>,
        placements: &[Placement],
    ) -> Result<u64> {
        let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let placed = self.fill(ctx, tlas, placements)?;
        let mut enc = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("hwrt instances move"),
        });
        let t = tlas.as_ref().expect("fill makes the TLAS");
        enc.build_acceleration_structures(std::iter::empty(), std::iter::once(t));
        submit_checked(ctx, scope, enc)?;
        Ok(placed * TLAS_INSTANCE_BYTES)
    }

    /// Writes `placements` into `tlas` (made anew where it is missing or of another
    /// capacity), each instance's custom data its index; returns how many were placed.
    fn fill(&mut self, ctx: &GpuContext, tlas: &mut Option<wgpu::Tlas>, placements: &[Placement]) -> Result<u64> {
        let n = placements.len();
        let limits = ctx.limits();
        // Custom data holds 24 bits (the instance's index).
        let most = (limits.max_tlas_instance_count as usize).min(1 << 24);
        if n > most {
            return Err(Error::Gpu(format!(
                "'hwrt' needs a top-level structure of {n} instances; adapter '{}' allows {most} \
                 (limit max_tlas_instance_count, and 2^24 instance indices)",
                ctx.info.name
            )));
        }
        if tlas.is_none() || self.capacity as usize != n.max(1) {
            self.capacity = n.max(1) as u32;
            *tlas = Some(ctx.device.create_tlas(&wgpu::CreateTlasDescriptor {
                label: Some("hwrt driver instances"),
                max_instances: self.capacity,
                flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
                update_mode: wgpu::AccelerationStructureUpdateMode::Build,
            }));
        }
        let t = tlas.as_mut().expect("made above");
        let mut placed = 0;
        for (k, p) in placements.iter().enumerate() {
            t[k] = self.blases[p.mesh as usize].as_ref().map(|blas| {
                placed += 1;
                wgpu::TlasInstance::new(blas, rows_3x4(&p.to_world), k as u32, p.mask)
            });
        }
        Ok(placed)
    }
}

/// An affine transform as the TLAS takes it: 3 rows of 4, row-major (the 3x3 part's rows, each
/// followed by the translation's entry).
fn rows_3x4(m: &Affine3A) -> [f32; 12] {
    let (x, y, z, t) = (m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis, m.translation);
    [x.x, y.x, z.x, t.x, x.y, y.y, z.y, t.y, x.z, y.z, z.z, t.z]
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Quat, Vec3};

    /// The rows place a point as the transform does.
    #[test]
    fn rows_place_points_as_the_transform() {
        let m = Affine3A::from_mat4(Mat4::from_scale_rotation_translation(
            Vec3::new(1.0, -2.0, 0.5),
            Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7),
            Vec3::new(3.0, -1.0, 2.0),
        ));
        let r = rows_3x4(&m);
        let p = Vec3::new(0.3, -0.8, 1.7);
        let by_rows = Vec3::new(
            r[0] * p.x + r[1] * p.y + r[2] * p.z + r[3],
            r[4] * p.x + r[5] * p.y + r[6] * p.z + r[7],
            r[8] * p.x + r[9] * p.y + r[10] * p.z + r[11],
        );
        assert!(by_rows.abs_diff_eq(m.transform_point3(p), 1e-6));
    }

    /// The table: classes, the exact word, then (mask, first) an instance numbered in order.
    #[test]
    fn the_table_numbers_instances_in_order() {
        let spec = &super::super::INSTANCES;
        let bottoms = bottom_levels(spec, AccelKind::Hwrt, vec![10, 3]);
        let inst = |mesh, mask| Instance {
            to_local: Affine3A::from_translation(Vec3::X),
            mask,
            mesh,
        };
        let (top, placed) = instance_table(&[inst(1, 4), inst(0, u32::MAX), inst(1, 4)], &bottoms).unwrap();
        let words: &[u32] = bytemuck::cast_slice(&top.recs);
        let r = DRIVER_FIRST_RECORD as usize;
        assert_eq!(&words[r..r + 6], &[4, 0, u32::MAX, 3, 4, 13]);
        assert_eq!(words[DRIVER_EXACT_WORD as usize], 1);
        assert_eq!((top.answers, top.first_answer.clone()), (16, vec![0, 3, 13]));
        assert_eq!(top.name(12), (1, 9));
        assert_eq!(top.name(13), (2, 0));
        assert_eq!(placed[0].mask, placed[2].mask);
        assert!(placed[0].to_world.translation.abs_diff_eq((-Vec3::X).into(), 1e-7));
    }
}
