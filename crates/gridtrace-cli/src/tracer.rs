//! A prepared scene owned together with where it is traced (its GPU upload, or the CPU): what a
//! program that keeps a scene for many frames holds (the viewer, `render --animate`). It owns
//! the scene, so it can be dropped and replaced (a file dropped on the viewer) and moved
//! (`update_vertices`), which `gridtrace::Renderer`, borrowing its scene, cannot.

use std::sync::Arc;

use gridtrace::gpu::{GpuContext, GpuRenderer};
use gridtrace::scene::{Camera, PointLight, PreparedScene, RebuildOn};
use gridtrace::{Backend, Frame, RenderOptions};

/// An adapter in a few words: "NAME (BACKEND)", with ", software" for a software rasteriser.
pub fn adapter_words(info: &wgpu::AdapterInfo) -> String {
    format!(
        "{} ({:?}{})",
        info.name,
        info.backend,
        if info.device_type == wgpu::DeviceType::Cpu {
            ", software"
        } else {
            ""
        }
    )
}

pub struct Tracer {
    pub scene: PreparedScene,
    gpu: Option<GpuRenderer>,
}

/// What moving the vertices cost, and how the structure followed.
#[derive(Debug, Clone)]
pub struct Update {
    /// Triangles, normals and bounds of the moved mesh (host).
    pub geometry_ms: f64,
    /// The structure's update: a CPU rebuild or refit, or the GPU build plus uploads.
    pub build_ms: f64,
    /// How the structure was updated, in words.
    pub how: String,
}

impl Tracer {
    /// The scene traced on `ctx` (a device `backend` opened; `None`: the CPU). With `auto` a
    /// scene the device cannot hold goes to the CPU, with a note (`Backend::upload`).
    pub fn open(
        scene: PreparedScene,
        ctx: Option<&Arc<GpuContext>>,
        backend: Backend,
        notes: &mut Vec<String>,
    ) -> gridtrace::Result<Tracer> {
        let gpu = match ctx {
            Some(ctx) => backend.upload(ctx.clone(), &scene, notes)?,
            None => None,
        };
        Ok(Tracer { scene, gpu })
    }

    pub fn gpu(&self) -> Option<&GpuRenderer> {
        self.gpu.as_ref()
    }

    /// "cpu (N threads)" or the GPU adapter's description.
    pub fn describe(&self) -> String {
        gridtrace::backend::describe_tracer(self.gpu.as_ref())
    }

    /// The same in a few words: "gpu: NAME (BACKEND)", "software" for a software adapter.
    pub fn short(&self) -> String {
        match &self.gpu {
            Some(g) => format!("gpu: {}", adapter_words(&g.context().info)),
            None => self.describe(),
        }
    }

    /// One frame (or band of rows, `opts.rows`) from `camera` with `lights`.
    pub fn render(&mut self, camera: &Camera, lights: &[PointLight], opts: &RenderOptions) -> gridtrace::Result<Frame> {
        match &mut self.gpu {
            Some(g) => {
                let (image, s) = g.render(camera, lights, opts)?;
                Ok(Frame {
                    image,
                    stats: s.render,
                    gpu: Some(s),
                })
            }
            None => {
                let (image, stats) = gridtrace::cpu::render_view(&self.scene, camera, lights, opts, None)?;
                Ok(Frame {
                    image,
                    stats,
                    gpu: None,
                })
            }
        }
    }

    /// Moves the mesh's vertices and updates the structure where the scene is traced: the
    /// grids rebuilt on the GPU when there is one (else on the CPU), the BVH refitted. A wrong
    /// length or a NaN is an error that leaves the mesh as it was.
    pub fn update_vertices(&mut self, positions: &[glam::Vec3]) -> gridtrace::Result<Update> {
        let on = if self.gpu.is_some() {
            RebuildOn::Device
        } else {
            RebuildOn::Cpu
        };
        let up = self.scene.update_vertices(positions, on)?;
        let mut build_ms = up.structure_ms;
        let mut how = up.how.to_string();
        if let Some(g) = &mut self.gpu {
            let u = g.update_vertices(&self.scene)?;
            build_ms += u.structure_upload_ms + u.upload_ms;
            if let Some(b) = &u.build {
                build_ms += b.timings.total_ms;
                how = match &b.cpu_fallback {
                    Some(why) => format!("rebuilt on the CPU ({why})"),
                    None => format!(
                        "rebuilt on the GPU ({})",
                        if b.timings.from_timestamps {
                            "timestamps"
                        } else {
                            "wall clock"
                        }
                    ),
                };
            }
        }
        Ok(Update {
            geometry_ms: up.geometry_ms,
            build_ms,
            how,
        })
    }
}
