//! Every pipeline's spec (`Kernel` order): its source, overrides, launch and group 1. Apart from
//! kernels.rs so that the table a new kernel joins is one place.

use super::super::shaders;
use super::{Group1, Kernel, KernelSpec, Launch};
use crate::gpu::layout::IndirectArgs;

const RAY_QUEUE: Launch = Launch::Indirect {
    offset_bytes: IndirectArgs::RAYS_OFFSET,
};
const SHADOW_QUEUE: Launch = Launch::Indirect {
    offset_bytes: IndirectArgs::SHADOW_OFFSET,
};

const fn spec(kernel: Kernel, label: &'static str, stage: &'static str, source: &'static str) -> KernelSpec {
    KernelSpec {
        kernel,
        walks: false,
        label,
        stage,
        source,
        overrides: &[],
        launch: RAY_QUEUE,
        group1: Group1::None,
    }
}

/// Every pipeline, in `Kernel` order (`kernel as usize` indexes it; a test checks).
pub(super) const SPECS: [KernelSpec; 16] = [
    KernelSpec {
        launch: Launch::PerPixel,
        ..spec(Kernel::Raygen, "raygen", "raygen", shaders::RAYGEN)
    },
    KernelSpec {
        walks: true,
        ..spec(Kernel::Traverse, "traverse", "traverse", shaders::TRAVERSE)
    },
    KernelSpec {
        walks: true,
        overrides: &[("COUNT_WORK", 1.0)],
        ..spec(Kernel::TraverseHeat, "traverse (heat)", "traverse", shaders::TRAVERSE)
    },
    KernelSpec {
        walks: true,
        launch: SHADOW_QUEUE,
        ..spec(Kernel::Occlusion, "occlusion", "occlusion", shaders::OCCLUSION)
    },
    spec(Kernel::Shade, "shade", "shade", shaders::SHADE),
    spec(Kernel::Resolve, "resolve", "resolve", shaders::RESOLVE),
    KernelSpec {
        launch: Launch::Once,
        group1: Group1::IndirectArgs,
        ..spec(Kernel::Indirect, "indirect", "indirect", shaders::INDIRECT)
    },
    KernelSpec {
        walks: true,
        launch: SHADOW_QUEUE,
        overrides: &[("SHADOW_CLOSEST", 1.0)],
        ..spec(
            Kernel::OcclusionClosest,
            "occlusion (closest hit)",
            "occlusion",
            shaders::OCCLUSION,
        )
    },
    KernelSpec {
        launch: Launch::PerPixel,
        group1: Group1::Packed,
        ..spec(Kernel::Pack, "pack", "pack", shaders::PACK)
    },
    KernelSpec {
        walks: true,
        ..spec(
            Kernel::ClosestPoint,
            "closest point",
            "closest point",
            shaders::CLOSEST_POINT,
        )
    },
    KernelSpec {
        launch: Launch::PerPixel,
        group1: Group1::Batch,
        ..spec(Kernel::BatchRays, "batch rays", "batch in", shaders::BATCH)
    },
    KernelSpec {
        launch: Launch::PerPixel,
        group1: Group1::Batch,
        overrides: &[("BATCH_ANSWERS", 1.0)],
        ..spec(Kernel::BatchAnswers, "batch answers", "batch out", shaders::BATCH)
    },
    KernelSpec {
        walks: true,
        group1: Group1::Batch,
        overrides: &[("NEXT_HIT", 1.0)],
        ..spec(Kernel::AllHits, "all hits (counts)", "all hits", shaders::ALL_HITS)
    },
    KernelSpec {
        walks: true,
        group1: Group1::Batch,
        overrides: &[("NEXT_HIT", 1.0), ("ALL_HITS_LIST", 1.0)],
        ..spec(Kernel::AllHitsList, "all hits (lists)", "all hits", shaders::ALL_HITS)
    },
    KernelSpec {
        launch: Launch::Once,
        group1: Group1::Batch,
        ..spec(Kernel::PrefixSum, "prefix sum", "prefix sum", shaders::PREFIX_SUM)
    },
    KernelSpec {
        group1: Group1::BatchWinding,
        ..spec(Kernel::Winding, "winding", "winding", shaders::WINDING)
    },
];
