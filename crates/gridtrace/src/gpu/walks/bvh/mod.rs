//! The BVH on the GPU, in either layout the variants choose (`bvh=`, `gpu::variants`): the
//! binary nodes (`binary`: the CPU's binary SAH tree re-laid as two-child nodes, walked by
//! `bvh.wgsl`) or the 8-wide compressed nodes (`wide8`: the CPU's 8-wide tree quantized after
//! Ylitie et al. 2017, walked by `bvh8.wgsl`), each with either stack (`stack=`: a private
//! array or a short ring in workgroup memory, its own WGSL file after the walk's). Four walk
//! specs; `spec_for` picks one by the variants. The two variant keys are this structure's own:
//! their values (`BvhLayout`, `BvhStack`) are defined here and `gpu::variants` lists them.

pub mod binary;
pub mod wide8;

use crate::accel::StructureId;
use std::borrow::Cow;

use super::{Lattice, WalkSpec, WalkUpload, bytes};
use crate::accel::{Aabb, BvhAccel, TriAccel};
use crate::gpu::constants::WgslConst;
use crate::gpu::layout::GpuTri;
use crate::{Error, Result};

/// The BVH's GPU layout (`bvh=`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum BvhLayout {
    /// Two-child nodes with both boxes (64 bytes).
    #[default]
    Binary,
    /// Ylitie et al.'s 8-wide compressed nodes (80 bytes).
    Wide8,
}

/// Where the BVH walk keeps its stack (`stack=`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BvhStack {
    /// A private array of `BVH_STACK` entries.
    Private,
    /// A ring of this many entries in workgroup memory, with the parent-link fallback.
    Short(u8),
}

/// Entries of `stack=short`.
pub const SHORT_STACK_DEFAULT: u8 = 8;
/// Most entries a short stack may have (the workgroup array is this deep).
pub const SHORT_STACK_MAX: u8 = 16;

/// The BVH's walk as the GPU variants choose it (`GpuVariants::bvh_walk`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BvhWalk {
    pub layout: BvhLayout,
    pub stack: BvhStack,
}

/// Entries of the GPU BVH walk's stack: the CPU builder's bound on the tree's depth (`STACK`),
/// so that no tree can overflow it.
pub const BVH_STACK: u32 = crate::accel::bvh::STACK as u32;

/// The BVH walks' WGSL constants (in the prelude of every module: `walks::wgsl_prelude`).
pub(super) const WGSL_CONSTANTS: &[(&str, WgslConst)] = &[
    ("BVH_STACK", WgslConst::U32(BVH_STACK)),
    ("SHORT_STACK_MAX", WgslConst::U32(SHORT_STACK_MAX as u32)),
    ("LEAF_BIT", WgslConst::U32(binary::LEAF_BIT)),
    ("LEAF_COUNT_SHIFT", WgslConst::U32(binary::LEAF_COUNT_SHIFT)),
    ("LEAF_FIRST_MAX", WgslConst::U32(binary::LEAF_FIRST_MAX)),
    ("STACK_DONE", WgslConst::U32(binary::STACK_DONE)),
    ("DIR_TINY", WgslConst::F32(crate::accel::bvh::DIR_TINY)),
    ("FAR_SCALE", WgslConst::F32(crate::accel::bvh::FAR_SCALE)),
    ("T_SLOP", WgslConst::F32(crate::accel::bvh::T_SLOP)),
];

pub(super) const BINARY: &str = include_str!("bvh.wgsl");
pub(super) const BINARY_PRIVATE: &str = include_str!("bvh_stack_private.wgsl");
pub(super) const BINARY_SHORT: &str = include_str!("bvh_stack_short.wgsl");
pub(super) const WIDE8: &str = include_str!("bvh8.wgsl");
pub(super) const WIDE8_PRIVATE: &str = include_str!("bvh8_stack_private.wgsl");
pub(super) const WIDE8_SHORT: &str = include_str!("bvh8_stack_short.wgsl");

pub(super) const BINARY_ARRAYS: &[(&str, &str)] = &[
    ("bvh_nodes", "bvh_nodes"),
    ("refs", "bvh_prims"),
    ("leaf triangles", "bvh_tris"),
];
pub(super) const WIDE8_ARRAYS: &[(&str, &str)] = &[
    ("bvh8_nodes", "bvh8_nodes"),
    ("refs", "bvh8_prims"),
    ("leaf triangles", "bvh8_tris"),
];

/// Binary nodes, private stack (`stack=private`; the default is `SPEC_SHORT` since the H200 runs).
pub const SPEC: WalkSpec = WalkSpec {
    structure: StructureId::Bvh,
    name: "bvh",
    wgsl: &[BINARY, BINARY_PRIVATE],
    prefix: "bvh",
    arrays: BINARY_ARRAYS,
    device_build: false,
    tlas: None,
    software_max_tris: None,
    constants: WGSL_CONSTANTS,
    bottom: None,
};

/// Binary nodes, short stack.
pub const SPEC_SHORT: WalkSpec = WalkSpec {
    name: "bvh (short stack)",
    wgsl: &[BINARY, BINARY_SHORT],
    ..SPEC
};

/// 8-wide compressed nodes, private stack.
pub const SPEC_WIDE8: WalkSpec = WalkSpec {
    name: "bvh (wide8)",
    wgsl: &[WIDE8, WIDE8_PRIVATE],
    prefix: "bvh8",
    arrays: WIDE8_ARRAYS,
    ..SPEC
};

/// 8-wide compressed nodes, short stack.
pub const SPEC_WIDE8_SHORT: WalkSpec = WalkSpec {
    name: "bvh (wide8, short stack)",
    wgsl: &[WIDE8, WIDE8_SHORT],
    ..SPEC_WIDE8
};

/// The BVH's walk for `walk`.
pub fn spec_for(walk: BvhWalk) -> &'static WalkSpec {
    match (walk.layout, walk.stack) {
        (BvhLayout::Binary, BvhStack::Private) => &SPEC,
        (BvhLayout::Binary, BvhStack::Short(_)) => &SPEC_SHORT,
        (BvhLayout::Wide8, BvhStack::Private) => &SPEC_WIDE8,
        (BvhLayout::Wide8, BvhStack::Short(_)) => &SPEC_WIDE8_SHORT,
    }
}

/// The BVH's arrays for `walk`: its nodes, its triangle references in leaf order, and the
/// triangles themselves in that order (`GpuTri`, 48 bytes a reference), so that a leaf's
/// triangles are read one after another and the reference only for a hit.
pub fn upload<'a>(b: &'a BvhAccel, tris: &[TriAccel], bounds: Aabb, walk: BvhWalk) -> Result<WalkUpload<'a>> {
    if b.bvh.depth >= BVH_STACK as usize {
        // The builder bounds the depth below the stack (`STACK`); checked all the same, since
        // an overflow would lose hits silently.
        return Err(Error::InvalidInput(format!(
            "the BVH is {} levels deep; the GPU walk's stack holds {BVH_STACK}",
            b.bvh.depth
        )));
    }
    let spec = spec_for(walk);
    let arrays = match walk.layout {
        BvhLayout::Binary => {
            let nodes = binary::gpu_nodes(&b.bvh)?;
            vec![
                Cow::Owned(bytemuck::cast_slice(&nodes).to_vec()),
                bytes(&b.bvh.prims),
                leaf_tris(tris, &b.bvh.prims),
            ]
        }
        BvhLayout::Wide8 => {
            let w = wide8::Wide8::build(b)?;
            vec![
                Cow::Owned(bytemuck::cast_slice(&w.nodes).to_vec()),
                Cow::Owned(bytemuck::cast_slice(&w.prims).to_vec()),
                leaf_tris(tris, &w.prims),
            ]
        }
    };
    Ok(WalkUpload {
        spec,
        arrays,
        // The walk reads only the bounds (ray generation clips to them).
        lattice: Lattice::bounds_only(bounds),
    })
}

/// The triangles `prims` names, in its order, as the GPU reads them.
fn leaf_tris<'a>(tris: &[TriAccel], prims: &[u32]) -> Cow<'a, [u8]> {
    let leaf: Vec<GpuTri> = prims.iter().map(|&p| GpuTri::new(&tris[p as usize])).collect();
    Cow::Owned(bytemuck::cast_slice(&leaf).to_vec())
}
