//! Puts a traced image on the window: a presentation device of its own (any tracer, CPU or GPU,
//! presents alike) and a surface the image is written into.

use std::sync::Arc;

use winit::event_loop::ActiveEventLoop;
use winit::window::Window;

pub struct Presenter {
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    config: wgpu::SurfaceConfiguration,
    /// The surface is BGRA (else RGBA): the bytes are swizzled to match.
    bgra: bool,
    max_side: u32,
    /// The surface is configured (the window has an area).
    live: bool,
}

fn err(what: &str, e: impl std::fmt::Display) -> gridtrace::Error {
    gridtrace::Error::Gpu(format!("presenting to the window: {what}: {e}"))
}

impl Presenter {
    pub fn new(el: &ActiveEventLoop, window: Arc<Window>) -> gridtrace::Result<Presenter> {
        let desc = wgpu::InstanceDescriptor::new_with_display_handle(Box::new(el.owned_display_handle())).with_env();
        let instance = wgpu::Instance::new(desc);
        let surface = instance.create_surface(window.clone()).map_err(|e| err("surface", e))?;
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            compatible_surface: Some(&surface),
            ..Default::default()
        }))
        .map_err(|e| err("no adapter can present to this window", e))?;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
            .map_err(|e| err("device", e))?;
        let caps = surface.get_capabilities(&adapter);
        // The image's bytes are 8-bit sRGB-encoded: written as they are into an 8-bit format
        // they show as traced (a copy converts nothing).
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| {
                matches!(
                    f,
                    wgpu::TextureFormat::Bgra8UnormSrgb
                        | wgpu::TextureFormat::Bgra8Unorm
                        | wgpu::TextureFormat::Rgba8UnormSrgb
                        | wgpu::TextureFormat::Rgba8Unorm
                )
            })
            .ok_or_else(|| err("formats", format!("no 8-bit RGBA/BGRA format among {:?}", caps.formats)))?;
        if !caps.usages.contains(wgpu::TextureUsages::COPY_DST) {
            return Err(err("usages", "the surface cannot be written to (no COPY_DST)"));
        }
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::COPY_DST,
            format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes[0],
            view_formats: vec![],
        };
        let max_side = device.limits().max_texture_dimension_2d;
        let mut p = Presenter {
            surface,
            device,
            queue,
            config,
            bgra: matches!(
                format,
                wgpu::TextureFormat::Bgra8UnormSrgb | wgpu::TextureFormat::Bgra8Unorm
            ),
            max_side,
            live: false,
        };
        p.resize(size.width, size.height);
        Ok(p)
    }

    /// The largest surface side the device allows.
    pub fn max_side(&self) -> u32 {
        self.max_side
    }

    pub fn resize(&mut self, w: u32, h: u32) {
        self.live = w > 0 && h > 0;
        if self.live {
            self.config.width = w.min(self.max_side);
            self.config.height = h.min(self.max_side);
            self.surface.configure(&self.device, &self.config);
        }
    }

    /// Shows `image` (its top-left part where the surface is smaller; the surface is cleared
    /// nowhere else, so a smaller image leaves the rest as it was).
    pub fn present(&mut self, image: &gridtrace::Image) -> gridtrace::Result<()> {
        if !self.live {
            return Ok(());
        }
        let tex = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                // The window changed under us: configure again, present next time.
                self.surface.configure(&self.device, &self.config);
                return Ok(());
            }
            other => {
                eprintln!("note: frame skipped ({other:?})");
                return Ok(());
            }
        };
        let w = image.width.min(self.config.width);
        let h = image.height.min(self.config.height);
        let rgb = image.to_rgb8();
        let mut px = Vec::with_capacity((w * h * 4) as usize);
        for y in 0..h {
            for x in 0..w {
                let i = ((y * image.width + x) * 3) as usize;
                let (r, g, b) = (rgb[i], rgb[i + 1], rgb[i + 2]);
                px.extend_from_slice(&if self.bgra { [b, g, r, 255] } else { [r, g, b, 255] });
            }
        }
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &tex.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &px,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * w),
                rows_per_image: Some(h),
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
        self.queue.submit([]);
        self.queue.present(tex);
        Ok(())
    }
}
