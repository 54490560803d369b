//! The GPU context: adapter choice, device, shader compilation (naga first, then wgpu), buffers,
//! uploads and read-backs, and device-loss detection.
//!
//! Nothing here panics: every failure is a [`GpuError`]. Uncaptured wgpu errors (which wgpu's
//! default handler would turn into a panic) are recorded and reported by [`Gpu::check`].

use std::fmt;
use std::sync::{Arc, Mutex};

use super::timing::Timing;

/// Environment variable: pick the first adapter whose name contains this (case-insensitive).
pub const ADAPTER_ENV: &str = "PAIRSUM_ADAPTER";

/// Everything that can go wrong on the GPU side.
#[derive(Clone, Debug)]
pub enum GpuError {
    /// No adapter at all; `help` says how to get one.
    NoAdapter { help: String },
    /// `PAIRSUM_ADAPTER` matched none of the adapters found.
    NoMatchingAdapter { wanted: String, available: Vec<String> },
    /// Device creation or an allocation failed.
    Device(String),
    /// naga or wgpu rejected a shader: the module's label, its WGSL text and the message.
    Shader { label: String, wgsl: String, message: String },
    /// A buffer larger than the device allows.
    TooLarge { what: String, needed: u64, limit: u64 },
    /// The device was lost (driver reset, out of memory, destroyed).
    Lost(String),
    /// Mapping a buffer for reading failed, or a copy was misaligned.
    Map(String),
}

/// What to tell a user who has no adapter.
pub const NO_ADAPTER_HELP: &str = "no GPU adapter found: install a Vulkan driver for your GPU; on Debian/Ubuntu \
without a GPU, `apt-get install mesa-vulkan-drivers` gives lavapipe, a Vulkan device that runs on the CPU \
(slow, but enough for tests)";

impl fmt::Display for GpuError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GpuError::NoAdapter { help } => f.write_str(help),
            GpuError::NoMatchingAdapter { wanted, available } => {
                write!(f, "no GPU adapter matches {ADAPTER_ENV}={wanted:?}; available: ")?;
                if available.is_empty() {
                    f.write_str("none")
                } else {
                    f.write_str(&available.join(", "))
                }
            }
            GpuError::Device(m) => write!(f, "GPU device error: {m}"),
            GpuError::Shader { label, wgsl, message } => {
                write!(f, "shader `{label}` was rejected (a compiler bug):\n{message}\n--- WGSL of `{label}` ---\n")?;
                for (k, line) in wgsl.lines().enumerate() {
                    writeln!(f, "{:4} | {line}", k + 1)?;
                }
                Ok(())
            }
            GpuError::TooLarge { what, needed, limit } => write!(
                f,
                "GPU buffer `{what}` needs {needed} bytes ({:.1} MiB), but this device allows at most {limit} bytes \
                 ({:.1} MiB) per storage buffer: use fewer particles or a GPU with larger limits",
                *needed as f64 / 1048576.0,
                *limit as f64 / 1048576.0
            ),
            GpuError::Lost(m) => write!(f, "the GPU device was lost: {m}"),
            GpuError::Map(m) => write!(f, "GPU read-back failed: {m}"),
        }
    }
}

impl std::error::Error for GpuError {}

/// A device and its queue, with the adapter's description and the limits the device was created
/// with (the adapter's own, so large storage buffers are allowed).
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter_info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    lost: Arc<Mutex<Option<String>>>,
    errors: Arc<Mutex<Vec<String>>>,
    /// What the run's kernels, submissions and read-backs cost (`pairsum run --timing`).
    timing: Option<Timing>,
    /// The pipelines compiled so far, by label, source and entry point: a rank of a split run
    /// builds its passes again for each new halo ([`crate::backend::gpu::share`]), from the same
    /// kernels.
    pipelines: Mutex<std::collections::HashMap<(String, String, String), wgpu::ComputePipeline>>,
}

impl fmt::Debug for Gpu {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Gpu").field("adapter", &self.describe()).finish_non_exhaustive()
    }
}

/// Preference rank of a device type: lower is better.
fn type_rank(t: wgpu::DeviceType) -> u32 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    }
}

/// Preference rank of a backend: the native APIs before GL.
fn backend_rank(b: wgpu::Backend) -> u32 {
    match b {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 0,
        wgpu::Backend::Gl => 1,
        _ => 2,
    }
}

/// "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)".
pub fn describe_adapter(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

/// The index of the adapter to use among `infos`: the first whose name contains `wanted`
/// (case-insensitive) if given, else the best by device type, then backend, then order.
pub fn choose_adapter(infos: &[wgpu::AdapterInfo], wanted: Option<&str>) -> Result<usize, GpuError> {
    choose_adapter_for(infos, wanted, 0)
}

/// [`choose_adapter`] for the `nth` rank on a machine: the `nth` (cyclically, in order) of the
/// adapters whose name contains `wanted`, or else of those tied for the best device type and
/// backend (a machine's GPUs, not their GL doubles).
pub fn choose_adapter_for(infos: &[wgpu::AdapterInfo], wanted: Option<&str>, nth: usize) -> Result<usize, GpuError> {
    let first = choose_first_adapter(infos, wanted)?;
    let tied: Vec<usize> = (0..infos.len())
        .filter(|&k| match wanted {
            Some(w) => infos[k].name.to_lowercase().contains(&w.to_lowercase()),
            None => {
                let rank = |k: usize| (type_rank(infos[k].device_type), backend_rank(infos[k].backend));
                rank(k) == rank(first)
            }
        })
        .collect();
    Ok(tied[nth % tied.len()])
}

fn choose_first_adapter(infos: &[wgpu::AdapterInfo], wanted: Option<&str>) -> Result<usize, GpuError> {
    if infos.is_empty() {
        return Err(GpuError::NoAdapter { help: NO_ADAPTER_HELP.to_string() });
    }
    if let Some(w) = wanted {
        let lw = w.to_lowercase();
        return infos.iter().position(|i| i.name.to_lowercase().contains(&lw)).ok_or_else(|| {
            GpuError::NoMatchingAdapter {
                wanted: w.to_string(),
                available: infos.iter().map(describe_adapter).collect(),
            }
        });
    }
    Ok((0..infos.len())
        .min_by_key(|&k| (type_rank(infos[k].device_type), backend_rank(infos[k].backend), k))
        .expect("not empty"))
}

fn panic_message(p: Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "panic".to_string()
    }
}

/// Size rounded up to a multiple of 4 bytes (wgpu's copy alignment), at least 4.
pub fn aligned_size(bytes: u64) -> u64 {
    bytes.max(4).div_ceil(4) * 4
}

impl Gpu {
    /// Opens the preferred adapter (see [`choose_adapter`]; `PAIRSUM_ADAPTER` overrides) and
    /// creates a device with the adapter's own limits and no optional features.
    pub fn new() -> Result<Gpu, GpuError> {
        Gpu::with_timing(false)
    }

    /// [`new`](Self::new); with `timing`, the device also keeps a [`Timing`] of the run (with
    /// each kernel's device time where the adapter has timestamp queries).
    pub fn with_timing(timing: bool) -> Result<Gpu, GpuError> {
        Gpu::for_rank(timing, 0)
    }

    /// [`with_timing`](Self::with_timing) for the rank `local` of those on this machine: it takes
    /// the `local`-th (cyclically) of the adapters tied for the best ([`choose_adapter_for`]), so
    /// that the ranks of a split run share a machine's GPUs out.
    pub fn for_rank(timing: bool, local: usize) -> Result<Gpu, GpuError> {
        let wanted = crate::config::env().adapter.clone().filter(|s| !s.trim().is_empty());
        // wgpu may panic inside driver or loader code; a failure to start is never a crash.
        std::panic::catch_unwind(move || Gpu::open(wanted.as_deref(), timing, local))
            .unwrap_or_else(|p| Err(GpuError::Device(format!("wgpu panicked: {}", panic_message(p)))))
    }

    fn open(wanted: Option<&str>, timing: bool, local: usize) -> Result<Gpu, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        let infos: Vec<wgpu::AdapterInfo> = adapters.iter().map(|a| a.get_info()).collect();
        let k = choose_adapter_for(&infos, wanted, local)?;
        let adapter = &adapters[k];
        let limits = adapter.limits();
        let timestamps = timing && adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let desc = wgpu::DeviceDescriptor {
            label: Some("pairsum"),
            required_features: if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() },
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&desc))
            .map_err(|e| GpuError::Device(format!("{}: {e}", describe_adapter(&infos[k]))))?;
        let lost = Arc::new(Mutex::new(None));
        let errors = Arc::new(Mutex::new(Vec::new()));
        {
            let lost = lost.clone();
            device.set_device_lost_callback(move |reason, message| {
                if let Ok(mut l) = lost.lock() {
                    *l = Some(format!("{reason:?}: {message}"));
                }
            });
        }
        {
            let errors = errors.clone();
            device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
                if let Ok(mut v) = errors.lock() {
                    v.push(e.to_string());
                }
            }));
        }
        let limits = device.limits();
        let timing = timing.then(|| Timing::new(&device, &queue, timestamps));
        Ok(Gpu {
            device,
            queue,
            adapter_info: infos[k].clone(),
            limits,
            lost,
            errors,
            timing,
            pipelines: Default::default(),
        })
    }

    /// Whether the adapter is a software rasteriser on the CPU (lavapipe, SwiftShader): right for
    /// testing the GPU backend, slower than the CPU backend for running.
    pub fn is_software(&self) -> bool {
        self.adapter_info.device_type == wgpu::DeviceType::Cpu
    }

    /// "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)".
    pub fn describe(&self) -> String {
        describe_adapter(&self.adapter_info)
    }

    /// Err(Lost) once the device-lost callback has fired.
    pub fn check_lost(&self) -> Result<(), GpuError> {
        match self.lost.lock().ok().and_then(|l| l.clone()) {
            Some(reason) => Err(GpuError::Lost(reason)),
            None => Ok(()),
        }
    }

    /// [`check_lost`](Self::check_lost), then the first uncaptured wgpu error since the last
    /// call (they are drained), as `GpuError::Device`.
    pub fn check(&self) -> Result<(), GpuError> {
        self.check_lost()?;
        let errors: Vec<String> = self.errors.lock().map(|mut v| std::mem::take(&mut *v)).unwrap_or_default();
        match errors.len() {
            0 => Ok(()),
            1 => Err(GpuError::Device(errors[0].clone())),
            k => Err(GpuError::Device(format!("{} (and {} more errors)", errors[0], k - 1))),
        }
    }

    /// Parses and validates `wgsl` with naga, then builds a compute pipeline for `entry` with an
    /// automatic layout. A module naga rejects never reaches wgpu; wgpu's own validation errors
    /// are caught in an error scope. Both give `GpuError::Shader` with the text and the message.
    /// A kernel compiled before on this device is not compiled again.
    pub fn compile(&self, label: &str, wgsl: &str, entry: &str) -> Result<wgpu::ComputePipeline, GpuError> {
        let key = (label.to_string(), wgsl.to_string(), entry.to_string());
        if let Some(p) = self.pipelines.lock().ok().and_then(|c| c.get(&key).cloned()) {
            return Ok(p);
        }
        let pipeline = self.compile_new(label, wgsl, entry)?;
        if let Ok(mut c) = self.pipelines.lock() {
            c.insert(key, pipeline.clone());
        }
        Ok(pipeline)
    }

    fn compile_new(&self, label: &str, wgsl: &str, entry: &str) -> Result<wgpu::ComputePipeline, GpuError> {
        validate_wgsl(label, wgsl)?;
        let shader_error =
            |message: String| GpuError::Shader { label: label.to_string(), wgsl: wgsl.to_string(), message };
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let descriptor =
            wgpu::ShaderModuleDescriptor { label: Some(label), source: wgpu::ShaderSource::Wgsl(wgsl.into()) };
        // Every runtime check stays on but naga's loop bounding, which gives every loop a 64-bit
        // countdown so that a loop that never ends cannot be assumed away; in the neighbour loop
        // that cost 3–5 % of a 3D pass on an H200 (docs/results/gpu_h200/, run 12).
        // SAFETY: wgpu requires that no shader given this way loops forever. Every loop of the
        // kernels pairsum compiles (generated from the IR, which has no loops of its own, or
        // written in `cells`, `reduce`, `reorder`, `lists` and `probe`) either counts a u32 up by
        // one to a bound read before the loop (cells, slots, list entries, mirror images, with
        // `<=` only to a cell count below u32::MAX), strides by at most 1024 × 256 up to a count
        // of particles, cells or partial results far below u32::MAX (buffer sizes bound them),
        // halves or doubles a power of two within 1..=256, or (the cell list's fit) doubles a
        // cell size whose exponent ends the loop past 1023.
        let checks = wgpu::ShaderRuntimeChecks { force_loop_bounding: false, ..wgpu::ShaderRuntimeChecks::checked() };
        let module = unsafe { self.device.create_shader_module_trusted(descriptor, checks) };
        let pipeline = self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: None,
            module: &module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(shader_error(format!("wgpu: {e}")));
        }
        self.check_lost()?;
        Ok(pipeline)
    }

    /// The largest storage buffer this device binds, in bytes.
    pub fn max_storage_bytes(&self) -> u64 {
        self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size)
    }

    /// Checks every planned buffer `(name, bytes)` against the device limits before anything is
    /// allocated; the first one too large is reported by name.
    pub fn estimate_fits(&self, bytes_per_buffer: &[(&str, u64)]) -> Result<(), GpuError> {
        let limit = self.max_storage_bytes();
        for &(what, needed) in bytes_per_buffer {
            if aligned_size(needed) > limit {
                return Err(GpuError::TooLarge { what: what.to_string(), needed, limit });
            }
        }
        Ok(())
    }

    /// A storage buffer of `size_bytes` (rounded up to 4, at least 4) with usage
    /// `STORAGE | COPY_SRC | COPY_DST | extra`, checked against the limits first.
    pub fn storage_buffer(
        &self,
        label: &str,
        size_bytes: u64,
        extra: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        self.estimate_fits(&[(label, size_bytes)])?;
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST | extra;
        self.buffer(label, aligned_size(size_bytes), usage)
    }

    /// A buffer of any usage; allocation failures (out of memory, validation) are errors.
    pub fn buffer(&self, label: &str, size_bytes: u64, usage: wgpu::BufferUsages) -> Result<wgpu::Buffer, GpuError> {
        if size_bytes > self.limits.max_buffer_size {
            return Err(GpuError::TooLarge {
                what: label.to_string(),
                needed: size_bytes,
                limit: self.limits.max_buffer_size,
            });
        }
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size_bytes,
            usage,
            mapped_at_creation: false,
        });
        let v = pollster::block_on(validation.pop());
        let o = pollster::block_on(oom.pop());
        if let Some(e) = v.or(o) {
            return Err(GpuError::Device(format!("allocating `{label}` ({size_bytes} bytes): {e}")));
        }
        Ok(buffer)
    }

    /// A small uniform buffer initialised with `data` (also usable as a copy source).
    pub fn uniform_buffer<T: bytemuck::Pod>(&self, label: &str, data: &[T]) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let mut padded = bytes.to_vec();
        padded.resize(aligned_size(bytes.len() as u64).max(16) as usize, 0);
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: &padded,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        })
    }

    /// Writes `data` into `buffer` at byte `offset_bytes` (queued; happens before the next
    /// submission). Offset and size must be multiples of 4.
    pub fn upload<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        offset_bytes: u64,
        data: &[T],
    ) -> Result<(), GpuError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.is_empty() {
            return Ok(());
        }
        let end = offset_bytes + bytes.len() as u64;
        if !offset_bytes.is_multiple_of(4) || !bytes.len().is_multiple_of(4) || end > buffer.size() {
            return Err(GpuError::Map(format!(
                "upload of {} bytes at byte {offset_bytes} into a buffer of {} bytes (offset and size must be \
                 multiples of 4, and fit)",
                bytes.len(),
                buffer.size()
            )));
        }
        self.queue.write_buffer(buffer, offset_bytes, bytes);
        Ok(())
    }

    /// Reads `count` values of `T` from `buffer` starting at byte `offset_bytes`: copies them to a
    /// mappable staging buffer, submits, waits and maps. Zero counts give an empty vector
    /// without touching the device.
    pub fn download<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        offset_bytes: u64,
        count: usize,
    ) -> Result<Vec<T>, GpuError> {
        let size = read_size::<T>(buffer, offset_bytes, count)?;
        if size == 0 {
            return Ok(Vec::new());
        }
        self.check_lost()?;
        let started = std::time::Instant::now();
        let staging = self.staging_buffer(size)?;
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("download") });
        encoder.copy_buffer_to_buffer(buffer, offset_bytes, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        self.map_read(&staging, count, started)
    }

    /// A buffer the host can map to read `size` bytes copied into it.
    pub fn staging_buffer(&self, size: u64) -> Result<wgpu::Buffer, GpuError> {
        self.buffer("download staging", size, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST)
    }

    /// Submits `encoder` with a copy of `count` values of `T` from `buffer` (at byte
    /// `offset_bytes`) into `staging` ([`Gpu::staging_buffer`], kept by the caller) appended, waits
    /// and returns the values: one submission and one wait where [`Gpu::download`] after the
    /// submission would take two, and a new staging buffer.
    pub fn submit_and_read<T: bytemuck::Pod>(
        &self,
        mut encoder: wgpu::CommandEncoder,
        buffer: &wgpu::Buffer,
        offset_bytes: u64,
        count: usize,
        staging: &wgpu::Buffer,
    ) -> Result<Vec<T>, GpuError> {
        let size = read_size::<T>(buffer, offset_bytes, count)?;
        if size > staging.size() {
            return Err(GpuError::Map(format!("a read of {size} bytes into a staging buffer of {}", staging.size())));
        }
        if size > 0 {
            encoder.copy_buffer_to_buffer(buffer, offset_bytes, staging, 0, size);
        }
        self.check_lost()?;
        let started = std::time::Instant::now();
        self.submit(encoder);
        if size == 0 {
            return Ok(Vec::new());
        }
        self.map_read(staging, count, started)
    }

    /// Waits for `staging` to be mappable (for the submission that copies into it to end), copies
    /// its first `count` values out and unmaps it. `started` is when the wait began, for the
    /// timing.
    pub fn map_read<T: bytemuck::Pod>(
        &self,
        staging: &wgpu::Buffer,
        count: usize,
        started: std::time::Instant,
    ) -> Result<Vec<T>, GpuError> {
        let size = count * std::mem::size_of::<T>();
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, ..size as u64, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| {
            self.check_lost().err().unwrap_or_else(|| GpuError::Map(format!("waiting for the GPU: {e}")))
        })?;
        match rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(self.check_lost().err().unwrap_or_else(|| GpuError::Map(e.to_string()))),
            Err(_) => {
                return Err(self.check_lost().err().unwrap_or_else(|| GpuError::Map("map callback dropped".into())))
            }
        }
        let mut out = vec![T::zeroed(); count];
        {
            let view = staging.get_mapped_range(..size as u64).map_err(|e| GpuError::Map(format!("{e:?}")))?;
            bytemuck::cast_slice_mut::<T, u8>(&mut out).copy_from_slice(&view[..size]);
        }
        staging.unmap();
        if let Some(t) = &self.timing {
            t.readback(size as u64, started.elapsed());
        }
        self.check()?;
        Ok(out)
    }

    /// Whether the run's timing is kept (`pairsum run --timing`): its timestamps are resolved at
    /// each submission, so commands must be submitted from their encoder, not finished ahead.
    pub fn is_timed(&self) -> bool {
        self.timing.is_some()
    }

    /// Submits commands finished ahead of their submission (never with timing: [`Gpu::is_timed`]).
    pub fn submit_finished(&self, commands: wgpu::CommandBuffer) {
        self.queue.submit([commands]);
    }

    /// Submits the encoder's commands.
    pub fn submit(&self, encoder: wgpu::CommandEncoder) {
        match &self.timing {
            Some(t) => t.submit(&self.device, &self.queue, encoder),
            None => {
                self.queue.submit([encoder.finish()]);
            }
        }
    }

    /// The timing of the run so far, per step over `steps` (None unless made
    /// [`with_timing`](Self::with_timing)).
    pub fn timing_report(&self, steps: u64) -> Option<String> {
        self.timing.as_ref().map(|t| t.report(steps))
    }

    /// Blocks until all submitted work is done.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| {
            self.check_lost().err().unwrap_or_else(|| GpuError::Device(format!("waiting for the GPU: {e}")))
        })?;
        self.check()
    }

    /// A new command encoder.
    pub fn encoder(&self, label: &str) -> wgpu::CommandEncoder {
        self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
    }

    /// Records one dispatch of `pipeline` with `bind_group` at group 0 over `groups` workgroups,
    /// split into a 2D grid when `groups` exceeds the per-dimension limit (kernels then read
    /// their linear workgroup index as `wg.x + wg.y * num_workgroups.x`; see [`dispatch_grid`]).
    pub fn dispatch(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        label: &str,
        pipeline: &wgpu::ComputePipeline,
        bind_group: &wgpu::BindGroup,
        groups: u32,
    ) {
        if groups == 0 {
            return;
        }
        let (x, y) = dispatch_grid(groups, self.limits.max_compute_workgroups_per_dimension);
        let timestamp_writes = self.timing.as_ref().and_then(|t| t.dispatch(label));
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(x, y, 1);
    }

    /// A bind group for group 0 of `pipeline` binding each `(binding, buffer)` of `entries`
    /// (with an automatic layout: exactly the bindings the shader uses, see [`used_bindings`]).
    pub fn bind_at(
        &self,
        label: &str,
        pipeline: &wgpu::ComputePipeline,
        entries: &[(u32, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let layout = pipeline.get_bind_group_layout(0);
        let entries: Vec<wgpu::BindGroupEntry> = entries
            .iter()
            .map(|(k, b)| wgpu::BindGroupEntry { binding: *k, resource: b.as_entire_binding() })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &layout,
            entries: &entries,
        })
    }

    /// A bind group for group 0 of `pipeline`: `entries[k]` is bound at binding `k` (every
    /// binding `0..entries.len()` must be used by the shader, see [`used_bindings`]).
    pub fn bind(&self, label: &str, pipeline: &wgpu::ComputePipeline, entries: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let layout = pipeline.get_bind_group_layout(0);
        let entries: Vec<wgpu::BindGroupEntry> = entries
            .iter()
            .enumerate()
            .map(|(k, b)| wgpu::BindGroupEntry { binding: k as u32, resource: b.as_entire_binding() })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &layout,
            entries: &entries,
        })
    }
}

/// The bytes of a read of `count` values of `T` at byte `offset_bytes` of `buffer`, checked: both
/// multiples of 4, and within the buffer.
fn read_size<T>(buffer: &wgpu::Buffer, offset_bytes: u64, count: usize) -> Result<u64, GpuError> {
    let size = (count * std::mem::size_of::<T>()) as u64;
    if size > 0 && (!offset_bytes.is_multiple_of(4) || !size.is_multiple_of(4) || offset_bytes + size > buffer.size()) {
        return Err(GpuError::Map(format!(
            "download of {size} bytes at byte {offset_bytes} from a buffer of {} bytes (offset and size must be \
             multiples of 4, and fit)",
            buffer.size()
        )));
    }
    Ok(size)
}

/// `(x, y)` with `x <= max_per_dim` and `x * y >= groups`, as square as needed: `(groups, 1)`
/// when it fits.
pub fn dispatch_grid(groups: u32, max_per_dim: u32) -> (u32, u32) {
    let max = max_per_dim.max(1);
    if groups <= max {
        return (groups, 1);
    }
    let y = groups.div_ceil(max);
    (groups.div_ceil(y), y)
}

/// Parses `wgsl` with naga's WGSL front end and validates it with every validation flag; the
/// error carries naga's message rendered against the source.
pub fn validate_wgsl(label: &str, wgsl: &str) -> Result<naga::Module, GpuError> {
    validate_with_info(label, wgsl).map(|(m, _)| m)
}

fn validate_with_info(label: &str, wgsl: &str) -> Result<(naga::Module, naga::valid::ModuleInfo), GpuError> {
    let err = |message: String| GpuError::Shader { label: label.to_string(), wgsl: wgsl.to_string(), message };
    let module = naga::front::wgsl::parse_str(wgsl).map_err(|e| err(e.emit_to_string_with_path(wgsl, label)))?;
    let mut validator =
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::default());
    let info = validator.validate(&module).map_err(|e| err(e.emit_to_string_with_path(wgsl, label)))?;
    Ok((module, info))
}

/// The `(group, binding)` pairs that entry point `entry` of `wgsl` actually uses, sorted. A
/// pipeline compiled with an automatic layout (as [`Gpu::compile`] does) has exactly these in
/// its bind group layouts, so a bind group must list exactly these: a declared but unused
/// binding must be left out (see [`Gpu::bind_at`]).
pub fn used_bindings(label: &str, wgsl: &str, entry: &str) -> Result<Vec<(u32, u32)>, GpuError> {
    let (module, info) = validate_with_info(label, wgsl)?;
    let Some(k) = module.entry_points.iter().position(|e| e.name == entry) else {
        return Err(GpuError::Shader {
            label: label.to_string(),
            wgsl: wgsl.to_string(),
            message: format!("no entry point `{entry}`"),
        });
    };
    let uses = info.get_entry_point(k);
    let mut out: Vec<(u32, u32)> = module
        .global_variables
        .iter()
        .filter(|(h, _)| !uses[*h].is_empty())
        .filter_map(|(_, v)| v.binding.as_ref().map(|b| (b.group, b.binding)))
        .collect();
    out.sort_unstable();
    Ok(out)
}
