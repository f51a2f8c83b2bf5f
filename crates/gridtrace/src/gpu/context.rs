//! Adapter and device: chosen once, described on every run (so a software adapter can never
//! pass for a GPU), with errors captured instead of panicking and waits that cannot hang.

use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::util::Instant;

use super::bindings::storage_buffers_needed;
use super::host_phases::HostPhases;
use crate::{Error, Result};

/// How long a submission may run before it is reported as a hang.
pub const GPU_TIMEOUT: Duration = Duration::from_secs(120);

/// A device fault a test can inject (`GpuContext::inject_fault`).
#[doc(hidden)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// The device is gone for good (a driver reset, a removed card, a watchdog).
    DeviceLost,
    /// One allocation failed (reported once, as wgpu reports an uncaptured error).
    OutOfMemory,
}

pub struct GpuContext {
    /// The instance the adapter came from: a window's surface is made from it, so that the
    /// viewer can present from this device (`Presenter`), which it can only when the instance
    /// knows the window's display (`GpuContext::new_with`).
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    /// Timestamp queries are available (per-stage GPU times).
    pub timestamps: bool,
    /// Subgroup operations are available (the `appends=subgroup` variant).
    pub subgroups: bool,
    /// Ray queries are available (`Features::EXPERIMENTAL_RAY_QUERY`, Vulkan's VK_KHR_ray_query
    /// and VK_KHR_acceleration_structure): the `hwrt` structure.
    pub ray_query: bool,
    /// First uncaptured device error, if any (validation, out of memory, lost device).
    errors: Arc<Mutex<Option<String>>>,
    /// Why the device was lost, once it was: every later wait is an error (a lost device
    /// stays lost; its work never completes).
    lost: Arc<Mutex<Option<String>>>,
    /// What is compiled once per device and shared (the tracer's kernels, the grid build's),
    /// by type: built by the first user (`cached`), so that this file names none of them.
    cache: Mutex<HashMap<TypeId, Arc<dyn Any + Send + Sync>>>,
    /// Hits one list pass may hold on this device, lowered by a test (`lower_list_hits`; 0:
    /// what the bindings hold): the scenes' renderers are out of a test's reach.
    list_hits_cap: AtomicU32,
    /// Entries the winding walk's stack may hold, lowered by a test (`lower_wind_stack`; 0:
    /// `WIND_STACK`).
    wind_stack_cap: AtomicU32,
}

/// The most bytes one storage binding may hold on a device of `limits`: the binding limit, or
/// the buffer limit where that is lower. Every array the kernels bind is checked against it.
pub(crate) fn max_binding_bytes(limits: &wgpu::Limits) -> u64 {
    limits.max_storage_buffer_binding_size.min(limits.max_buffer_size)
}

/// Adapter kinds in order of preference.
fn rank(t: wgpu::DeviceType) -> u32 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

impl GpuContext {
    /// Opens the best adapter (discrete first, software last). `GRIDTRACE_ADAPTER=text` picks the
    /// first adapter whose name contains `text` (case-insensitive).
    pub fn new() -> Result<GpuContext> {
        GpuContext::new_with(wgpu::InstanceDescriptor::new_without_display_handle())
    }

    /// `new`, from an instance made with `desc` (its backends and flags still from the
    /// environment, as `new`'s): the viewer passes one that knows the window system's display
    /// (`InstanceDescriptor::new_with_display_handle`), so that a window's surface can be made
    /// from the tracer's own instance and the frames presented from its device.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new_with(desc: wgpu::InstanceDescriptor) -> Result<GpuContext> {
        pollster::block_on(Self::new_async(desc))
    }

    /// In a browser nothing may block: the adapter and device come from promises the page's
    /// event loop resolves, so the blocking `new_with` (which would wait forever) is an error
    /// that says to open the device with `new_async` (`Backend::Auto` falls back to the CPU).
    #[cfg(target_arch = "wasm32")]
    pub fn new_with(_desc: wgpu::InstanceDescriptor) -> Result<GpuContext> {
        Err(Error::Gpu(
            "in a browser the GPU device is opened asynchronously (GpuContext::new_async)".into(),
        ))
    }

    /// `new_with`, awaited rather than blocked on: the one way to open a device in a browser.
    pub async fn new_async(mut desc: wgpu::InstanceDescriptor) -> Result<GpuContext> {
        desc.backends = wgpu::Backends::PRIMARY.with_env();
        desc.flags = wgpu::InstanceFlags::empty().with_env();
        let instance = wgpu::Instance::new(desc);
        let mut adapters = instance.enumerate_adapters(wgpu::Backends::PRIMARY.with_env()).await;
        if adapters.is_empty() {
            return Err(Error::Gpu(
                "no GPU adapter found (for a software one on Linux, install Mesa's lavapipe: \
                 Debian/Ubuntu package mesa-vulkan-drivers)"
                    .into(),
            ));
        }
        if let Ok(want) = std::env::var("GRIDTRACE_ADAPTER") {
            let want = want.to_lowercase();
            let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
            adapters.retain(|a| a.get_info().name.to_lowercase().contains(&want));
            if adapters.is_empty() {
                return Err(Error::Gpu(format!(
                    "GRIDTRACE_ADAPTER={want} matches none of: {}",
                    names.join(", ")
                )));
            }
        }
        adapters.sort_by_key(|a| rank(a.get_info().device_type));
        let adapter = adapters.remove(0);
        let info = adapter.get_info();
        let features = adapter.features();
        let timestamps = features.contains(wgpu::Features::TIMESTAMP_QUERY);
        let subgroups = features.contains(wgpu::Features::SUBGROUP);
        let mut required_features = wgpu::Features::empty();
        if timestamps {
            required_features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        if subgroups {
            required_features |= wgpu::Features::SUBGROUP;
        }
        let ray_query = features.contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY);
        if ray_query {
            required_features |= wgpu::Features::EXPERIMENTAL_RAY_QUERY;
        }
        // SAFETY: wgpu asks the caller to accept that its experimental features may have bugs.
        // The one used is ray queries, only where the adapter offers them, and only by the
        // `hwrt` walk (its acceleration structures built and bound through wgpu's validated
        // API); every other kernel is unchanged by it.
        let experimental_features = if ray_query {
            unsafe { wgpu::ExperimentalFeatures::enabled() }
        } else {
            wgpu::ExperimentalFeatures::disabled()
        };
        // Ask for what the adapter really has, not the conservative defaults (8 storage buffers,
        // 128 MiB bindings): large scenes need the real limits, and ray queries the adapter's
        // acceleration-structure limits (0 by default: no BLAS could hold a triangle).
        let limits = adapter.limits();
        let needed = storage_buffers_needed();
        if limits.max_storage_buffers_per_shader_stage < needed {
            return Err(Error::Gpu(format!(
                "adapter '{}' allows {} storage buffers per shader stage; gridtrace needs {needed} \
                 (limit max_storage_buffers_per_shader_stage)",
                info.name, limits.max_storage_buffers_per_shader_stage
            )));
        }
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("gridtrace"),
                required_features,
                required_limits: limits,
                experimental_features,
                memory_hints: wgpu::MemoryHints::Performance,
                trace: wgpu::Trace::Off,
            })
            .await
            .map_err(|e| Error::Gpu(format!("cannot open device on '{}': {e}", info.name)))?;
        let errors = Arc::new(Mutex::new(None::<String>));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut slot = sink.lock().unwrap_or_else(|p| p.into_inner());
            slot.get_or_insert_with(|| e.to_string());
        }));
        let lost = Arc::new(Mutex::new(None::<String>));
        let sink = lost.clone();
        device.set_device_lost_callback(move |reason, msg| {
            let mut slot = sink.lock().unwrap_or_else(|p| p.into_inner());
            slot.get_or_insert_with(|| format!("device lost ({reason:?}): {msg}"));
        });
        Ok(GpuContext {
            instance,
            adapter,
            device,
            queue,
            info,
            timestamps,
            subgroups,
            ray_query,
            errors,
            lost,
            cache: Mutex::new(HashMap::new()),
            list_hits_cap: AtomicU32::new(0),
            wind_stack_cap: AtomicU32::new(0),
        })
    }

    /// One line naming the adapter: name, backend, type, driver.
    pub fn describe(&self) -> String {
        let i = &self.info;
        let driver = if i.driver.is_empty() {
            String::new()
        } else {
            format!(", driver {} {}", i.driver, i.driver_info)
        };
        // Browsers withhold the adapter's name (fingerprinting); say so rather than print nothing.
        let name = if i.name.is_empty() {
            "an unnamed adapter"
        } else {
            i.name.as_str()
        };
        format!(
            "{name} ({:?}, {:?}{driver}; {})",
            i.backend,
            i.device_type,
            self.ray_queries_words()
        )
    }

    /// Whether `hwrt` can run here, in words: "ray queries" or "no ray queries".
    pub fn ray_queries_words(&self) -> &'static str {
        if self.ray_query {
            "ray queries"
        } else {
            "no ray queries"
        }
    }

    /// An error naming this adapter and what it lacks, for a structure that traces by ray
    /// query (`hwrt`); `Ok` where it has them.
    pub fn check_ray_queries(&self, structure: &str) -> Result<()> {
        if self.ray_query {
            return Ok(());
        }
        Err(Error::Gpu(format!(
            "'{structure}' needs ray queries, which adapter '{}' ({:?}, driver {} {}) does not offer \
             (wgpu feature EXPERIMENTAL_RAY_QUERY: Vulkan's VK_KHR_ray_query and VK_KHR_acceleration_structure; \
             Mesa's lavapipe has them from Mesa 25)",
            self.info.name, self.info.backend, self.info.driver, self.info.driver_info
        )))
    }

    /// Whether `--accel auto` may pick `hwrt` here: ray queries on a hardware adapter (a
    /// software one's, lavapipe's from Mesa 25, run on the CPU's cores).
    pub fn hardware_ray_queries(&self) -> bool {
        self.ray_query && !self.is_software()
    }

    /// True for software rasterisers such as lavapipe or llvmpipe.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    pub fn limits(&self) -> wgpu::Limits {
        self.device.limits()
    }

    /// This device's `T`, made by `make` on first use and shared after (the compiled kernels:
    /// `Kernels::of`, `BuildKernels::of`). An error is returned and nothing is kept.
    pub(crate) fn cached<T: Any + Send + Sync>(&self, make: impl FnOnce(&wgpu::Device) -> Result<T>) -> Result<Arc<T>> {
        // Held while `make` runs: a second thread waits for the first's kernels instead of
        // compiling its own.
        let mut cache = self.cache.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(v) = cache.get(&TypeId::of::<T>()) {
            return Ok(v.clone().downcast::<T>().expect("the cache holds a T under T's id"));
        }
        let v = Arc::new(make(&self.device)?);
        cache.insert(TypeId::of::<T>(), v.clone());
        Ok(v)
    }

    /// Returns the first device error since the last call, as an `Error`.
    pub fn check_errors(&self) -> Result<()> {
        if let Some(why) = self.lost.lock().unwrap_or_else(|p| p.into_inner()).as_ref() {
            return Err(Error::Gpu(format!("the GPU device was lost: {why}")));
        }
        let mut slot = self.errors.lock().unwrap_or_else(|p| p.into_inner());
        match slot.take() {
            Some(e) => Err(Error::Gpu(e)),
            None => Ok(()),
        }
    }

    /// Makes the device behave as if `fault` had happened, through the same paths a real one
    /// takes (the device-lost callback's record, the uncaptured-error record), so that tests can
    /// check what callers do about faults that cannot be made to happen on demand.
    #[doc(hidden)]
    pub fn inject_fault(&self, fault: Fault) {
        match fault {
            Fault::DeviceLost => {
                let mut slot = self.lost.lock().unwrap_or_else(|p| p.into_inner());
                slot.get_or_insert_with(|| "device lost (Unknown): injected by a test".into());
            }
            Fault::OutOfMemory => {
                let mut slot = self.errors.lock().unwrap_or_else(|p| p.into_inner());
                slot.get_or_insert_with(|| "Out of Memory (injected by a test)".into());
            }
        }
    }

    /// Makes every list pass on this device hold at most `hits` hits (at least 1), as a device
    /// with smaller bindings would: how tests make a list meet a device limit
    /// (`Error::Limit`) through the scenes' own renderers, as `inject_fault` makes faults.
    #[doc(hidden)]
    pub fn lower_list_hits(&self, hits: u32) {
        self.list_hits_cap.store(hits.max(1), Ordering::Relaxed);
    }

    /// Makes the winding walk's stack on this device hold at most `entries` (at least 1) as
    /// far as the host's check goes: how tests make a winding tree meet the walk's limit
    /// (`Error::Limit`) without a mesh deep enough for `WIND_STACK`.
    #[doc(hidden)]
    pub fn lower_wind_stack(&self, entries: u32) {
        self.wind_stack_cap.store(entries.max(1), Ordering::Relaxed);
    }

    /// The stack entries a test allowed the winding walk (`lower_wind_stack`), if it lowered
    /// them.
    pub(crate) fn wind_stack_cap(&self) -> Option<u32> {
        Some(self.wind_stack_cap.load(Ordering::Relaxed)).filter(|&h| h > 0)
    }

    /// The hits a test allowed one list pass (`lower_list_hits`), if it lowered them.
    pub(crate) fn list_hits_cap(&self) -> Option<u32> {
        Some(self.list_hits_cap.load(Ordering::Relaxed)).filter(|&h| h > 0)
    }

    /// Waits for all submitted work, with a time limit: a hung or lost device is an error.
    pub fn wait(&self) -> Result<()> {
        self.wait_for(None)
    }

    /// Waits for the submission `index` (`None`: all submitted work), as `wait`.
    pub(crate) fn wait_for(&self, index: Option<wgpu::SubmissionIndex>) -> Result<()> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: index,
                timeout: Some(GPU_TIMEOUT),
            })
            .map_err(|e| {
                // A submission that failed validation is never run, so the wait fails: the
                // validation error says why.
                let why = self
                    .check_errors()
                    .err()
                    .map_or_else(String::new, |v| format!(" ({v})"));
                Error::Gpu(format!("waiting for the GPU failed: {e}{why}"))
            })?;
        self.check_errors()
    }

    /// Copies `size` bytes of `src` (from offset 0) back to the CPU: one submission and one
    /// wait (a host round trip).
    pub fn read_buffer(&self, src: &wgpu::Buffer, size: u64) -> Result<Vec<u8>> {
        if size == 0 {
            return Ok(Vec::new());
        }
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(src, 0, &staging, 0, Some(size));
        self.queue.submit([enc.finish()]);
        self.map_read_with(&staging, size, |raw| raw.to_vec())
            .map(|(bytes, _)| bytes)
    }

    /// The first `size` bytes (not zero) of `staging`, a `MAP_READ` buffer that submitted work
    /// fills, once that work is done: waits, maps, hands them to `f` and unmaps. Called right
    /// after the submission; with `f`'s result come the wait (to the mapped bytes) and the
    /// readout (`f`'s own time) on the host's clock, the preparation left at 0 for the caller
    /// (`HostPhases::close`).
    pub fn map_read_with<R>(
        &self,
        staging: &wgpu::Buffer,
        size: u64,
        f: impl FnOnce(&[u8]) -> R,
    ) -> Result<(R, HostPhases)> {
        self.begin_read(staging, size, None).finish(self, f)
    }

    /// Asks for the first `size` bytes (not zero) of `staging` mapped once the submission
    /// `after` (`None`: everything submitted) is done, without waiting: `PendingRead::finish`
    /// waits for it later. The pipelined ray batches trace one chunk while the host writes the
    /// next and reads the one before.
    pub(crate) fn begin_read(
        &self,
        staging: &wgpu::Buffer,
        size: u64,
        after: Option<wgpu::SubmissionIndex>,
    ) -> PendingRead {
        let (tx, rx) = std::sync::mpsc::channel();
        let mapped = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = mapped.clone();
        staging.map_async(wgpu::MapMode::Read, ..size, move |r| {
            let _ = tx.send(r);
            flag.store(true, std::sync::atomic::Ordering::Release);
        });
        PendingRead {
            staging: staging.clone(),
            size,
            after,
            rx,
            mapped,
        }
    }
}

/// A readback asked for by `GpuContext::begin_read`, not yet waited for.
pub(crate) struct PendingRead {
    staging: wgpu::Buffer,
    size: u64,
    after: Option<wgpu::SubmissionIndex>,
    rx: std::sync::mpsc::Receiver<std::result::Result<(), wgpu::BufferAsyncError>>,
    /// Set when the mapping has completed (or failed): `finish` will not wait.
    mapped: Arc<std::sync::atomic::AtomicBool>,
}

impl PendingRead {
    /// Whether the mapping has completed, so that `finish` returns without waiting. In a
    /// browser the mapping completes only on the page's event loop, and nothing may block: the
    /// page yields to it until this holds, then calls `finish`.
    pub(crate) fn is_ready(&self) -> bool {
        self.mapped.load(std::sync::atomic::Ordering::Acquire)
    }

    /// Waits for the submission and the mapping, hands the bytes to `f` and unmaps; with `f`'s
    /// result come the wait (to the mapped bytes) and the readout (`f`'s own time) on the
    /// host's clock, the preparation left at 0 for the caller (`HostPhases::close`).
    pub(crate) fn finish<R>(self, ctx: &GpuContext, f: impl FnOnce(&[u8]) -> R) -> Result<(R, HostPhases)> {
        let PendingRead {
            staging,
            size,
            after,
            rx,
            mapped: _,
        } = self;
        let waited = Instant::now();
        // On any failure the buffer is unmapped again (a pending map is cancelled), so that it
        // can be used by the next submission once the fault has passed.
        let failed = |e: Error| {
            staging.unmap();
            Err(e)
        };
        if let Err(e) = ctx.wait_for(after) {
            return failed(e);
        }
        // In a browser, waiting is not possible (`recv_timeout` needs a clock std lacks there,
        // and the mapping cannot complete while the page's thread blocks): the page waited for
        // `is_ready` before calling this.
        #[cfg(target_arch = "wasm32")]
        let received = rx.try_recv().map_err(|_| ());
        #[cfg(not(target_arch = "wasm32"))]
        let received = rx.recv_timeout(Duration::from_secs(5)).map_err(|_| ());
        match received {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return failed(Error::Gpu(format!("mapping a result buffer failed: {e}"))),
            Err(_) => return failed(Error::Gpu("mapping a result buffer did not complete".into())),
        }
        let mapped = Instant::now();
        let out = {
            let view = staging
                .get_mapped_range(..size)
                .map_err(|e| Error::Gpu(format!("reading a result buffer failed: {e}")))?;
            f(&view)
        };
        staging.unmap();
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let phases = HostPhases {
            prepare_ms: 0.0,
            wait_ms: ms(mapped - waited),
            readout_ms: ms(mapped.elapsed()),
        };
        Ok((out, phases))
    }
}

/// Runs `f`, which creates things on `dev`, with the validation error it caused, if any.
/// Natively that is an error scope, popped by blocking: wgpu-core validates as things are
/// created, so the scope's future is ready at once. In a browser (WebGPU) the scope's promise
/// resolves only on the page's event loop, which blocking would never reach: there no scope is
/// pushed, and an error goes to the device's uncaptured-error record, which the next wait
/// reports (`GpuContext::check_errors`).
pub(crate) fn validated<T>(dev: &wgpu::Device, f: impl FnOnce() -> T) -> (T, Option<wgpu::Error>) {
    #[cfg(not(target_arch = "wasm32"))]
    {
        let scope = dev.push_error_scope(wgpu::ErrorFilter::Validation);
        let made = f();
        (made, pollster::block_on(scope.pop()))
    }
    #[cfg(target_arch = "wasm32")]
    {
        let _ = dev;
        (f(), None)
    }
}

/// Checks every scene array (`(name, bytes)`) against the device's per-binding limits before
/// anything is allocated: a scene too large for the device is an error that names the array and
/// the limit, not a validation panic or a lost device.
pub fn check_scene_fits(arrays: &[(&'static str, u64)], limits: &wgpu::Limits, adapter: &str) -> Result<()> {
    let max_binding = max_binding_bytes(limits);
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
