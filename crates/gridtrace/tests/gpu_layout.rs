//! One source of truth for GPU layouts: the Rust structs. This test parses the WGSL with naga
//! (the compiler wgpu itself uses) and checks that every shared struct has the same size and
//! the same fields at the same offsets as its Rust twin. Needs no GPU.

use std::mem::{offset_of, size_of};

use gridtrace::accel::{Cell, IrrCell};
use gridtrace::gpu::bindings::{self, Access};
use gridtrace::gpu::constants::WgslConst;
use gridtrace::gpu::layout::{
    BatchUniform, GpuHit, GpuMaterial, GpuTri, IndirectArgs, PassUniform, RayRec, SceneUniform, TriShade,
};
use gridtrace::gpu::shaders;
use gridtrace::gpu::walks::bvh::binary::GpuBvhNode;
use gridtrace::gpu::walks::bvh::wide8::GpuBvh8Node;
use gridtrace::gpu::walks::two_level::{LatticeRow, TopRec};
use gridtrace::gpu::walks::{wgsl_constants, wgsl_prelude};
use gridtrace::scene::{CameraFrame, PointLight};
use wgpu::naga;

/// Every module the tracer compiles (each walk's in its own: walks of different structures may
/// define the same names).
fn modules() -> Vec<naga::Module> {
    shaders::all_modules()
        .iter()
        .map(|(name, src)| naga::front::wgsl::parse_str(src).unwrap_or_else(|e| panic!("{name}: {e}")))
        .collect()
}

/// (size, [(field, offset)]) of a WGSL struct, the same in every module of `ms` that declares it.
fn wgsl_struct(ms: &[naga::Module], name: &str) -> (u32, Vec<(String, u32)>) {
    let mut found: Option<(u32, Vec<(String, u32)>)> = None;
    for m in ms {
        for (_, ty) in m.types.iter() {
            if ty.name.as_deref() == Some(name)
                && let naga::TypeInner::Struct { members, span } = &ty.inner
            {
                let this = (
                    *span,
                    members
                        .iter()
                        .map(|mb| (mb.name.clone().unwrap_or_default(), mb.offset))
                        .collect::<Vec<_>>(),
                );
                match &found {
                    Some(first) => assert_eq!(first, &this, "{name} differs between modules"),
                    None => found = Some(this),
                }
            }
        }
    }
    found.unwrap_or_else(|| panic!("struct {name} not found in any module"))
}

macro_rules! check {
    ($m:expr, $ty:ty, $wgsl:literal, [$($field:ident),* $(,)?]) => {{
        let (size, members) = wgsl_struct(&$m, $wgsl);
        let rust: Vec<(String, u32)> = vec![$((stringify!($field).to_string(), offset_of!($ty, $field) as u32)),*];
        assert_eq!(members, rust, "{}: WGSL fields/offsets differ from Rust", $wgsl);
        assert_eq!(size as usize, size_of::<$ty>(), "{}: WGSL size differs from Rust", $wgsl);
    }};
}

/// The GPU grid build's modules declare their own structs (they do not include common.wgsl):
/// checked the same way, in every build kernel's module.
#[test]
fn grid_build_structs_match_rust() {
    use gridtrace::gpu::walks::grid::build::{GridBuildUniform, KERNEL_SOURCES, module_source};
    for kernel in KERNEL_SOURCES {
        let m = [naga::front::wgsl::parse_str(&module_source(kernel)).expect("build kernel parses")];
        check!(m, Cell, "Cell", [start, count, dist]);
        check!(m, GpuTri, "GpuTri", [v0, _pad0, v1, _pad1, v2, _pad2]);
        check!(
            m,
            GridBuildUniform,
            "GridBuildUniform",
            [
                bounds_min,
                n_tris,
                cell_size,
                n_cells,
                inv_cell_size,
                refs_capacity,
                margin,
                axis,
                dims,
                n,
                in_offset,
                out_offset,
                last,
                _pad0
            ]
        );
    }
}

#[test]
fn wgsl_structs_match_rust() {
    let m = modules();
    check!(m, Cell, "Cell", [start, count, dist]);
    check!(m, GpuTri, "GpuTri", [v0, _pad0, v1, _pad1, v2, _pad2]);
    check!(m, TriShade, "TriShade", [n0, n1, n2, material]);
    check!(m, GpuMaterial, "GpuMaterial", [diffuse, reflectivity]);
    check!(m, PointLight, "PointLight", [position, _pad0, intensity, _pad1]);
    check!(m, RayRec, "RayRec", [origin, pixel, dir, t_max, weight, t_min]);
    check!(m, GpuHit, "GpuHit", [t, tri, u, v]);
    check!(
        m,
        BatchUniform,
        "BatchUniform",
        [
            stride, to_shadow, t_min, t_max, mask, range_only, first, cells, cols, poses_at, pose_cols, _pad0
        ]
    );
    check!(m, TopRec, "TopRec", [a, b, c, w]);
    check!(
        m,
        LatticeRow,
        "Lattice",
        [
            lo, first_cell, hi, first_tri, cell, shift, inv_cell, first_map, dims, _pad1
        ]
    );
    check!(m, GpuBvhNode, "BvhNode", [xy0, xy1, z01, child]);
    check!(m, GpuBvh8Node, "Bvh8Node", [p_e, info, q0, q1, q2]);
    check!(m, IrrCell, "IrrCell", [bounds, start]);
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
            shift,
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
            max_depth,
            compact,
            _pad0,
            _pad1,
            _pad2
        ]
    );
}

/// The check itself must catch a mismatch.
#[test]
fn mismatch_is_detected() {
    let (_, grid) = shaders::all_modules()
        .into_iter()
        .find(|(name, _)| name == "closest point [grid]")
        .unwrap();
    let src = grid.replace(
        "struct Cell { start: u32, count: u32, dist: u32 }",
        "struct Cell { count: u32, start: u32, dist: u32 }",
    );
    assert_ne!(src, grid);
    let m = [naga::front::wgsl::parse_str(&src).unwrap()];
    let r = std::panic::catch_unwind(|| check!(m, Cell, "Cell", [start, count, dist]));
    assert!(r.is_err());
}

/// Every kernel compiles and validates as its own module (common + kernel): raygen, shade,
/// resolve, indirect, pack, batch, prefix sum and winding once, traverse, occlusion, all hits
/// and closest point once per structure, with its walk.
#[test]
fn kernels_validate() {
    let modules = shaders::all_modules();
    // Traverse, occlusion and all hits per walk, closest point per walk that searches points.
    let walking: usize = gridtrace::gpu::walks::WALKS
        .iter()
        .map(|w| 3 + w.points() as usize)
        .sum();
    assert_eq!(modules.len(), 8 + walking);
    for (name, src) in modules {
        let m = naga::front::wgsl::parse_str(&src).unwrap_or_else(|e| panic!("{name}: {e}"));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
            .validate(&m)
            .unwrap_or_else(|e| panic!("{name}: {e:?}"));
    }
}

/// The kernels that append, as `appends=subgroup` builds them (append_subgroup.wgsl), validate
/// with naga's subgroup capabilities: what an adapter with subgroups compiles, checked here
/// where lavapipe may have none.
#[test]
fn subgroup_append_modules_validate() {
    let variants: gridtrace::gpu::GpuVariants = "appends=subgroup".parse().unwrap();
    let mut swapped = 0;
    for (name, src) in shaders::KERNELS {
        let module = shaders::module_source_for(src, &variants);
        if module.contains("subgroupExclusiveAdd") {
            swapped += 1;
            assert!(!module.contains("wg_count"), "{name}: both appends");
        } else {
            assert_eq!(module, shaders::module_source(src), "{name}");
        }
        if shaders::walks(name) {
            continue;
        }
        let m = naga::front::wgsl::parse_str(&module).unwrap_or_else(|e| panic!("{name}: {e}"));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
            .validate(&m)
            .unwrap_or_else(|e| panic!("{name} (appends=subgroup): {e:?}"));
    }
    assert_eq!(swapped, 2, "raygen and shade append");
}

/// Every named constant of `m` that is in the Rust table, checked against it bit for bit:
/// one line per constant whose WGSL value differs (or is not a plain literal), and one per Rust
/// constant the module lacks.
fn constant_mismatches(m: &naga::Module) -> Vec<String> {
    let mut problems = Vec::new();
    for (name, want) in wgsl_constants() {
        let Some((_, c)) = m.constants.iter().find(|(_, c)| c.name.as_deref() == Some(name)) else {
            problems.push(format!("{name}: not declared in WGSL"));
            continue;
        };
        let got = match m.global_expressions[c.init] {
            naga::Expression::Literal(naga::Literal::U32(v)) => Some(WgslConst::U32(v)),
            naga::Expression::Literal(naga::Literal::F32(v)) => Some(WgslConst::F32(v)),
            _ => None,
        };
        let same = match (got, want) {
            (Some(WgslConst::U32(a)), WgslConst::U32(b)) => a == b,
            (Some(WgslConst::F32(a)), WgslConst::F32(b)) => a.to_bits() == b.to_bits(),
            _ => false,
        };
        if !same {
            problems.push(format!("{name}: WGSL {got:?}, Rust {want:?}"));
        }
    }
    problems
}

/// Single source for the shared numbers: in every kernel's module, naga's value of each prelude
/// constant is the Rust constant's, exactly.
#[test]
fn wgsl_constants_match_rust() {
    for (name, src) in shaders::all_modules() {
        let m = naga::front::wgsl::parse_str(&src).unwrap_or_else(|e| panic!("{name}: {e}"));
        let problems = constant_mismatches(&m);
        assert!(problems.is_empty(), "{name}: {problems:#?}");
    }
}

/// The comparison catches a prelude with one value altered: an integer, and a float by one ulp.
#[test]
fn altered_constant_is_reported() {
    let prelude = wgsl_prelude();
    let bary = wgsl_constants()
        .into_iter()
        .find_map(|(n, v)| match (n, v) {
            ("PARALLEL_COS2", WgslConst::F32(v)) => Some(v),
            _ => None,
        })
        .unwrap();
    let next_up = f32::from_bits(bary.to_bits() + 1);
    for (line, altered) in [
        (
            "const WORKGROUP: u32 = 64u;".to_string(),
            "const WORKGROUP: u32 = 65u;".to_string(),
        ),
        (
            format!("const PARALLEL_COS2: f32 = {bary:?}f;"),
            format!("const PARALLEL_COS2: f32 = {next_up:?}f;"),
        ),
    ] {
        assert!(prelude.contains(&line), "prelude lacks {line}:\n{prelude}");
        let src = format!("{}\n{}", prelude.replace(&line, &altered), shaders::COMMON);
        let m = naga::front::wgsl::parse_str(&src).unwrap();
        let problems = constant_mismatches(&m);
        let name = line.split(':').next().unwrap().trim_start_matches("const ");
        assert!(
            problems.len() == 1 && problems[0].starts_with(name),
            "{altered}: {problems:?}"
        );
    }
}

/// A WGSL file cannot declare a prelude name again: the module fails to compile, so a second
/// definition of a shared number cannot creep back into the shaders.
#[test]
fn redeclared_constant_fails() {
    for (name, _) in wgsl_constants() {
        let src = format!("{}\nconst {name}: u32 = 1u;\n", shaders::module_source(shaders::SHADE));
        let e = naga::front::wgsl::parse_str(&src).expect_err(name);
        assert!(
            e.emit_to_string(&src).contains("redefinition"),
            "{name}: {}",
            e.emit_to_string(&src)
        );
    }
}

/// The bind group tables are what the WGSL declares: same (group, binding, name, access), no
/// binding missing from either side; each structure's group 1 is its `WalkSpec::arrays`.
#[test]
fn bindings_match_wgsl() {
    let mut declared = std::collections::BTreeSet::new();
    for (name, src) in shaders::all_modules() {
        let m = naga::front::wgsl::parse_str(&src).unwrap_or_else(|e| panic!("{name}: {e}"));
        for (_, g) in m.global_variables.iter() {
            let Some(b) = &g.binding else { continue };
            let access = match g.space {
                naga::AddressSpace::Uniform => "uniform",
                naga::AddressSpace::Storage { access } if access.contains(naga::StorageAccess::STORE) => "read_write",
                naga::AddressSpace::Storage { .. } => "read",
                naga::AddressSpace::Handle
                    if matches!(m.types[g.ty].inner, naga::TypeInner::AccelerationStructure { .. }) =>
                {
                    "acceleration structure"
                }
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
        .chain(gridtrace::gpu::walks::WALKS.iter().flat_map(|w| {
            let arrays = w
                .arrays
                .iter()
                .enumerate()
                .map(|(i, (_, name))| (bindings::STRUCTURE_GROUP, i as u32, name.to_string(), "read"));
            // A walk by ray query binds its top-level structure after its arrays.
            let tlas = w.tlas.map(|name| {
                (
                    bindings::STRUCTURE_GROUP,
                    w.arrays.len() as u32,
                    name.to_string(),
                    "acceleration structure",
                )
            });
            arrays.chain(tlas)
        }))
        .collect();
    assert_eq!(declared, table);
}

/// Group 0's rows each module's entry point uses, by naga's analysis (the one wgpu checks a
/// pipeline's layout against): the (group 0) binding indices of the globals it reaches.
fn frame_bindings_used(src: &str, name: &str) -> Vec<u32> {
    let m = naga::front::wgsl::parse_str(src).unwrap_or_else(|e| panic!("{name}: {e}"));
    let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&m)
        .unwrap_or_else(|e| panic!("{name}: {e:?}"));
    let ep = m
        .entry_points
        .iter()
        .position(|e| e.name == "main")
        .expect("entry point main");
    let uses = info.get_entry_point(ep);
    let mut out: Vec<u32> = m
        .global_variables
        .iter()
        .filter(|(h, _)| !uses[*h].is_empty())
        .filter_map(|(_, g)| g.binding.as_ref())
        .filter(|b| b.group == bindings::FRAME_GROUP)
        .map(|b| b.binding)
        .collect();
    out.sort();
    out
}

/// Each kernel's group 0 (`bindings::FRAME_USE`) is exactly what its modules use: a row it lacks
/// would fail its pipeline's creation, one it has but never reads would count against WebGPU's
/// storage buffers a stage for nothing. A walking kernel's list is the union over the walks.
#[test]
fn each_kernel_binds_the_group_0_rows_it_uses() {
    let mut problems = Vec::new();
    for (name, src) in shaders::KERNELS {
        // Every kernel has its entry, its group 1 as it binds it (a walk's arrays at most).
        let (_, group1, _) = bindings::FRAME_USE
            .iter()
            .find(|(n, _, _)| *n == name)
            .unwrap_or_else(|| panic!("{name} has no FRAME_USE entry"));
        if shaders::walks(name) {
            // The all-hits kernels bind the batch's buffers too, after the structure's arrays.
            let batch = bindings::BATCH_BINDINGS
                .iter()
                .filter(|b| b.access != Access::Uniform)
                .count();
            let extra = if name == "all hits" { batch } else { 0 };
            assert_eq!(*group1, bindings::STRUCTURE_ARRAYS_MAX + extra, "{name}");
        }
        let modules: Vec<(String, String)> = if shaders::walks(name) {
            shaders::all_modules()
                .into_iter()
                .filter(|(n, _)| n.starts_with(&format!("{name} [")))
                .collect()
        } else {
            vec![(name.to_string(), shaders::module_source(src))]
        };
        assert!(!modules.is_empty(), "{name}");
        let mut union: Vec<u32> = Vec::new();
        for (module, src) in &modules {
            for b in frame_bindings_used(src, module) {
                if !union.contains(&b) {
                    union.push(b);
                }
            }
        }
        union.sort();
        let listed: Vec<u32> = bindings::frame_rows(name).iter().map(|b| b.index).collect();
        if union != listed {
            let names = |ix: &[u32]| -> Vec<&str> {
                ix.iter()
                    .map(|i| {
                        bindings::FRAME_BINDINGS
                            .iter()
                            .find(|b| b.index == *i)
                            .map_or("?", |b| b.name)
                    })
                    .collect()
            };
            problems.push(format!(
                "{name}: uses {:?}, FRAME_USE lists {:?}",
                names(&union),
                names(&listed)
            ));
        }
    }
    assert!(problems.is_empty(), "{problems:#?}");
}
