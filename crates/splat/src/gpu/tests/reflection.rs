//! Every assembled shader (common code, injected constants and bindings,
//! kernel source) parses and validates with naga in every variant, and
//! matches its `kernel!` declaration: each `@group(0) @binding(n)` global is
//! the declared n-th binding (the `.wgsl` files declare none of their own),
//! the uniform struct has the Rust struct's name and byte size, and the
//! entry points are exactly the declared ones with the declared
//! `@workgroup_size`.

use crate::gpu::kernel::{BindingKind, shader_source};
use naga::{AddressSpace, StorageAccess, TypeInner};

/// Parse WGSL with naga and validate it with every capability; panics
/// naming `what` on either failure.
fn parse_and_validate(what: &str, src: &str) -> naga::Module {
    let module = naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("{what}: {}", e.emit_to_string(src)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{what}: {e:?}"));
    module
}

#[test]
fn shaders_match_host_declarations() {
    assert!(!crate::gpu::ALL_KERNELS.is_empty());
    for decl in crate::gpu::ALL_KERNELS {
        let variants: &[bool] = if decl.uses_grad_atomics {
            &[true, false]
        } else {
            &[false]
        };
        for (&float_atomics, subgroups) in variants.iter().flat_map(|a| [(a, false), (a, true)]) {
            let src = shader_source(decl, float_atomics, subgroups);
            let what = format!(
                "{} (float_atomics={float_atomics}, subgroups={subgroups})",
                decl.name
            );
            let module = parse_and_validate(&what, &src);
            let mut seen = 0;
            for (_, var) in module.global_variables.iter() {
                let Some(rb) = &var.binding else { continue };
                let name = var.name.clone().unwrap_or_default();
                assert_eq!(rb.group, 0, "{what}: {name} not in group 0");
                let b = decl
                    .bindings
                    .get(rb.binding as usize)
                    .unwrap_or_else(|| panic!("{what}: binding {} undeclared", rb.binding));
                assert_eq!(b.name, name, "{what}: binding {}", rb.binding);
                let kind = match var.space {
                    AddressSpace::Uniform => BindingKind::Uniform,
                    AddressSpace::Storage { access } if access.contains(StorageAccess::STORE) => {
                        BindingKind::StorageRw
                    }
                    // The uniform struct, bound read-only in storage where
                    // the kernel has room (`KernelDecl::uniform_in_storage`).
                    AddressSpace::Storage { .. }
                        if b.kind == BindingKind::Uniform && decl.uniform_in_storage() =>
                    {
                        BindingKind::Uniform
                    }
                    AddressSpace::Storage { .. } => BindingKind::StorageRead,
                    other => panic!("{what}: {name} has address space {other:?}"),
                };
                assert_eq!(b.kind, kind, "{what}: {name} access");
                if kind == BindingKind::Uniform {
                    assert_eq!(rb.binding, 0, "{what}: the uniform is binding 0");
                    let ty = &module.types[var.ty];
                    assert_eq!(ty.name.as_deref(), Some(b.ty), "{what}: uniform struct");
                    match &ty.inner {
                        TypeInner::Struct { span, .. } => assert_eq!(
                            *span as usize, decl.uniform_size,
                            "{what}: uniform {} size (WGSL vs Rust)",
                            b.ty
                        ),
                        other => panic!("{what}: uniform is {other:?}"),
                    }
                }
                seen += 1;
            }
            assert_eq!(seen, decl.bindings.len(), "{what}: bindings in the shader");
            assert_eq!(
                module.entry_points.len(),
                decl.entry_points.len(),
                "{what}: entry points"
            );
            for ep in decl.entry_points {
                let found = module
                    .entry_points
                    .iter()
                    .find(|e| e.name == ep.name)
                    .unwrap_or_else(|| panic!("{what}: entry point {} missing", ep.name));
                assert_eq!(
                    found.workgroup_size, ep.workgroup_size,
                    "{what}: @workgroup_size of {} (shader vs host)",
                    ep.name
                );
            }
        }
    }
}

/// Storage buffers per shader stage that wgpu's GL fallback on llvmpipe
/// allows (`Limits::max_storage_buffers_per_shader_stage` there), the
/// tightest adapter the trainer supports.
const GL_MAX_STORAGE_BUFFERS: usize = 8;

#[test]
fn every_kernel_binds_at_most_the_gl_storage_buffer_limit() {
    for decl in crate::gpu::ALL_KERNELS {
        let declared = decl
            .bindings
            .iter()
            .filter(|b| b.kind != BindingKind::Uniform)
            .count();
        assert!(
            declared <= GL_MAX_STORAGE_BUFFERS,
            "{}: {declared} storage buffers declared",
            decl.name
        );
        // And what the shader itself binds (every entry point shares group 0).
        let src = shader_source(decl, false, false);
        let module = naga::front::wgsl::parse_str(&src).unwrap();
        let in_shader = module
            .global_variables
            .iter()
            .filter(|(_, v)| v.binding.is_some() && matches!(v.space, AddressSpace::Storage { .. }))
            .count();
        assert!(
            in_shader <= GL_MAX_STORAGE_BUFFERS,
            "{}: {in_shader} storage buffers in the shader",
            decl.name
        );
    }
}

/// The 16-column (one list per tile) variant of the gradient kernels, used
/// on adapters whose subgroups may exceed 8 lanes, validates too.
#[test]
fn wide_subgroup_list_variant_validates() {
    for decl in crate::gpu::ALL_KERNELS
        .iter()
        .filter(|d| d.uses_grad_atomics)
    {
        for float_atomics in [true, false] {
            let src = crate::gpu::kernel::shader_source_cols(decl, float_atomics, true, 16, 1);
            parse_and_validate(decl.name, &src);
        }
    }
}

/// The rasterizers' 8-lane list walk (`kernel::lane_wgsl`, subgroup
/// broadcasts) validates in every atomics variant.
#[test]
fn lane_chunk_variant_validates() {
    let decls: Vec<_> = crate::gpu::ALL_KERNELS
        .iter()
        .filter(|d| crate::gpu::kernel::uses_block_lists(d))
        .collect();
    assert_eq!(decls.len(), 2, "rasterize and rasterize_backward");
    for decl in decls {
        for float_atomics in [true, false] {
            let src = crate::gpu::kernel::shader_source_cols(decl, float_atomics, true, 8, 8);
            parse_and_validate(decl.name, &src);
        }
    }
}
