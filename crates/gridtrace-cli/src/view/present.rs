//! Puts the frame on the window: the traced image (a texture, drawn over the whole window by
//! `blit.wgsl`, so a reduced resolution scale shows as blocks) and the egui overlay on top. A
//! presentation device of its own, so the CPU and GPU tracers present alike; the traced image
//! reaches it through host memory (the tracer reads its bands back anyway, to refine
//! progressively and to take screenshots).

use std::sync::Arc;

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
    /// The traced image's texture format: sRGB when the surface is (the sampler decodes, the
    /// surface encodes again), plain unorm when it is not, so the bytes pass unchanged.
    image_format: wgpu::TextureFormat,
    image: Option<ImageTexture>,
    blit: wgpu::RenderPipeline,
    blit_layout: wgpu::BindGroupLayout,
    nearest: wgpu::Sampler,
    egui: egui_wgpu::Renderer,
    max_side: u32,
    /// The surface is configured (the window has an area).
    live: bool,
    /// The adapter presenting, for the overlay.
    pub adapter: String,
}

struct ImageTexture {
    texture: wgpu::Texture,
    bind_group: wgpu::BindGroup,
    size: (u32, u32),
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
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
            .map_err(|e| err("device", e))?;
        let caps = surface.get_capabilities(&adapter);
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
        let mut p = Presenter {
            surface,
            device,
            queue,
            config,
            image_format,
            image: None,
            blit,
            blit_layout,
            nearest,
            egui,
            max_side,
            live: false,
            adapter: gridtrace::backend::adapter_words(&info),
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

    /// Writes the traced image (RGBA8, `w` x `h`) into its texture.
    pub fn upload(&mut self, rgba: &[u8], (w, h): (u32, u32)) {
        if w == 0 || h == 0 {
            return;
        }
        if self.image.as_ref().is_none_or(|t| t.size != (w, h)) {
            let texture = texture_2d(
                &self.device,
                "traced image",
                (w, h),
                self.image_format,
                wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            );
            let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
            let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("traced image"),
                layout: &self.blit_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(&view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::Sampler(&self.nearest),
                    },
                ],
            });
            self.image = Some(ImageTexture {
                texture,
                bind_group,
                size: (w, h),
            });
        }
        let t = self.image.as_ref().expect("created above");
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
            if let Some(t) = &self.image {
                pass.set_pipeline(&self.blit);
                pass.set_bind_group(0, &t.bind_group, &[]);
                pass.draw(0..3, 0..1);
            }
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

/// The pipeline that draws the traced image over the whole target (`blit.wgsl`).
fn blit_pipeline(device: &wgpu::Device, format: wgpu::TextureFormat) -> (wgpu::RenderPipeline, wgpu::BindGroupLayout) {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("blit"),
        source: wgpu::ShaderSource::Wgsl(include_str!("blit.wgsl").into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("blit"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("blit"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("blit"),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            buffers: &[],
            compilation_options: wgpu::PipelineCompilationOptions::default(),
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_main"),
            targets: &[Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
            compilation_options: wgpu::PipelineCompilationOptions::default(),
        }),
        multiview_mask: None,
        cache: None,
    });
    (pipeline, layout)
}
