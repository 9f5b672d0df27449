//! Host for `shaders/splat/emit_keys.wgsl`: tile binning of projected splats
//! (depth keys for the depth sort, tile counts in depth order, one
//! `(tile id, splat index)` pair per touched 16×16 tile). The tile rectangle
//! comes from `tile_rect` in `common.wgsl`, shared by counting and emission.
//! Reference: Kerbl et al., "3D Gaussian Splatting" (2023), §6 (tile binning).

use super::kernel::{BindingDecl, BindingKind, Kernel, KernelDecl, Recorder, groups_1d};
use super::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup.
pub const WORKGROUP_SIZE: u32 = 256;

/// Uniforms (16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct BinUniforms {
    /// Number of splats.
    pub n: u32,
    pub grid_x: u32,
    pub grid_y: u32,
    pub pad: u32,
}

pub static DECL: KernelDecl = KernelDecl {
    name: "emit_keys",
    source: include_str!("../../../../shaders/splat/emit_keys.wgsl"),
    entry_points: &["depth_keys", "gather_counts", "emit"],
    bindings: &[
        BindingDecl {
            name: "u",
            binding: 0,
            kind: BindingKind::Uniform,
        },
        BindingDecl {
            name: "projected",
            binding: 1,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "depth_keys_out",
            binding: 2,
            kind: BindingKind::StorageRw,
        },
        BindingDecl {
            name: "order",
            binding: 3,
            kind: BindingKind::StorageRw,
        },
        BindingDecl {
            name: "counts",
            binding: 4,
            kind: BindingKind::StorageRw,
        },
        BindingDecl {
            name: "offsets",
            binding: 5,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "tile_keys",
            binding: 6,
            kind: BindingKind::StorageRw,
        },
        BindingDecl {
            name: "tile_values",
            binding: 7,
            kind: BindingKind::StorageRw,
        },
    ],
    uniform: Some(("BinUniforms", std::mem::size_of::<BinUniforms>())),
    uses_grad_atomics: false,
};

/// Buffers of one binning step (bound by name).
pub struct EmitArgs<'a> {
    pub uniforms: &'a wgpu::Buffer,
    pub projected: &'a wgpu::Buffer,
    pub depth_keys: &'a wgpu::Buffer,
    pub order: &'a wgpu::Buffer,
    pub counts: &'a wgpu::Buffer,
    pub offsets: &'a wgpu::Buffer,
    pub tile_keys: &'a wgpu::Buffer,
    pub tile_values: &'a wgpu::Buffer,
    /// Number of splats.
    pub n: u32,
}

/// The compiled binning kernel.
pub struct EmitKeys {
    kernel: Kernel,
}

impl EmitKeys {
    pub fn new(ctx: &GpuContext) -> Self {
        EmitKeys {
            kernel: Kernel::new(ctx, &DECL),
        }
    }

    fn bind(&self, ctx: &GpuContext, a: &EmitArgs) -> Result<wgpu::BindGroup, GpuError> {
        self.kernel.bind(
            ctx,
            &[
                ("u", a.uniforms),
                ("projected", a.projected),
                ("depth_keys_out", a.depth_keys),
                ("order", a.order),
                ("counts", a.counts),
                ("offsets", a.offsets),
                ("tile_keys", a.tile_keys),
                ("tile_values", a.tile_values),
            ],
        )
    }

    /// Record `entry` ("depth_keys", "gather_counts" or "emit") over all splats.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        entry: &'static str,
        args: &EmitArgs,
    ) -> Result<(), GpuError> {
        let bind = self.bind(ctx, args)?;
        rec.dispatch(
            &self.kernel,
            entry,
            &bind,
            groups_1d(args.n, WORKGROUP_SIZE),
        )
    }
}
