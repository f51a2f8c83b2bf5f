//! The device's acceleration structures for `hwrt`, built at upload: one bottom-level
//! structure (BLAS) over every triangle, opaque, and one top-level structure (TLAS) with one
//! instance of it, untransformed.
//!
//! The BLAS is built from a vertex buffer of three vertices per triangle in the tracer's
//! triangle order (`v0`, `v0 + e1`, `v0 + e2` of each `TriAccel`), without an index buffer, so
//! that the ray query's primitive index is the triangle index every other walk reports (`tri`)
//! and its barycentrics are the weights of `v1` and `v2`, the `u` and `v` of `intersect_tri`.
//! (`v0 + e1` may differ from the file's `v1` in the last bit: the driver intersects the
//! triangle the tracer stores.) A moved mesh is uploaded again and its structures rebuilt, not
//! updated: a rebuild keeps the driver's tree as good as the first one however far the
//! triangles move, and costs one build on the device (the BVH's refit is also re-uploaded).

use wgpu::util::DeviceExt;

use crate::accel::TriAccel;
use crate::gpu::context::GpuContext;
use crate::gpu::walks::DeviceStructure;
use crate::{Error, Result};

/// The identity as a 3x4 row-major affine transform (the instance's).
const IDENTITY_3X4: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// Builds the BLAS and the TLAS over `tris` on `ctx`'s device (one submission, not waited for:
/// the kernels that bind the TLAS run after it in queue order). An adapter without ray queries,
/// or a mesh over its limits, is an error that names the adapter and the limit.
pub fn build_on_device(ctx: &GpuContext, tris: &[TriAccel]) -> Result<DeviceStructure> {
    ctx.check_ray_queries("hwrt")?;
    let dev = &ctx.device;
    let scope = dev.push_error_scope(wgpu::ErrorFilter::Validation);
    let input = BlasInput::new(ctx, tris)?;
    let mut tlas = dev.create_tlas(&wgpu::CreateTlasDescriptor {
        label: Some("hwrt instances"),
        max_instances: 1,
        flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
        update_mode: wgpu::AccelerationStructureUpdateMode::Build,
    });
    // Custom data 0 and mask 0xff: the walk's ray queries ask for every instance.
    tlas[0] = Some(wgpu::TlasInstance::new(&input.blas, IDENTITY_3X4, 0, 0xff));
    let mut enc = dev.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("hwrt build"),
    });
    enc.build_acceleration_structures(std::iter::once(&input.entry()), std::iter::once(&tlas));
    submit_checked(ctx, scope, enc)?;
    Ok(DeviceStructure {
        tlas,
        input_bytes: input.bytes,
    })
}

/// One mesh's BLAS before its build: the structure, its size and the vertex buffer it is built
/// from (three vertices a triangle in the tracer's order, no index buffer).
pub(super) struct BlasInput {
    pub blas: wgpu::Blas,
    size: wgpu::BlasTriangleGeometrySizeDescriptor,
    vertices: wgpu::Buffer,
    /// Bytes of the vertex buffer.
    pub bytes: u64,
}

impl BlasInput {
    /// The BLAS of `tris` (at least one), checked against the adapter's limits.
    pub fn new(ctx: &GpuContext, tris: &[TriAccel]) -> Result<BlasInput> {
        let limits = ctx.limits();
        let n = tris.len() as u64;
        if n > limits.max_blas_primitive_count as u64 {
            return Err(Error::Gpu(format!(
                "'hwrt' needs a bottom-level structure of {n} triangles; adapter '{}' allows {} \
                 (limit max_blas_primitive_count)",
                ctx.info.name, limits.max_blas_primitive_count
            )));
        }
        let vertices: Vec<[f32; 3]> = tris.iter().flat_map(|t| [t.v0, t.v1, t.v2]).collect();
        let bytes = std::mem::size_of_val(vertices.as_slice()) as u64;
        if bytes > limits.max_buffer_size {
            return Err(Error::Gpu(format!(
                "'hwrt' needs {bytes} bytes of vertices; adapter '{}' allows {} per buffer (limit max_buffer_size)",
                ctx.info.name, limits.max_buffer_size
            )));
        }
        let dev = &ctx.device;
        let vertices = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("hwrt vertices"),
            contents: bytemuck::cast_slice(&vertices),
            usage: wgpu::BufferUsages::BLAS_INPUT,
        });
        let size = wgpu::BlasTriangleGeometrySizeDescriptor {
            vertex_format: wgpu::VertexFormat::Float32x3,
            vertex_count: 3 * tris.len() as u32,
            index_format: None,
            index_count: None,
            // Opaque: the hardware commits every hit itself; no shader sees candidates (unless
            // a ray forces it non-opaque: the driver's instances under folded masks).
            flags: wgpu::AccelerationStructureGeometryFlags::OPAQUE,
        };
        let blas = dev.create_blas(
            &wgpu::CreateBlasDescriptor {
                label: Some("hwrt triangles"),
                flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
                update_mode: wgpu::AccelerationStructureUpdateMode::Build,
            },
            wgpu::BlasGeometrySizeDescriptors::Triangles {
                descriptors: vec![size.clone()],
            },
        );
        Ok(BlasInput {
            blas,
            size,
            vertices,
            bytes,
        })
    }

    /// The build entry of `build_acceleration_structures`.
    pub fn entry(&self) -> wgpu::BlasBuildEntry<'_> {
        wgpu::BlasBuildEntry {
            blas: &self.blas,
            geometry: wgpu::BlasGeometries::TriangleGeometries(vec![wgpu::BlasTriangleGeometry {
                size: &self.size,
                vertex_buffer: &self.vertices,
                first_vertex: 0,
                vertex_stride: std::mem::size_of::<[f32; 3]>() as u64,
                index_buffer: None,
                first_index: None,
                transform_buffer: None,
                transform_buffer_offset: None,
            }]),
        }
    }
}

/// Submits the build in `enc` and reports a validation error of the scope as the build's.
pub(super) fn submit_checked(ctx: &GpuContext, scope: wgpu::ErrorScopeGuard, enc: wgpu::CommandEncoder) -> Result<()> {
    ctx.queue.submit([enc.finish()]);
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(Error::Gpu(format!(
            "building 'hwrt''s acceleration structures on '{}' failed: {e}",
            ctx.info.name
        )));
    }
    ctx.check_errors()
}
