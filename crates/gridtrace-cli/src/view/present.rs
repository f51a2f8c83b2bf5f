//! Puts the frame on the window: the traced image (drawn over the whole window by `blit.wgsl`,
//! nearest pixel, so a reduced resolution scale shows as blocks) and the egui overlay on top.
//!
//! When the tracer is on a GPU that can present to the window, the presenter draws with that
//! device (`GpuContext::instance`, `adapter`, `device`): the tracer leaves each frame in a
//! `DeviceImage` and the blit reads it there, so the frame never crosses to the host (before,
//! every band was read back, 4 bytes a pixel, and uploaded again to a second device). Frames the
//! host makes (the CPU tracer's, heat frames coloured by their whole frame's maximum, the coarse
//! preview) go through a texture, as they all did before; the blit takes the rows the refiner
//! names from it (`set_texture_rows`). A tracer on the CPU, or on an adapter that cannot present
//! to this window, leaves the presenter a device of its own.

use std::ops::Range;
use std::sync::Arc;

use gridtrace::gpu::{DeviceImage, GpuContext};

use super::blit::{BlitUniform, blit_bind_group, blit_pipeline};
use winit::event_loop::ActiveEventLoop;
use winit::window::Window;

/// What egui drew this pass, ready for the GPU.
pub struct Overlay {
    pub primitives: Vec<egui::ClippedPrimitive>,
    pub textures: egui::TexturesDelta,
    pub pixels_per_point: f32,
}

pub struct Presenter {
    surface: wgpu::Surface<'static>,
    pub device: wgpu::Device,
    queue: wgpu::Queue,
    config: wgpu::SurfaceConfiguration,
    /// The tracer's device, when this presenter draws with it (frames stay on the GPU).
    shared: Option<Arc<GpuContext>>,
    /// The traced image's texture format: sRGB when the surface is (the sampler decodes, the
    /// surface encodes again), plain unorm when it is not, so the bytes pass unchanged.
    image_format: wgpu::TextureFormat,
    /// The host's image (1x1 black until the first upload).
    image: ImageTexture,
    /// The tracer's frame on the shared device, sized to the traced image (`frame_target`).
    frame: Option<DeviceImage>,
    /// Bound in `frame`'s place while there is none.
    no_frame: wgpu::Buffer,
    /// The blit's `Blit` uniform (size, texture rows, surface encoding).
    blit_uniform: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// Rows drawn from the texture (the rest from `frame`).
    texture_rows: Range<u32>,
    blit: wgpu::RenderPipeline,
    blit_layout: wgpu::BindGroupLayout,
    nearest: wgpu::Sampler,
    egui: egui_wgpu::Renderer,
    max_side: u32,
    /// The surface is configured (the window has an area).
    live: bool,
    /// The adapter presenting and whose device it is, for the overlay.
    pub adapter: String,
    /// Why the tracer's device does not present, when it is on a GPU that cannot.
    pub note: Option<String>,
}

struct ImageTexture {
    texture: wgpu::Texture,
    size: (u32, u32),
}

fn err(what: &str, e: impl std::fmt::Display) -> gridtrace::Error {
    gridtrace::Error::Gpu(format!("presenting to the window: {what}: {e}"))
}

impl Presenter {
    /// The presenter of `window`: with the tracer's device `tracer` where its adapter can
    /// present to the window, else with a device of its own.
    pub fn new(
        el: &ActiveEventLoop,
        window: Arc<Window>,
        tracer: Option<&Arc<GpuContext>>,
    ) -> gridtrace::Result<Presenter> {
        let mut note = None;
        if let Some(ctx) = tracer {
            match ctx.instance.create_surface(window.clone()) {
                Ok(surface) if ctx.adapter.is_surface_supported(&surface) => {
                    let words = format!(
                        "{}, the tracer's device: frames stay on the GPU",
                        gridtrace::backend::adapter_words(&ctx.info)
                    );
                    return Presenter::with_device(
                        surface,
                        &ctx.adapter,
                        (ctx.device.clone(), ctx.queue.clone()),
                        Some(ctx.clone()),
                        window,
                        words,
                        None,
                    );
                }
                Ok(_) => {
                    note = Some(format!(
                        "the tracer's adapter ({}) cannot present to this window: frames go through the host",
                        ctx.info.name
                    ))
                }
                Err(e) => {
                    note = Some(format!(
                        "no window surface on the tracer's device ({e}): frames go through the host"
                    ))
                }
            }
        }
        let desc = wgpu::InstanceDescriptor::new_with_display_handle(Box::new(el.owned_display_handle())).with_env();
        let instance = wgpu::Instance::new(desc);
        let surface = instance.create_surface(window.clone()).map_err(|e| err("surface", e))?;
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            compatible_surface: Some(&surface),
            ..Default::default()
        }))
        .map_err(|e| err("no adapter can present to this window", e))?;
        let device = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
            .map_err(|e| err("device", e))?;
        let words = format!(
            "{}, a device of its own: frames uploaded from the host",
            gridtrace::backend::adapter_words(&adapter.get_info())
        );
        Presenter::with_device(surface, &adapter, device, None, window, words, note)
    }

    fn with_device(
        surface: wgpu::Surface<'static>,
        adapter: &wgpu::Adapter,
        (device, queue): (wgpu::Device, wgpu::Queue),
        shared: Option<Arc<GpuContext>>,
        window: Arc<Window>,
        adapter_words: String,
        note: Option<String>,
    ) -> gridtrace::Result<Presenter> {
        let caps = surface.get_capabilities(adapter);
        // egui prefers a gamma-space (non-sRGB) target; either works, and the image texture
        // follows the surface's encoding.
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| matches!(f, wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Rgba8Unorm))
            .or_else(|| {
                caps.formats.iter().copied().find(|f| {
                    matches!(
                        f,
                        wgpu::TextureFormat::Bgra8UnormSrgb | wgpu::TextureFormat::Rgba8UnormSrgb
                    )
                })
            })
            .ok_or_else(|| err("formats", format!("no 8-bit RGBA/BGRA format among {:?}", caps.formats)))?;
        let image_format = if format.is_srgb() {
            wgpu::TextureFormat::Rgba8UnormSrgb
        } else {
            wgpu::TextureFormat::Rgba8Unorm
        };
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
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
        let (blit, blit_layout) = blit_pipeline(&device, format);
        let image = ImageTexture {
            texture: texture_2d(
                &device,
                "traced image",
                (1, 1),
                image_format,
                wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            ),
            size: (1, 1),
        };
        let no_frame = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("no device frame"),
            size: 4,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let blit_uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("blit uniform"),
            size: std::mem::size_of::<BlitUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let nearest = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("nearest"),
            mag_filter: wgpu::FilterMode::Nearest,
            min_filter: wgpu::FilterMode::Nearest,
            ..Default::default()
        });
        let egui = egui_wgpu::Renderer::new(
            &device,
            format,
            egui_wgpu::RendererOptions {
                msaa_samples: 1,
                depth_stencil_format: None,
                dithering: false,
                predictable_texture_filtering: false,
            },
        );
        let bind_group = blit_bind_group(
            &device,
            &blit_layout,
            &image.texture,
            &nearest,
            &no_frame,
            &blit_uniform,
        );
        let mut p = Presenter {
            surface,
            device,
            queue,
            config,
            shared,
            image_format,
            image,
            frame: None,
            no_frame,
            blit_uniform,
            bind_group,
            texture_rows: 0..u32::MAX,
            blit,
            blit_layout,
            nearest,
            egui,
            max_side,
            live: false,
            adapter: adapter_words,
            note,
        };
        p.resize(size.width, size.height);
        Ok(p)
    }

    /// The device image a `w` x `h` frame is traced into (made anew when the size changes;
    /// black at first), when the presenter shares the tracer's device.
    pub fn frame_target(&mut self, (w, h): (u32, u32)) -> gridtrace::Result<Option<&DeviceImage>> {
        let Some(ctx) = &self.shared else {
            return Ok(None);
        };
        if self.frame.as_ref().is_none_or(|f| f.size() != (w, h)) {
            self.frame = Some(DeviceImage::new(ctx, w, h)?);
            self.rebind();
        }
        Ok(self.frame.as_ref())
    }

    /// The device image of the last frame traced into it.
    pub fn frame(&self) -> Option<&DeviceImage> {
        self.frame.as_ref()
    }

    /// The rows of the traced image (`size`) drawn from the host's texture; the others come
    /// from the device image when there is one of that size (else every row is the texture's:
    /// a frame too large for the device image).
    pub fn set_texture_rows(&mut self, rows: Range<u32>, size: (u32, u32)) {
        let device = self.frame.as_ref().is_some_and(|f| f.size() == size);
        self.texture_rows = if device { rows } else { 0..u32::MAX };
    }

    fn rebind(&mut self) {
        let frame = self.frame.as_ref().map_or(&self.no_frame, |f| f.buffer());
        self.bind_group = blit_bind_group(
            &self.device,
            &self.blit_layout,
            &self.image.texture,
            &self.nearest,
            frame,
            &self.blit_uniform,
        );
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

    /// Writes the traced image (RGBA8, `w` x `h`) into its texture.
    pub fn upload(&mut self, rgba: &[u8], (w, h): (u32, u32)) {
        if w == 0 || h == 0 {
            return;
        }
        if self.image.size != (w, h) {
            let texture = texture_2d(
                &self.device,
                "traced image",
                (w, h),
                self.image_format,
                wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            );
            self.image = ImageTexture { texture, size: (w, h) };
            self.rebind();
        }
        let t = &self.image;
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &t.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            rgba,
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
    }

    /// Draws the image and the overlay into the window; false when the surface took no frame
    /// (it changed under us and was configured again: ask for another pass). egui's texture
    /// changes (its font atlas among them) are applied even when there is nothing to draw on (a
    /// minimised window): egui sends each change once.
    pub fn present(&mut self, mut overlay: Overlay) -> gridtrace::Result<bool> {
        self.set_textures(&overlay);
        if !self.live {
            self.free_textures(&mut overlay);
            return Ok(true);
        }
        let tex = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                // The window changed under us: configure again, present next time.
                self.surface.configure(&self.device, &self.config);
                self.free_textures(&mut overlay);
                return Ok(false);
            }
            other => {
                eprintln!("note: frame skipped ({other:?})");
                self.free_textures(&mut overlay);
                return Ok(false);
            }
        };
        let view = tex.texture.create_view(&wgpu::TextureViewDescriptor::default());
        let size = [self.config.width, self.config.height];
        self.draw(&view, size, &overlay);
        self.queue.present(tex);
        self.free_textures(&mut overlay);
        Ok(true)
    }

    /// The window as it looks (image and overlay), drawn into a texture of its own and read
    /// back: RGBA8, `width` x `height` of the surface.
    pub fn capture(&mut self, mut overlay: Overlay) -> gridtrace::Result<image::RgbaImage> {
        self.set_textures(&overlay);
        let (w, h) = (self.config.width, self.config.height);
        let texture = texture_2d(
            &self.device,
            "window capture",
            (w, h),
            self.config.format,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        self.draw(&view, [w, h], &overlay);
        self.free_textures(&mut overlay);
        // Rows of a texture copy are padded to 256 bytes.
        let row = (4 * w).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("window capture"),
            size: row as u64 * h as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        enc.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(h),
                },
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
        self.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: Some(std::time::Duration::from_secs(30)),
            })
            .map_err(|e| err("reading the capture back", e))?;
        match rx.recv_timeout(std::time::Duration::from_secs(5)) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(err("mapping the capture", e)),
            Err(_) => return Err(err("mapping the capture", "did not complete")),
        }
        let data = buffer.get_mapped_range(..).map_err(|e| err("reading the capture", e))?;
        let bgra = matches!(
            self.config.format,
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        );
        let mut px = Vec::with_capacity((w * h * 4) as usize);
        for y in 0..h {
            let r = &data[(y * row) as usize..][..(4 * w) as usize];
            for c in r.chunks_exact(4) {
                px.extend_from_slice(&if bgra {
                    [c[2], c[1], c[0], 255]
                } else {
                    [c[0], c[1], c[2], 255]
                });
            }
        }
        drop(data);
        image::RgbaImage::from_raw(w, h, px).ok_or_else(|| err("capture", "size mismatch"))
    }

    fn draw(&mut self, target: &wgpu::TextureView, size: [u32; 2], overlay: &Overlay) {
        // Rows are counted in the device image's pixels when there is one; the texture is
        // sampled by position, whatever its size.
        let (frame_size, texture_rows) = match &self.frame {
            Some(f) => (f.size(), [self.texture_rows.start, self.texture_rows.end]),
            None => (self.image.size, [0, u32::MAX]),
        };
        let uniform = BlitUniform {
            size: [frame_size.0, frame_size.1],
            texture_rows,
            srgb_target: self.image_format.is_srgb() as u32,
            _pad: 0,
        };
        self.queue
            .write_buffer(&self.blit_uniform, 0, bytemuck::bytes_of(&uniform));
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: size,
            pixels_per_point: overlay.pixels_per_point,
        };
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("present") });
        let extra = self
            .egui
            .update_buffers(&self.device, &self.queue, &mut enc, &overlay.primitives, &screen);
        {
            let mut pass = enc
                .begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("image + overlay"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: target,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                            store: wgpu::StoreOp::Store,
                        },
                        depth_slice: None,
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                })
                .forget_lifetime();
            pass.set_pipeline(&self.blit);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.draw(0..3, 0..1);
            self.egui.render(&mut pass, &overlay.primitives, &screen);
        }
        self.queue.submit(extra.into_iter().chain([enc.finish()]));
    }

    /// Applies egui's new and changed textures (before painting).
    fn set_textures(&mut self, overlay: &Overlay) {
        for (id, deltas) in &overlay.textures.set {
            for delta in deltas {
                self.egui.update_texture(&self.device, &self.queue, *id, delta);
            }
        }
    }

    /// Frees the textures egui is done with (after painting) and marks the changes handled.
    fn free_textures(&mut self, overlay: &mut Overlay) {
        for id in &overlay.textures.free {
            self.egui.free_texture(id);
        }
        overlay.textures.clear();
    }
}

fn texture_2d(
    device: &wgpu::Device,
    label: &str,
    (width, height): (u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}
