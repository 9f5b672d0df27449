//! Host for `shaders/splat/prefix_sum.wgsl`: exclusive scan of `u32` on the
//! GPU (block scan in workgroup memory + recursive scan of block totals), used
//! for per-splat tile counts → key offsets and for radix-sort digit offsets.
//! Reference: Blelloch, "Prefix sums and their applications" (1990); the
//! per-block scan is Hillis–Steele.

use super::kernel::{Recorder, groups_1d, kernel};
use super::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup (= elements per block).
pub const WORKGROUP_SIZE: u32 = 256;

/// Uniforms of the scan (16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct ScanUniforms {
    pub n: u32,
    pub pad: [u32; 3],
}

kernel! {
    /// The compiled scan kernel.
    pub struct PrefixSum;
    decl DECL = "prefix_sum";
    bindings ScanBindings {
        u: uniform ScanUniforms,
        input: read "array<u32>",
        output: read_write "array<u32>",
        block_sums: read_write "array<u32>",
    }
    entry_points {
        scan_blocks: [WORKGROUP_SIZE],
        add_block_offsets: [WORKGROUP_SIZE],
        write_total: [1],
    }
    constants { WORKGROUP_SIZE }
}

/// Arguments of one scan.
pub struct ScanArgs<'a> {
    /// `n` input values.
    pub input: &'a wgpu::Buffer,
    /// At least `n + 1` values: exclusive scan in `[0, n)`, total at `[n]`.
    pub output: &'a wgpu::Buffer,
    /// Number of elements.
    pub n: u32,
}

impl PrefixSum {
    /// Record an exclusive scan of `args.input[..n]` into `args.output`.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        args: &ScanArgs,
    ) -> Result<(), GpuError> {
        self.dispatch_level(ctx, rec, args, 0)
    }

    /// One level of the recursive scan (`level` picks the scratch buffers,
    /// which are live at the same time across levels).
    fn dispatch_level(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        args: &ScanArgs,
        level: usize,
    ) -> Result<(), GpuError> {
        const SUMS: [&str; 5] = [
            "scan_block_sums0",
            "scan_block_sums1",
            "scan_block_sums2",
            "scan_block_sums3",
            "scan_block_sums4",
        ];
        const SCANNED: [&str; 5] = [
            "scan_block_offsets0",
            "scan_block_offsets1",
            "scan_block_offsets2",
            "scan_block_offsets3",
            "scan_block_offsets4",
        ];
        let n = args.n;
        let blocks = n.div_ceil(WORKGROUP_SIZE).max(1);
        // 256^4 > u32::MAX elements: four levels always suffice.
        let lv = level.min(SUMS.len() - 1);
        let sums = rec.storage(SUMS[lv], (blocks as u64 + 1) * 4);
        let u = ctx.uniform("scan_u", &ScanUniforms { n, pad: [0; 3] });
        let bind = self.bind(
            ctx,
            &ScanBindings {
                u: &u,
                input: args.input,
                output: args.output,
                block_sums: &sums,
            },
        )?;
        let groups = groups_1d(n, WORKGROUP_SIZE);
        if n > 0 {
            rec.dispatch(&self.kernel, "scan_blocks", &bind, groups)?;
        }
        if blocks > 1 {
            let scanned = rec.storage(SCANNED[lv], (blocks as u64 + 1) * 4);
            self.dispatch_level(
                ctx,
                rec,
                &ScanArgs {
                    input: &sums,
                    output: &scanned,
                    n: blocks,
                },
                level + 1,
            )?;
            let bind2 = self.bind(
                ctx,
                &ScanBindings {
                    u: &u,
                    input: args.input,
                    output: args.output,
                    block_sums: &scanned,
                },
            )?;
            rec.dispatch(&self.kernel, "add_block_offsets", &bind2, groups)?;
        }
        rec.dispatch(&self.kernel, "write_total", &bind, [1, 1, 1])
    }
}
