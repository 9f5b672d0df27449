//! GPU tests. They skip (with a message) only when no adapter exists and the
//! `CI` environment variable is unset; under CI a missing adapter fails.

mod backward;
mod binning;
mod forward;
mod fuzz;
mod reflection;
mod scenes;
mod train_step;

use super::{GpuContext, GpuError, GpuOptions};
use std::sync::OnceLock;

fn open(opts: &GpuOptions) -> Option<GpuContext> {
    match GpuContext::new(opts) {
        Ok(c) => Some(c),
        Err(GpuError::NoAdapter) if std::env::var_os("CI").is_none() => {
            eprintln!("skipping GPU test: no adapter (set CI to make this fail)");
            None
        }
        Err(e) => panic!("GPU context: {e}"),
    }
}

/// Shared context using float atomics when the adapter has them.
pub(crate) fn ctx() -> Option<&'static GpuContext> {
    static C: OnceLock<Option<GpuContext>> = OnceLock::new();
    C.get_or_init(|| {
        open(&GpuOptions {
            force_cas_atomics: false,
            no_subgroups: false,
            timestamps: true,
            wide_lists: false,
        })
    })
    .as_ref()
}

/// Shared context forced onto the compare-and-swap atomics path without
/// subgroup reductions (the GL / no-subgroup path).
pub(crate) fn ctx_cas() -> Option<&'static GpuContext> {
    static C: OnceLock<Option<GpuContext>> = OnceLock::new();
    C.get_or_init(|| {
        open(&GpuOptions {
            force_cas_atomics: true,
            no_subgroups: true,
            timestamps: false,
            wide_lists: false,
        })
    })
    .as_ref()
}

/// Shared context with subgroups on but one `rasterize_backward` splat list
/// per tile (the path adapters with subgroups wider than 8 lanes take).
pub(crate) fn ctx_wide_lists() -> Option<&'static GpuContext> {
    static C: OnceLock<Option<GpuContext>> = OnceLock::new();
    C.get_or_init(|| {
        open(&GpuOptions {
            force_cas_atomics: false,
            no_subgroups: false,
            timestamps: false,
            wide_lists: true,
        })
    })
    .as_ref()
}
