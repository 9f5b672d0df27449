//! Run-time instruction-set dispatch for the flow kernels (and the LMedS
//! residuals, the Gaussian blur and the MLP's training and prediction,
//! which use it too). The release build
//! targets baseline x86-64 (SSE2, 4 lanes), so the 8-wide loops of the
//! patch search, the densification, the variational refinement and the
//! SOR solver would run at half width. Each hot function is declared
//! through [`multiversion!`], which compiles its body a second time with
//! AVX2 enabled (closures inside the body, e.g. the per-row bodies handed
//! to rayon, inherit that) and picks the copy at run time. Only the vector
//! width changes: Rust never contracts `a * b + c` into a fused
//! multiply–add or reorders floating-point arithmetic, so both copies
//! compute bit-identical results (tested in `dis`, `geometry::robust`,
//! `plane` and `mlp`).

use std::sync::atomic::{AtomicBool, Ordering};

/// When set, multiversioned functions take the baseline path.
static BASELINE_ONLY: AtomicBool = AtomicBool::new(false);

/// Force (or stop forcing) the baseline path process-wide (for tests and
/// benchmarks; results are identical either way).
pub fn force_baseline(on: bool) {
    BASELINE_ONLY.store(on, Ordering::Relaxed);
}

/// True when multiversioned functions take the AVX2 path on this CPU.
pub fn avx2_active() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        !BASELINE_ONLY.load(Ordering::Relaxed) && std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Declare a free function whose body is compiled twice, for baseline
/// x86-64 and with AVX2, and dispatched at run time by [`avx2_active`].
/// Arguments must be plain identifiers; const generics are supported.
macro_rules! multiversion {
    (
        $(#[$attr:meta])*
        $vis:vis fn $name:ident $(<$(const $g:ident: $gt:ty),* $(,)?>)?
        ($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)?
        $body:block
    ) => {
        $(#[$attr])*
        $vis fn $name $(<$(const $g: $gt),*>)? ($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                #[allow(clippy::too_many_arguments)]
                fn avx2 $(<$(const $g: $gt),*>)? ($($arg: $ty),*) $(-> $ret)? $body
                if $crate::flow::simd::avx2_active() {
                    // SAFETY: `avx2` only requires the AVX2 instruction
                    // set, which `avx2_active` just confirmed at run time.
                    #[allow(unsafe_code)]
                    return unsafe { avx2 $(::<$($g),*>)? ($($arg),*) };
                }
            }
            $body
        }
    };
}
pub(crate) use multiversion;
