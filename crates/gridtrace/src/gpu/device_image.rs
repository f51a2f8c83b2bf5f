//! A frame's pixels kept on the device (`GpuRenderer::render_to_device`): the viewer draws its
//! window from them with the tracer's own device, so a frame never crosses to the host and back
//! (before, each band was read back, 4 bytes a pixel, and uploaded again to a second device).
//! Only the frame's counters and timestamps are read back.
//!
//! Layout: one `u32` a pixel, rows top to bottom, `width` pixels a row; each word is the pack
//! kernel's 8-bit sRGB (red in the low byte, `pack.wgsl`), so a fragment shader reads a pixel
//! with `unpack4x8unorm`.

use std::sync::Arc;

use super::context::{GpuContext, max_binding_bytes};
use super::work::PACKED_TEXEL_BYTES;
use crate::render::Image;
use crate::{Error, Result};

pub struct DeviceImage {
    ctx: Arc<GpuContext>,
    buffer: wgpu::Buffer,
    width: u32,
    height: u32,
}

impl DeviceImage {
    /// A `width` x `height` image on `ctx`'s device, black. An image larger than one storage
    /// binding may be is an error that says so.
    pub fn new(ctx: &Arc<GpuContext>, width: u32, height: u32) -> Result<DeviceImage> {
        let bytes = width as u64 * height as u64 * PACKED_TEXEL_BYTES;
        let max = max_binding_bytes(&ctx.limits());
        if bytes > max {
            return Err(Error::Gpu(format!(
                "a {width}x{height} image on the device takes {bytes} bytes; '{}' binds {max} at most",
                ctx.info.name
            )));
        }
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("device image"),
            // Zero-length bindings are invalid.
            size: bytes.max(PACKED_TEXEL_BYTES),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        ctx.check_errors()?;
        Ok(DeviceImage {
            ctx: ctx.clone(),
            buffer,
            width,
            height,
        })
    }

    /// The pixels (the layout in the module docs), for a shader to read.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The device it lives on.
    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// The image brought to the host (a screenshot): equal to what `GpuRenderer::render` returns
    /// for the same frame with `PixelFormat::Srgb8`.
    pub fn read(&self) -> Result<Image> {
        let bytes = self.width as u64 * self.height as u64 * PACKED_TEXEL_BYTES;
        let raw = self.ctx.read_buffer(&self.buffer, bytes)?;
        Ok(Image::from_srgb8(
            self.width,
            self.height,
            bytemuck::cast_slice(&raw).to_vec(),
        ))
    }
}
