//! Host for `shaders/splat/radix_sort.wgsl`: a stable GPU LSD radix sort of
//! `(u32 key, u32 value)` pairs, 4 bits per pass (count → scan → scatter).
//!
//! The splat pipeline uses it twice, as Brush's WGSL renderer did: once to
//! order splats by depth (32 key bits), then — after emitting one key per
//! (splat, tile) in depth order — a stable sort on the tile id only (just
//! enough bits for the tile count), which leaves every tile depth-sorted.
//! Reference: Merrill & Grimshaw, "High performance and scalable radix
//! sorting" (2011), in its simplest (non-fused) form.

use super::kernel::{Recorder, groups_1d, kernel};
use super::prefix_sum::{PrefixSum, ScanArgs};
use super::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup (= elements per block).
pub const WORKGROUP_SIZE: u32 = 256;
/// Key bits sorted per pass.
pub const BITS_PER_PASS: u32 = 4;
/// Digits per pass (`RADIX` in the shader).
pub const RADIX: u32 = 1 << BITS_PER_PASS;

/// Uniforms of one pass (16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct SortUniforms {
    pub n: u32,
    pub shift: u32,
    pub num_blocks: u32,
    /// `(1 << bits sorted in this pass) - 1`.
    pub digit_mask: u32,
}

kernel! {
    /// The compiled sort kernel.
    pub struct RadixSort;
    decl DECL = "radix_sort";
    bindings SortBindings {
        u: uniform SortUniforms,
        keys_in: read "array<u32>",
        values_in: read "array<u32>",
        keys_out: read_write "array<u32>",
        values_out: read_write "array<u32>",
        counts: read_write "array<u32>",
        offsets: read "array<u32>",
    }
    entry_points { count: [WORKGROUP_SIZE], scatter: [WORKGROUP_SIZE] }
    constants { WORKGROUP_SIZE, RADIX }
}

/// Arguments of one sort (in place on `keys` / `values`).
pub struct SortArgs<'a> {
    pub keys: &'a wgpu::Buffer,
    pub values: &'a wgpu::Buffer,
    /// Number of pairs.
    pub n: u32,
    /// Low key bits to sort on (1..=32); higher bits are ignored.
    pub bits: u32,
}

/// Key bits needed to sort values in `0..=max_key`.
pub fn bits_for(max_key: u32) -> u32 {
    (32 - max_key.leading_zeros()).max(1)
}

impl RadixSort {
    /// Record a stable sort of `args.keys[..n]` (with `args.values`) on the
    /// low `args.bits` key bits.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        scan: &PrefixSum,
        rec: &mut Recorder,
        args: &SortArgs,
    ) -> Result<(), GpuError> {
        if args.n <= 1 {
            return Ok(());
        }
        if args.bits == 0 || args.bits > 32 {
            return Err(GpuError::InvalidInput(format!(
                "radix sort on {} bits",
                args.bits
            )));
        }
        let n = args.n;
        let num_blocks = n.div_ceil(WORKGROUP_SIZE);
        let bytes = n as u64 * 4;
        let keys_tmp = rec.storage("sort_keys_tmp", bytes);
        let values_tmp = rec.storage("sort_values_tmp", bytes);
        let digits = num_blocks as u64 * RADIX as u64;
        let counts = rec.storage("sort_counts", digits * 4);
        let offsets = rec.storage("sort_offsets", (digits + 1) * 4);
        let passes = args.bits.div_ceil(BITS_PER_PASS);
        let groups = groups_1d(n, WORKGROUP_SIZE);
        for pass in 0..passes {
            let (ki, vi, ko, vo) = if pass % 2 == 0 {
                (args.keys, args.values, &keys_tmp, &values_tmp)
            } else {
                (&keys_tmp, &values_tmp, args.keys, args.values)
            };
            let shift = pass * BITS_PER_PASS;
            let pass_bits = (args.bits - shift).min(BITS_PER_PASS);
            let u = ctx.uniform(
                "sort_u",
                &SortUniforms {
                    n,
                    shift,
                    num_blocks,
                    digit_mask: (1 << pass_bits) - 1,
                },
            );
            let bind = self.bind(
                ctx,
                &SortBindings {
                    u: &u,
                    keys_in: ki,
                    values_in: vi,
                    keys_out: ko,
                    values_out: vo,
                    counts: &counts,
                    offsets: &offsets,
                },
            )?;
            rec.dispatch(&self.kernel, "count", &bind, groups)?;
            scan.dispatch(
                ctx,
                rec,
                &ScanArgs {
                    input: &counts,
                    output: &offsets,
                    n: num_blocks * RADIX,
                },
            )?;
            rec.dispatch(&self.kernel, "scatter", &bind, groups)?;
        }
        if passes % 2 == 1 {
            rec.encoder
                .copy_buffer_to_buffer(&keys_tmp, 0, args.keys, 0, bytes);
            rec.encoder
                .copy_buffer_to_buffer(&values_tmp, 0, args.values, 0, bytes);
        }
        Ok(())
    }
}
