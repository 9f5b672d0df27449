//! The wgpu device every kernel runs on: adapter selection, the features the
//! kernels care about (float atomics, timestamp queries), limits, and buffer
//! helpers (create / upload / readback).
//!
//! Why a module of its own: every kernel host needs the same device and the
//! same buffer conventions, and tests must be able to force the fallback paths
//! (the compare-and-swap atomics used on GL / llvmpipe) on a Vulkan adapter.
//! Under `cfg(test)` freshly created buffers are filled with noise (a Brush
//! habit) so no test leans on zero-initialised memory.

use super::GpuError;
use bytemuck::Pod;
use wgpu::util::DeviceExt;

/// How to pick and configure the device.
#[derive(Debug, Clone, Default)]
pub struct GpuOptions {
    /// Use the compare-and-swap loop for gradient accumulation even when the
    /// adapter has `SHADER_FLOAT32_ATOMIC` (tests force this to cover the GL path).
    pub force_cas_atomics: bool,
    /// Do not use subgroup operations even when the adapter has
    /// `SUBGROUP` (tests force this to cover the plain-atomics path).
    pub no_subgroups: bool,
    /// Request timestamp queries when the adapter has them (for profiling).
    pub timestamps: bool,
    /// Give `rasterize_backward` one splat list per tile (16 columns), as on
    /// adapters whose subgroups may be wider than 8 lanes, even when 8-column
    /// lists would do (tests force this to cover that path on lavapipe).
    pub wide_lists: bool,
}

/// Adapter, device, queue and the detected capabilities.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// Adapter name and backend, for logs.
    pub adapter_info: wgpu::AdapterInfo,
    /// True when gradient accumulation uses native `atomicAdd` on `f32`.
    pub float_atomics: bool,
    /// True when gradient kernels reduce over the subgroup before their
    /// atomics (`SUBGROUP` feature).
    pub subgroups: bool,
    /// True when timestamp queries were enabled.
    pub timestamps: bool,
    /// Column-block width of `rasterize_backward`'s per-block splat lists:
    /// 8 when subgroups are off or every possible subgroup size divides 8
    /// (so no subgroup spans two blocks and `grad_acc` stays
    /// subgroup-uniform), else 16 (one block per tile).
    pub list_cols: u32,
    /// Entries the rasterizers fetch per list step, one per subgroup lane
    /// (`kernel::lane_wgsl`): 8 when subgroups are on, every subgroup has
    /// exactly 8 lanes and `list_cols` is 8 (llvmpipe with AVX2), else 1.
    pub lanes: u32,
    /// Device limits in force.
    pub limits: wgpu::Limits,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.adapter_info.name)
            .field("backend", &self.adapter_info.backend)
            .field("float_atomics", &self.float_atomics)
            .field("subgroups", &self.subgroups)
            .field("timestamps", &self.timestamps)
            .field("list_cols", &self.list_cols)
            .field("lanes", &self.lanes)
            .finish()
    }
}

impl GpuContext {
    /// Open the first suitable adapter. `Err(GpuError::NoAdapter)` when there
    /// is none, so callers can fall back to the CPU reference.
    pub fn new(opts: &GpuOptions) -> Result<Self, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            apply_limit_buckets: false,
        }))
        .map_err(|_| GpuError::NoAdapter)?;
        let features = adapter.features();
        let float_atomics =
            !opts.force_cas_atomics && features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC);
        let timestamps = opts.timestamps && features.contains(wgpu::Features::TIMESTAMP_QUERY);
        let subgroups = !opts.no_subgroups && features.contains(wgpu::Features::SUBGROUP);
        let mut required = wgpu::Features::empty();
        if subgroups {
            required |= wgpu::Features::SUBGROUP;
        }
        if float_atomics {
            required |= wgpu::Features::SHADER_FLOAT32_ATOMIC;
        }
        if timestamps {
            required |= wgpu::Features::TIMESTAMP_QUERY;
        }
        let adapter_limits = adapter.limits();
        let limits = wgpu::Limits {
            // Every kernel binds ≤ 8 (the GL fallback's limit; a test checks),
            // so asking for no more makes wgpu reject a kernel that grows past it.
            max_storage_buffers_per_shader_stage: adapter_limits
                .max_storage_buffers_per_shader_stage
                .min(8),
            max_storage_buffer_binding_size: adapter_limits.max_storage_buffer_binding_size,
            max_buffer_size: adapter_limits.max_buffer_size,
            max_compute_workgroup_storage_size: adapter_limits.max_compute_workgroup_storage_size,
            ..wgpu::Limits::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("romosplat"),
            required_features: required,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        let adapter_info = adapter.get_info();
        let list_cols = if !opts.wide_lists
            && (!subgroups
                || (adapter_info.subgroup_max_size <= 8 && adapter_info.subgroup_min_size >= 1))
        {
            8
        } else {
            16
        };
        let lanes = if subgroups
            && list_cols == 8
            && adapter_info.subgroup_min_size == 8
            && adapter_info.subgroup_max_size == 8
        {
            8
        } else {
            1
        };
        Ok(GpuContext {
            device,
            queue,
            adapter_info,
            list_cols,
            lanes,
            float_atomics,
            subgroups,
            timestamps,
            limits,
        })
    }

    /// Largest number of bytes one storage binding may hold.
    pub fn max_binding_bytes(&self) -> u64 {
        self.limits.max_storage_buffer_binding_size
    }

    /// A read-write storage buffer of `bytes` (at least 16) bytes. Contents are
    /// unspecified (noise under `cfg(test)`, zero otherwise).
    pub fn storage(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        let size = bytes.max(16).next_multiple_of(4);
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        #[cfg(test)]
        {
            let noise: Vec<u32> = (0..size / 4)
                .map(|i| (i as u32).wrapping_mul(2_654_435_761).rotate_left(13) ^ 0x7f80_0001)
                .collect();
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: bytemuck::cast_slice(&noise),
                    usage,
                })
        }
        #[cfg(not(test))]
        {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        }
    }

    /// A storage buffer holding `data` (padded to at least 16 bytes).
    pub fn upload<T: Pod>(&self, label: &str, data: &[T]) -> wgpu::Buffer {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.len() >= 16 {
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: bytes,
                    usage: wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::COPY_SRC
                        | wgpu::BufferUsages::COPY_DST,
                })
        } else {
            let mut padded = vec![0u8; 16];
            padded[..bytes.len()].copy_from_slice(bytes);
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: &padded,
                    usage: wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::COPY_SRC
                        | wgpu::BufferUsages::COPY_DST,
                })
        }
    }

    /// A uniform buffer holding one `#[repr(C)]` value.
    pub fn uniform<T: Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::bytes_of(value),
                usage: wgpu::BufferUsages::UNIFORM
                    | wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// Copy the first `count` elements of `buffer` back to the host.
    /// Submits and waits for all queued work first.
    pub fn read<T: Pod>(&self, buffer: &wgpu::Buffer, count: usize) -> Result<Vec<T>, GpuError> {
        self.read_at(buffer, 0, count)
    }

    /// Copy `count` elements starting at element `first` back to the host.
    pub fn read_at<T: Pod>(
        &self,
        buffer: &wgpu::Buffer,
        first: usize,
        count: usize,
    ) -> Result<Vec<T>, GpuError> {
        let size = std::mem::size_of::<T>();
        let bytes = (count * size) as u64;
        let offset = (first * size) as u64;
        if bytes == 0 {
            return Ok(Vec::new());
        }
        if !offset.is_multiple_of(4) || offset + bytes.next_multiple_of(4) > buffer.size() {
            return Err(GpuError::InvalidInput(format!(
                "readback of {bytes} bytes from a {}-byte buffer",
                buffer.size()
            )));
        }
        let padded = bytes.next_multiple_of(4);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: padded,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        enc.copy_buffer_to_buffer(buffer, offset, &staging, 0, padded);
        self.queue.submit([enc.finish()]);
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let view = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let out: Vec<T> = bytemuck::pod_collect_to_vec(&view[..bytes as usize]);
        drop(view);
        staging.unmap();
        Ok(out)
    }

    /// Block until every submitted command has finished.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Device(e.to_string()))
    }
}
