//! How the C allocator hands memory back to the kernel.
//!
//! The mask stage frees and allocates planes of 0.1–2 MB per pair and
//! stage (flow pyramids, label maps, the cut's graph). glibc's malloc
//! serves blocks above its mmap threshold (128 KB at first, raised as such
//! blocks are freed) with fresh `mmap`s, and returns the free top of its
//! heaps to the kernel once it exceeds the trim threshold (twice the mmap
//! threshold). Every new plane then costs page faults and the kernel's
//! zeroing of its pages: 5–6% of the mask stage's `perf` samples on the
//! 2-core machine (`exc_page_fault`, `clear_page_erms`, `memset`).
//! [`keep_freed_memory`] keeps freed memory for reuse instead; the mask
//! stage releases it when it ends ([`release_freed_memory`]), so its planes
//! do not stay resident through COLMAP and training in `run`, `demo` and
//! `onthego`.
//!
//! Measured in `docs/results.md` ("glibc's malloc thresholds"): the mask
//! stage 8% faster at the same peak memory.

/// Blocks up to this size come from the heap, never from their own `mmap`
/// (glibc's largest allowed value on 64-bit targets: half of its 64 MB heap).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MMAP_THRESHOLD: i32 = 32 << 20;

/// Free memory at a heap's top is returned to the kernel only above this.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const TRIM_THRESHOLD: i32 = 1 << 30;

/// Fixes glibc's mmap and trim thresholds (module docs); true when glibc
/// took both. Without glibc (musl, other systems) nothing changes: false.
pub fn keep_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` only sets the allocator's parameters, under its own
    // lock; it takes plain integers and touches no memory of ours.
    #[allow(unsafe_code)]
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
            && libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    false
}

/// Returns the heaps' free memory to the kernel (`malloc_trim`), as the
/// default thresholds would have as it was freed.
pub fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` only releases free pages of the allocator's own
    // heaps, under its locks; live allocations are untouched.
    #[allow(unsafe_code)]
    unsafe {
        libc::malloc_trim(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[test]
    fn glibc_takes_both_thresholds() {
        // glibc refuses an mmap threshold over half its heap size; ours is
        // the largest it allows.
        assert!(keep_freed_memory());
    }
}
