//! Every shader parses and validates with naga (both atomics variants where
//! relevant), and its `@group(0) @binding(n)` globals match the host module's
//! declared table exactly: name, binding number, uniform vs storage,
//! read-only vs read-write, uniform struct name and byte size, entry points.

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
fn shaders_match_host_binding_tables() {
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
            let mut seen = Vec::new();
            for (_, var) in module.global_variables.iter() {
                let Some(rb) = &var.binding else { continue };
                let name = var.name.clone().unwrap_or_default();
                assert_eq!(rb.group, 0, "{}: {name} not in group 0", decl.name);
                let b = decl
                    .bindings
                    .iter()
                    .find(|b| b.name == name)
                    .unwrap_or_else(|| {
                        panic!(
                            "{}: shader binding {name} missing from host table",
                            decl.name
                        )
                    });
                assert_eq!(
                    b.binding, rb.binding,
                    "{}: {name} binding number",
                    decl.name
                );
                let kind = match var.space {
                    AddressSpace::Uniform => BindingKind::Uniform,
                    AddressSpace::Storage { access } if access.contains(StorageAccess::STORE) => {
                        BindingKind::StorageRw
                    }
                    AddressSpace::Storage { .. } => BindingKind::StorageRead,
                    other => panic!("{}: {name} has address space {other:?}", decl.name),
                };
                assert_eq!(b.kind, kind, "{}: {name} access", decl.name);
                if kind == BindingKind::Uniform {
                    let (uname, usize_) = decl
                        .uniform
                        .unwrap_or_else(|| panic!("{}: undeclared uniform", decl.name));
                    let ty = &module.types[var.ty];
                    assert_eq!(
                        ty.name.as_deref(),
                        Some(uname),
                        "{}: uniform struct name",
                        decl.name
                    );
                    match &ty.inner {
                        TypeInner::Struct { span, .. } => {
                            assert_eq!(
                                *span as usize, usize_,
                                "{}: uniform {uname} size",
                                decl.name
                            )
                        }
                        other => panic!("{}: uniform is {other:?}", decl.name),
                    }
                }
                seen.push(name);
            }
            for b in decl.bindings {
                assert!(
                    seen.iter().any(|s| s == b.name),
                    "{}: host binding {} not in shader",
                    decl.name,
                    b.name
                );
            }
            for ep in decl.entry_points {
                assert!(
                    module.entry_points.iter().any(|e| e.name == *ep),
                    "{}: entry point {ep} missing",
                    decl.name
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
            let src = crate::gpu::kernel::shader_source_cols(decl, float_atomics, true, 16);
            parse_and_validate(decl.name, &src);
        }
    }
}
