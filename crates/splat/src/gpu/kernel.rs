//! Shared plumbing for every compute kernel: the [`kernel!`] declaration each
//! host module makes, the pipeline built once from it, the bind group built
//! from a typed struct of buffers, and a command recorder that can time every
//! dispatch with timestamp queries (used by `gpu::profile_step`).
//!
//! A kernel is declared once, in its host module, with [`kernel!`]: the WGSL
//! file, its bindings (name, access, WGSL type), its entry points with their
//! workgroup sizes, and the Rust constants injected into the WGSL. From that
//! one declaration come the [`KernelDecl`] table, the `@group(0) @binding(n)`
//! lines prepended to the shader (the `.wgsl` files declare no bindings), a
//! bindings struct with one field per binding (so buffers are bound by name,
//! checked by the compiler), and the host type with `new` / `bind`. The
//! reflection test (`tests/reflection`) parses every assembled shader with
//! naga and checks it against the table: uniform struct name and byte size,
//! entry points, and each entry point's `@workgroup_size`.

use super::{GpuContext, GpuError};

/// What a binding is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BindingKind {
    /// `var<uniform>` of the kernel's uniform struct.
    Uniform,
    /// `var<storage, read>`.
    StorageRead,
    /// `var<storage, read_write>`.
    StorageRw,
}

/// One `@group(0) @binding(n) var` of a kernel; `n` is its index in
/// [`KernelDecl::bindings`].
#[derive(Debug, Clone, Copy)]
pub struct BindingDecl {
    pub name: &'static str,
    pub kind: BindingKind,
    /// WGSL type: the uniform struct's name, or the storage type
    /// (`array<f32>`, `atomic<u32>`, …).
    pub ty: &'static str,
}

/// One compute entry point and its workgroup size.
#[derive(Debug, Clone, Copy)]
pub struct EntryPoint {
    pub name: &'static str,
    pub workgroup_size: [u32; 3],
}

/// Everything the host knows about one WGSL file (made by [`kernel!`]).
#[derive(Debug, Clone, Copy)]
pub struct KernelDecl {
    /// File stem in `shaders/splat/` and the host module name.
    pub name: &'static str,
    /// The WGSL text of the kernel (without `common.wgsl`, the injected
    /// constants and the bindings).
    pub source: &'static str,
    /// Compute entry points.
    pub entry_points: &'static [EntryPoint],
    /// `const NAME: u32 = value;` lines injected into the WGSL.
    pub constants: &'static [(&'static str, u32)],
    /// Every binding in group 0; binding 0 is the uniform.
    pub bindings: &'static [BindingDecl],
    /// Byte size of the Rust uniform struct (`bindings[0].ty` names it).
    pub uniform_size: usize,
    /// True when the kernel uses gradient atomics (`grad_add`), so it is
    /// compiled in a float-atomic and a CAS variant.
    pub uses_grad_atomics: bool,
}

/// Storage buffers per shader stage every WebGPU device allows.
pub const MIN_STORAGE_BUFFERS_PER_STAGE: usize = 8;

impl KernelDecl {
    /// Whether the uniform struct is bound as a read-only storage buffer: yes
    /// whenever the kernel's storage bindings leave room for it. Mesa's
    /// lavapipe inlines uniform-buffer values that steer control flow and
    /// compiles a shader variant for every distinct value, so per-step counts
    /// (splats, intersections) passed in a uniform buffer made it recompile
    /// during training; storage buffers are not inlined.
    pub fn uniform_in_storage(&self) -> bool {
        let storage = self
            .bindings
            .iter()
            .filter(|b| b.kind != BindingKind::Uniform)
            .count();
        storage < MIN_STORAGE_BUFFERS_PER_STAGE
    }
}

/// Declares one kernel: its [`KernelDecl`] static, a bindings struct and the
/// host type (`new`, `bind`, `record`). The host module adds its own
/// `dispatch`, which sizes the grid and fills the uniforms.
///
/// ```ignore
/// kernel! {
///     /// The compiled kernel.
///     pub struct Adam;
///     decl DECL = "adam";                      // shaders/splat/adam.wgsl
///     bindings AdamBindings {
///         u: uniform AdamUniforms,             // binding 0, the Rust #[repr(C)] struct
///         params: read_write "array<f32>",     // binding 1, …
///         grads: read "array<f32>",
///     }
///     entry_points { adam_main: [WORKGROUP_SIZE] }
///     constants { WORKGROUP_SIZE }             // Rust consts, injected as WGSL consts
/// }
/// ```
/// `decl X = "name" after ["other"]` prepends `shaders/splat/other.wgsl`;
/// `constants { NAME = expr }` injects a value under another name;
/// `grad_atomics` marks a kernel that calls `grad_add` (see [`shader_source`]).
macro_rules! kernel {
    (
        $(#[$doc:meta])*
        pub struct $host:ident;
        decl $decl:ident = $name:literal $(after [$($pre:literal),+])?;
        bindings $bindings:ident {
            $uname:ident: uniform $uty:ident,
            $($sname:ident: $access:ident $sty:literal),+ $(,)?
        }
        entry_points { $($ep:ident: [$($wg:expr),+]),+ $(,)? }
        constants { $($cname:ident $(= $cval:expr)?),* $(,)? }
        $($atomics:ident)?
    ) => {
        pub static $decl: $crate::gpu::kernel::KernelDecl = $crate::gpu::kernel::KernelDecl {
            name: $name,
            source: concat!(
                $($(include_str!(concat!("../../../../shaders/splat/", $pre, ".wgsl")),)+)?
                include_str!(concat!("../../../../shaders/splat/", $name, ".wgsl"))
            ),
            entry_points: &[$($crate::gpu::kernel::EntryPoint {
                name: stringify!($ep),
                workgroup_size: $crate::gpu::kernel::kernel!(@wg $($wg),+),
            }),+],
            constants: &[$((stringify!($cname), $crate::gpu::kernel::kernel!(@value $cname $($cval)?))),*],
            bindings: &[
                $crate::gpu::kernel::BindingDecl {
                    name: stringify!($uname),
                    kind: $crate::gpu::kernel::BindingKind::Uniform,
                    ty: stringify!($uty),
                },
                $($crate::gpu::kernel::BindingDecl {
                    name: stringify!($sname),
                    kind: $crate::gpu::kernel::kernel!(@kind $access),
                    ty: $sty,
                }),+
            ],
            uniform_size: std::mem::size_of::<$uty>(),
            uses_grad_atomics: $crate::gpu::kernel::kernel!(@atomics $($atomics)?),
        };

        /// The buffers of one bind group, one field per binding of the
        /// kernel (generated by `kernel!`).
        pub struct $bindings<'a> {
            pub $uname: &'a wgpu::Buffer,
            $(pub $sname: &'a wgpu::Buffer,)+
        }

        $(#[$doc])*
        pub struct $host {
            kernel: $crate::gpu::kernel::Kernel,
        }

        impl $host {
            /// Build the pipelines (pays the shader compile once).
            pub fn new(ctx: &$crate::gpu::GpuContext) -> Self {
                $host {
                    kernel: $crate::gpu::kernel::Kernel::new(ctx, &$decl),
                }
            }

            /// A bind group holding `b`.
            pub fn bind(
                &self,
                ctx: &$crate::gpu::GpuContext,
                b: &$bindings,
            ) -> Result<wgpu::BindGroup, $crate::gpu::GpuError> {
                self.kernel.bind(ctx, &[b.$uname, $(b.$sname),+])
            }

            /// Record one dispatch of `entry` over `groups` with the
            /// buffers `b` bound.
            pub fn record(
                &self,
                ctx: &$crate::gpu::GpuContext,
                rec: &mut $crate::gpu::kernel::Recorder,
                entry: &'static str,
                b: &$bindings,
                groups: [u32; 3],
            ) -> Result<(), $crate::gpu::GpuError> {
                let bind = self.bind(ctx, b)?;
                rec.dispatch(&self.kernel, entry, &bind, groups)
            }
        }
    };
    (@wg $x:expr) => { [$x, 1, 1] };
    (@wg $x:expr, $y:expr) => { [$x, $y, 1] };
    (@wg $x:expr, $y:expr, $z:expr) => { [$x, $y, $z] };
    (@value $cname:ident) => { $cname };
    (@value $cname:ident $cval:expr) => { $cval };
    (@kind read) => { $crate::gpu::kernel::BindingKind::StorageRead };
    (@kind read_write) => { $crate::gpu::kernel::BindingKind::StorageRw };
    (@atomics) => { false };
    (@atomics grad_atomics) => { true };
}
pub(crate) use kernel;

/// Shared helpers (structs, tile rectangles, projection math) prepended to every kernel.
pub const COMMON_WGSL: &str = include_str!("../../../../shaders/splat/common.wgsl");
/// Gradient accumulation with native float atomics. Kernels that set
/// `uses_grad_atomics` declare `grads: array<GradAtomic>` and call `grad_add`.
pub const ATOMIC_FLOAT_WGSL: &str = "alias GradAtomic = atomic<f32>;\n\
fn grad_add(i: u32, v: f32) { atomicAdd(&grads[i], v); }\n";
/// Gradient accumulation with a compare-and-swap loop on `atomic<u32>` (the
/// GL / llvmpipe fallback, where `SHADER_FLOAT32_ATOMIC` is missing).
pub const ATOMIC_CAS_WGSL: &str = "alias GradAtomic = atomic<u32>;\n\
fn grad_add(i: u32, v: f32) {\n\
    var old = atomicLoad(&grads[i]);\n\
    loop {\n\
        let r = atomicCompareExchangeWeak(&grads[i], old, bitcast<u32>(bitcast<f32>(old) + v));\n\
        if r.exchanged { break; }\n\
        old = r.old_value;\n\
    }\n\
}\n";

/// Subgroup-reduced gradient accumulation: `grad_acc` sums `v` over the
/// subgroup (8 lanes on llvmpipe) and only the subgroup's leader issues the
/// atomic, so a splat costs one atomic per subgroup instead of one per
/// invocation (atomics are scalarised, CAS-looped per lane on CPU drivers).
/// `grad_leader(lane)` picks the leader once, at the kernel's start, with
/// every invocation active (`lane` any per-invocation unique id);
/// `grad_any` / `grad_acc` must be called in subgroup-uniform control flow
/// with a subgroup-uniform `i`.
pub const GRAD_SUBGROUP_WGSL: &str = "fn grad_any(b: bool) -> bool { return subgroupAny(b); }\n\
fn grad_leader(lane: u32) -> bool { return lane == subgroupBroadcastFirst(lane); }\n\
fn grad_acc(i: u32, v: f32, leader: bool) {\n\
    let s = subgroupAdd(v);\n\
    if (leader) { grad_add(i, s); }\n\
}\n";
/// Without subgroups every invocation issues its own atomics.
pub const GRAD_PLAIN_WGSL: &str = "fn grad_any(b: bool) -> bool { return b; }\n\
fn grad_leader(lane: u32) -> bool { return true; }\n\
fn grad_acc(i: u32, v: f32, leader: bool) { grad_add(i, v); }\n";

/// The full WGSL module text for a kernel, atomics variant and subgroup
/// variant (`subgroups` only matters for kernels with gradient atomics).
pub fn shader_source(decl: &KernelDecl, float_atomics: bool, subgroups: bool) -> String {
    shader_source_cols(decl, float_atomics, subgroups, 8, 1)
}

/// Whether a kernel walks per-block splat lists (`block_lists.wgsl`), so
/// it takes the [`lane_wgsl`] helpers.
pub fn uses_block_lists(decl: &KernelDecl) -> bool {
    decl.source.contains("struct Chunk")
}

/// `LANES`, `lane_index`, `lane_all` and `lane_chunk` for the rasterizers'
/// list walk (see `block_lists.wgsl`): with `lanes` = 8 (every subgroup is
/// exactly 8 invocations, one column block) lane t fetches entry m0 + t and
/// `subgroupBroadcast` hands it to the others; with 1 each invocation
/// fetches every entry itself.
pub fn lane_wgsl(lanes: u32) -> String {
    if lanes == 1 {
        return "const LANES: u32 = 1u;\n\
fn lane_index() -> u32 { return 0u; }\n\
fn lane_all(b: bool) -> bool { return b; }\n\
fn lane_chunk(e: Entry) -> Chunk { return Chunk(e, e, e, e, e, e, e, e); }\n"
            .into();
    }
    let mut s = format!(
        "const LANES: u32 = {lanes}u;\n\
fn lane_index() -> u32 {{ return subgroupExclusiveAdd(1u); }}\n\
fn lane_all(b: bool) -> bool {{ return subgroupAll(b); }}\n"
    );
    for t in 0..lanes {
        s.push_str(&format!(
            "fn lane_entry{t}(e: Entry) -> Entry {{ return Entry(subgroupBroadcast(e.mo, {t}u), \
subgroupBroadcast(e.conic, {t}u), subgroupBroadcast(e.color, {t}u), \
subgroupBroadcast(e.key, {t}u), subgroupBroadcast(e.id, {t}u)); }}\n"
        ));
    }
    let args: Vec<String> = (0..lanes).map(|t| format!("lane_entry{t}(e)")).collect();
    s.push_str(&format!(
        "fn lane_chunk(e: Entry) -> Chunk {{ return Chunk({}); }}\n",
        args.join(", ")
    ));
    s
}

/// [`shader_source`] with the column-block width `list_cols` (8 or 16) of
/// `rasterize_backward`'s per-block splat lists (see
/// [`GpuContext::list_cols`]) and the rasterizers' list-walk width `lanes`
/// (1 or 8, [`GpuContext::lanes`]).
pub fn shader_source_cols(
    decl: &KernelDecl,
    float_atomics: bool,
    subgroups: bool,
    list_cols: u32,
    lanes: u32,
) -> String {
    let mut s = String::with_capacity(COMMON_WGSL.len() + decl.source.len() + 512);
    let subgroups = subgroups && decl.uses_grad_atomics;
    s.push_str(COMMON_WGSL);
    s.push('\n');
    if decl.uses_grad_atomics {
        s.push_str(&format!("const LIST_COLS: u32 = {list_cols}u;\n"));
    }
    if uses_block_lists(decl) {
        s.push_str(&lane_wgsl(lanes));
    }
    if decl.uses_grad_atomics {
        s.push_str(if float_atomics {
            ATOMIC_FLOAT_WGSL
        } else {
            ATOMIC_CAS_WGSL
        });
        s.push('\n');
        s.push_str(if subgroups {
            GRAD_SUBGROUP_WGSL
        } else {
            GRAD_PLAIN_WGSL
        });
        s.push('\n');
    }
    for (name, value) in decl.constants {
        s.push_str(&format!("const {name}: u32 = {value}u;\n"));
    }
    for (i, b) in decl.bindings.iter().enumerate() {
        let space = match b.kind {
            BindingKind::Uniform if decl.uniform_in_storage() => "storage, read",
            BindingKind::Uniform => "uniform",
            BindingKind::StorageRead => "storage, read",
            BindingKind::StorageRw => "storage, read_write",
        };
        s.push_str(&format!(
            "@group(0) @binding({i}) var<{space}> {}: {};\n",
            b.name, b.ty
        ));
    }
    s.push_str(decl.source);
    s
}

/// A compiled kernel: one pipeline per entry point, one bind group layout.
pub struct Kernel {
    pub decl: &'static KernelDecl,
    layout: wgpu::BindGroupLayout,
    pipelines: Vec<(&'static str, wgpu::ComputePipeline)>,
}

impl Kernel {
    /// Build the pipelines (pays the shader compile once).
    pub fn new(ctx: &GpuContext, decl: &'static KernelDecl) -> Self {
        let entries: Vec<wgpu::BindGroupLayoutEntry> = decl
            .bindings
            .iter()
            .zip(0u32..)
            .map(|(b, binding)| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: match b.kind {
                        BindingKind::Uniform if decl.uniform_in_storage() => {
                            wgpu::BufferBindingType::Storage { read_only: true }
                        }
                        BindingKind::Uniform => wgpu::BufferBindingType::Uniform,
                        BindingKind::StorageRead => {
                            wgpu::BufferBindingType::Storage { read_only: true }
                        }
                        BindingKind::StorageRw => {
                            wgpu::BufferBindingType::Storage { read_only: false }
                        }
                    },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            })
            .collect();
        let layout = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(decl.name),
                entries: &entries,
            });
        let pl = ctx
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(decl.name),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(decl.name),
                source: wgpu::ShaderSource::Wgsl(
                    shader_source_cols(
                        decl,
                        ctx.float_atomics,
                        ctx.subgroups,
                        ctx.list_cols,
                        ctx.lanes,
                    )
                    .into(),
                ),
            });
        let pipelines = decl
            .entry_points
            .iter()
            .map(|ep| {
                let ep = ep.name;
                let p = ctx
                    .device
                    .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(ep),
                        layout: Some(&pl),
                        module: &module,
                        entry_point: Some(ep),
                        compilation_options: Default::default(),
                        cache: None,
                    });
                (ep, p)
            })
            .collect();
        Kernel {
            decl,
            layout,
            pipelines,
        }
    }

    /// A bind group from one buffer per declared binding, in binding order
    /// (the bindings struct that [`kernel!`] generates calls this).
    pub fn bind(
        &self,
        ctx: &GpuContext,
        buffers: &[&wgpu::Buffer],
    ) -> Result<wgpu::BindGroup, GpuError> {
        if buffers.len() != self.decl.bindings.len() {
            return Err(GpuError::Binding(format!(
                "{}: {} buffers for {} bindings",
                self.decl.name,
                buffers.len(),
                self.decl.bindings.len()
            )));
        }
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .zip(0u32..)
            .map(|(buf, binding)| wgpu::BindGroupEntry {
                binding,
                resource: buf.as_entire_binding(),
            })
            .collect();
        Ok(ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.decl.name),
            layout: &self.layout,
            entries: &entries,
        }))
    }

    fn pipeline(&self, entry: &str) -> Result<&wgpu::ComputePipeline, GpuError> {
        self.pipelines
            .iter()
            .find(|(n, _)| *n == entry)
            .map(|(_, p)| p)
            .ok_or_else(|| GpuError::Binding(format!("{}: no entry point {entry}", self.decl.name)))
    }
}

/// Workgroup counts for `n` items at `wg` per group, spread over y when x
/// would exceed the 65 535 limit. Shaders recover the linear index with
/// `linear_index` from `common.wgsl`.
pub fn groups_1d(n: u32, wg: u32) -> [u32; 3] {
    let groups = n.div_ceil(wg).max(1);
    if groups <= 65_535 {
        [groups, 1, 1]
    } else {
        [65_535, groups.div_ceil(65_535), 1]
    }
}

/// Grow-only storage buffers kept across steps, one per role (`label`), so
/// a training step allocates nothing once the sizes have settled. A buffer is
/// reallocated only when a step needs more than its capacity, with 1.5×
/// headroom (capped at the device's binding limit) so slowly growing counts
/// (splats, tile intersections) reallocate rarely. Contents are unspecified
/// (whatever the last user left); kernels never read past what they wrote
/// this step. One `Scratch` per owner (never shared between threads: tests
/// share one device).
#[derive(Default)]
pub struct Scratch {
    buffers: std::collections::HashMap<&'static str, wgpu::Buffer>,
    /// Buffers (re)allocated so far, for tests and the profile.
    pub allocations: u64,
}

impl Scratch {
    /// The buffer for `label`, at least `bytes` long.
    pub fn get(&mut self, ctx: &GpuContext, label: &'static str, bytes: u64) -> wgpu::Buffer {
        let need = bytes.max(16).next_multiple_of(4);
        if let Some(b) = self.buffers.get(label)
            && b.size() >= need
        {
            return b.clone();
        }
        let cap = (need + need / 2)
            .min(ctx.max_binding_bytes().max(need))
            .next_multiple_of(4);
        let b = ctx.storage(label, cap);
        self.allocations += 1;
        self.buffers.insert(label, b.clone());
        b
    }
}

/// Records dispatches into one command encoder; optionally timestamps each.
/// Transient buffers of the kernels come from [`Recorder::storage`]: from the
/// attached [`Scratch`] when there is one, else freshly allocated.
pub struct Recorder<'a> {
    ctx: &'a GpuContext,
    pub encoder: wgpu::CommandEncoder,
    timer: Option<Timer>,
    scratch: Option<&'a mut Scratch>,
}

struct Timer {
    set: wgpu::QuerySet,
    capacity: u32,
    labels: Vec<&'static str>,
}

impl<'a> Recorder<'a> {
    /// A recorder; with `profile` (and a device with timestamp queries) each
    /// dispatch gets a begin/end timestamp pair, up to `2048` dispatches.
    pub fn new(ctx: &'a GpuContext, profile: bool) -> Self {
        let encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("splat"),
            });
        let timer = (profile && ctx.timestamps).then(|| {
            let capacity = 4096;
            Timer {
                set: ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: capacity,
                }),
                capacity,
                labels: Vec::new(),
            }
        });
        Recorder {
            ctx,
            encoder,
            timer,
            scratch: None,
        }
    }

    /// A recorder whose transient buffers persist in `scratch`.
    pub fn with_scratch(ctx: &'a GpuContext, profile: bool, scratch: &'a mut Scratch) -> Self {
        let mut r = Recorder::new(ctx, profile);
        r.scratch = Some(scratch);
        r
    }

    /// A storage buffer of at least `bytes` for the role `label`: persistent
    /// (see [`Scratch`]) when the recorder has one, else new. Two buffers live
    /// at the same time in one recording must have different labels.
    pub fn storage(&mut self, label: &'static str, bytes: u64) -> wgpu::Buffer {
        match self.scratch.as_deref_mut() {
            Some(s) => s.get(self.ctx, label, bytes),
            None => self.ctx.storage(label, bytes),
        }
    }

    /// One compute pass running `entry` of `kernel`.
    pub fn dispatch(
        &mut self,
        kernel: &Kernel,
        entry: &'static str,
        bind: &wgpu::BindGroup,
        groups: [u32; 3],
    ) -> Result<(), GpuError> {
        let pipeline = kernel.pipeline(entry)?;
        let ts = match &mut self.timer {
            Some(t) if (t.labels.len() as u32 + 1) * 2 <= t.capacity => {
                let i = t.labels.len() as u32 * 2;
                t.labels.push(entry);
                Some(wgpu::ComputePassTimestampWrites {
                    query_set: &t.set,
                    beginning_of_pass_write_index: Some(i),
                    end_of_pass_write_index: Some(i + 1),
                })
            }
            _ => None,
        };
        let mut pass = self
            .encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(entry),
                timestamp_writes: ts,
            });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind, &[]);
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        Ok(())
    }

    /// Submit everything recorded and wait. Returns per-dispatch
    /// `(entry point, milliseconds)` when timing was on.
    pub fn finish(self) -> Result<Vec<(&'static str, f64)>, GpuError> {
        let Recorder {
            ctx,
            mut encoder,
            timer,
            ..
        } = self;
        let resolve = timer.as_ref().filter(|t| !t.labels.is_empty()).map(|t| {
            let n = t.labels.len() as u32 * 2;
            let buf = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: n as u64 * 8,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            encoder.resolve_query_set(&t.set, 0..n, &buf, 0);
            buf
        });
        ctx.queue.submit([encoder.finish()]);
        ctx.wait()?;
        let (Some(t), Some(buf)) = (timer, resolve) else {
            return Ok(Vec::new());
        };
        let stamps: Vec<u64> = ctx.read(&buf, t.labels.len() * 2)?;
        let period = ctx.queue.get_timestamp_period() as f64;
        Ok(t.labels
            .iter()
            .enumerate()
            .map(|(i, l)| {
                (
                    *l,
                    stamps[2 * i + 1].saturating_sub(stamps[2 * i]) as f64 * period * 1e-6,
                )
            })
            .collect())
    }
}
