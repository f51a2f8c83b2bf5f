//! One source of truth for GPU layouts: the Rust structs. This test parses the WGSL with naga
//! (the compiler wgpu itself uses) and checks that every shared struct has the same size and
//! the same fields at the same offsets as its Rust twin. Needs no GPU.

use std::mem::{offset_of, size_of};

use gridtrace::accel::{Cell, TriAccel};
use gridtrace::gpu::bindings::{self, Access};
use gridtrace::gpu::layout::{GpuHit, GpuMaterial, IndirectArgs, PassUniform, RayRec, SceneUniform, TriShade};
use gridtrace::gpu::shaders;
use gridtrace::scene::{CameraFrame, PointLight};
use wgpu::naga;

fn module() -> naga::Module {
    naga::front::wgsl::parse_str(&shaders::common_source()).expect("common.wgsl parses")
}

/// (size, [(field, offset)]) of a WGSL struct.
fn wgsl_struct(m: &naga::Module, name: &str) -> (u32, Vec<(String, u32)>) {
    for (_, ty) in m.types.iter() {
        if ty.name.as_deref() == Some(name) {
            if let naga::TypeInner::Struct { members, span } = &ty.inner {
                return (
                    *span,
                    members
                        .iter()
                        .map(|mb| (mb.name.clone().unwrap_or_default(), mb.offset))
                        .collect(),
                );
            }
        }
    }
    panic!("struct {name} not found in common.wgsl");
}

macro_rules! check {
    ($m:expr, $ty:ty, $wgsl:literal, [$($field:ident),* $(,)?]) => {{
        let (size, members) = wgsl_struct(&$m, $wgsl);
        let rust: Vec<(String, u32)> = vec![$((stringify!($field).to_string(), offset_of!($ty, $field) as u32)),*];
        assert_eq!(members, rust, "{}: WGSL fields/offsets differ from Rust", $wgsl);
        assert_eq!(size as usize, size_of::<$ty>(), "{}: WGSL size differs from Rust", $wgsl);
    }};
}

#[test]
fn wgsl_structs_match_rust() {
    let m = module();
    check!(m, Cell, "Cell", [start, count, dist]);
    check!(m, TriAccel, "TriAccel", [v0, e1, e2]);
    check!(m, TriShade, "TriShade", [n0, n1, n2, material]);
    check!(m, GpuMaterial, "GpuMaterial", [diffuse, reflectivity]);
    check!(m, PointLight, "PointLight", [position, _pad0, intensity, _pad1]);
    check!(m, RayRec, "RayRec", [origin, pixel, dir, t_max, weight, t_min]);
    check!(m, GpuHit, "GpuHit", [t, tri, u, v]);
    check!(
        m,
        SceneUniform,
        "SceneUniform",
        [
            bounds_min,
            ray_epsilon,
            bounds_max,
            n_lights,
            cell_size,
            n_tris,
            inv_cell_size,
            _pad0,
            dims,
            _pad1,
            background,
            _pad2,
            ambient,
            _pad3
        ]
    );
    check!(
        m,
        CameraFrame,
        "CameraFrame",
        [eye, width, forward, height, right_scaled, _pad0, up_scaled, _pad1]
    );
    check!(m, IndirectArgs, "IndirectArgs", [rays, shadow]);
    check!(
        m,
        PassUniform,
        "PassUniform",
        [
            depth,
            in_slot,
            out_slot,
            tile_offset,
            tile_pixels,
            mode,
            accel,
            max_depth
        ]
    );
}

/// The check itself must catch a mismatch.
#[test]
fn mismatch_is_detected() {
    let src = shaders::common_source().replace(
        "struct Cell { start: u32, count: u32, dist: u32 }",
        "struct Cell { count: u32, start: u32, dist: u32 }",
    );
    assert_ne!(src, shaders::common_source());
    let m = naga::front::wgsl::parse_str(&src).unwrap();
    let r = std::panic::catch_unwind(|| check!(m, Cell, "Cell", [start, count, dist]));
    assert!(r.is_err());
}

/// Every kernel compiles and validates as its own module (common + kernel).
#[test]
fn kernels_validate() {
    for (name, src) in shaders::KERNELS {
        let m = naga::front::wgsl::parse_str(&shaders::module_source(src)).unwrap_or_else(|e| panic!("{name}: {e}"));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
            .validate(&m)
            .unwrap_or_else(|e| panic!("{name}: {e:?}"));
    }
}

/// The bind group tables are what the WGSL declares: same (group, binding, name, access), no
/// binding missing from either side.
#[test]
fn bindings_match_wgsl() {
    let mut declared = std::collections::BTreeSet::new();
    for (name, src) in shaders::KERNELS {
        let m = naga::front::wgsl::parse_str(&shaders::module_source(src)).unwrap_or_else(|e| panic!("{name}: {e}"));
        for (_, g) in m.global_variables.iter() {
            let Some(b) = &g.binding else { continue };
            let access = match g.space {
                naga::AddressSpace::Uniform => "uniform",
                naga::AddressSpace::Storage { access } if access.contains(naga::StorageAccess::STORE) => "read_write",
                naga::AddressSpace::Storage { .. } => "read",
                _ => "other",
            };
            declared.insert((b.group, b.binding, g.name.clone().unwrap_or_default(), access));
        }
    }
    let table: std::collections::BTreeSet<_> = bindings::all()
        .into_iter()
        .map(|(group, index, name, access)| {
            let access = match access {
                Access::Uniform => "uniform",
                Access::StorageRead => "read",
                Access::StorageReadWrite => "read_write",
            };
            (group, index, name.to_string(), access)
        })
        .collect();
    assert_eq!(declared, table);
}
