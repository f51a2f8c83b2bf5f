//! GPU variants: the choices the GPU literature disagrees with today's kernels on, each
//! switchable at run time (`--gpu-variant KEY=VALUE,...`, Python's `gpu_variant=`), so that one
//! hardware run can measure them all. Every value gives the same images and hits
//! (tests/gpu_variants.rs), so a variant is a speed choice only, and none is chosen on lavapipe
//! (it runs the shaders on the CPU and would pick the wrong ones). The defaults were chosen by
//! the hardware suite (`bench --suite hardware`, which runs `GpuVariants::suite()`) on an NVIDIA
//! H200 on 2026-11-26 (docs/benchmarks.md, "GPU hardware"): of the single changes from the
//! kernels as first written, a short stack, 8x8 tiles, workgroup appends and no statistics
//! atomics each made frames faster in two runs, and together they took frames' GPU time to
//! x0.74-0.86 (geomean per structure, never slower), ray batches x0.90-1.15 (the worst from one
//! sub-millisecond row). The 8-wide BVH
//! was 1.5x (frames) to 2.3x (ray batches) slower there and stays a variant; bounds checks
//! (x0.79-0.96 off) stay on, since they are what keeps a kernel bug from reading other memory.
//!
//! The choices, what the literature expects of them and why:
//! - `bvh=binary|wide8` (default `binary`): the BVH's GPU layout. `binary` is Aila and Laine's two-child node (64
//!   bytes: both child boxes). `wide8` is the 8-wide compressed node of Ylitie, Karras and Laine
//!   (HPG 2017), built from the CPU's 8-wide SAH tree: 80 bytes for eight children, boxes
//!   quantized to 8 bits per plane against a per-node grid, children visited in the ray's
//!   octant order. The paper finds it clearly faster than binary BVHs for incoherent rays on
//!   NVIDIA GPUs, from fewer node fetches and fewer bytes per ray (tray_racing's wgpu compute
//!   shader reaches 1.2-1.5 Grays/s on an RTX 4070 Ti with it, as issue 32 cites); the
//!   example `gpu_variant_work` (gridtrace-bench) counts both for our trees.
//! - `stack=short|private|shortN` (default `short`): where the BVH walk keeps its traversal stack. `private` is an
//!   array of `BVH_STACK` (97) entries per thread: local memory on GPUs (cached in L1, but
//!   naga zero-fills it per ray). `short` keeps the top 8 entries (`shortN`: N, 1..=16) in
//!   workgroup memory, a ring that drops its oldest entry when full; when it runs dry with
//!   entries dropped, the walk climbs the tree by parent links to the next unvisited sibling
//!   (the stackless fallback of Hapala et al. 2011), so no hit is lost. Short stacks in
//!   on-chip memory are what Ylitie et al. and most GPU walkers use: the top few entries take
//!   nearly every push and pop.
//! - `order=tiles|rows` (default `tiles`): which pixels a workgroup's 64 eye rays start from. `rows` is a 64x1
//!   strip; `tiles` an 8x8 square (inside each tile's whole-row part), so a warp's rays are
//!   coherent in two directions and share more nodes and cells (Aila and Laine 2009 trace
//!   primary rays in such tiles).
//! - `appends=workgroup|per_ray|subgroup` (default `workgroup`, which every adapter runs): how kernels append to the compacted queues.
//!   `per_ray` is one global `atomicAdd` per emitted ray; `workgroup` sums the workgroup's
//!   appends in workgroup memory and makes one global `atomicAdd` per workgroup and queue (the
//!   aggregation that CUDA compilers do for warps automatically and wavefront renderers do by
//!   hand), so contention on the counter drops 64-fold; `subgroup` does the same per subgroup
//!   (warp, wave) with subgroup operations (an exclusive prefix sum, one elected atomic, a
//!   broadcast), no workgroup memory and no barriers. It needs the adapter's subgroup
//!   operations (wgpu's `SUBGROUP` feature, which the context asks for where the adapter has
//!   it); on an adapter without them the variant is refused with an error naming it.
//! - `stats=off|on` (default `off`): `on` counts shadow and reflection rays with two more per-ray atomics in
//!   shading; `off` lets the one-invocation `indirect` kernel read the same totals off the
//!   queue lengths once per bounce (with compaction; without it the per-ray counts stay), so
//!   the ray counts are the same and the atomics are gone.
//! - `checks=on|off` (default `on`): `off` compiles the tracer's modules with `create_shader_module_trusted`
//!   (no bounds checks, no loop bounding; integer-division guards kept) and without zeroing
//!   workgroup memory: every index the kernels make is in bounds by construction (the SAFETY
//!   note in `kernels.rs`). Bounds checks cost a compare and select per storage access.

use std::fmt;
use std::str::FromStr;

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

/// Which pixels a workgroup's eye rays start from (`order=`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RayOrder {
    /// Row by row: a workgroup is a strip of 64 pixels.
    Rows,
    /// 8x8 squares.
    Tiles,
}

/// How queue appends reach the global counters (`appends=`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Appends {
    /// One global atomic per appended ray.
    PerRay,
    /// One global atomic per workgroup and queue, offsets handed out in workgroup memory.
    Workgroup,
    /// One global atomic per subgroup and queue, offsets from a subgroup prefix sum.
    Subgroup,
}

/// One choice of every GPU variant. `Default` is what the H200 runs chose (module docs);
/// `before_hardware` the kernels as first written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GpuVariants {
    pub bvh: BvhLayout,
    pub stack: BvhStack,
    pub order: RayOrder,
    pub appends: Appends,
    /// Per-ray statistics atomics in shading.
    pub stats: bool,
    /// Bounds checks and loop bounding in the shader modules.
    pub checks: bool,
}

impl Default for GpuVariants {
    fn default() -> Self {
        GpuVariants {
            bvh: BvhLayout::Binary,
            stack: BvhStack::Short(SHORT_STACK_DEFAULT),
            order: RayOrder::Tiles,
            appends: Appends::Workgroup,
            stats: false,
            checks: true,
        }
    }
}

/// Every key with its valid values, as errors list them.
const KEYS: [(&str, &str); 6] = [
    ("bvh", "binary|wide8"),
    ("stack", "short|private|shortN (N = 1..16)"),
    ("order", "tiles|rows"),
    ("appends", "workgroup|per_ray|subgroup"),
    ("stats", "off|on"),
    ("checks", "on|off"),
];

fn on_off(v: bool) -> &'static str {
    if v { "on" } else { "off" }
}

impl GpuVariants {
    /// What the hardware suite runs: the default, then each single change from it, then the
    /// kernels as first written (`before_hardware`), so that every run measures what the
    /// defaults gained on its GPU.
    pub fn suite() -> Vec<GpuVariants> {
        let d = GpuVariants::default();
        vec![
            d,
            GpuVariants {
                bvh: BvhLayout::Wide8,
                ..d
            },
            GpuVariants {
                stack: BvhStack::Private,
                ..d
            },
            GpuVariants {
                order: RayOrder::Rows,
                ..d
            },
            GpuVariants {
                appends: Appends::PerRay,
                ..d
            },
            GpuVariants {
                appends: Appends::Subgroup,
                ..d
            },
            GpuVariants { stats: true, ..d },
            GpuVariants { checks: false, ..d },
            GpuVariants::before_hardware(),
        ]
    }

    /// The kernels as first written, before any ran on a GPU: a private stack, rows, an atomic
    /// per appended ray, statistics atomics. The first H200 runs measured each of these against
    /// the others (module docs).
    pub fn before_hardware() -> GpuVariants {
        GpuVariants {
            bvh: BvhLayout::Binary,
            stack: BvhStack::Private,
            order: RayOrder::Rows,
            appends: Appends::PerRay,
            stats: true,
            checks: true,
        }
    }

    /// Whether the device of `ctx` can run these variants: `appends=subgroup` needs its
    /// subgroup operations. The error says which variant, which adapter and what to use.
    pub fn supported_on(&self, ctx: &super::GpuContext) -> Result<(), String> {
        if self.appends == Appends::Subgroup && !ctx.subgroups {
            return Err(format!(
                "the GPU variant appends=subgroup needs subgroup operations, which adapter '{}' does not offer \
                 (wgpu's SUBGROUP feature); use appends=workgroup",
                ctx.info.name
            ));
        }
        Ok(())
    }

    /// Only the keys that differ from the default (`default` when none): a short label.
    pub fn changes(&self) -> String {
        let d = GpuVariants::default().to_string();
        let own = self.to_string();
        let diff: Vec<&str> = own
            .split(',')
            .zip(d.split(','))
            .filter(|(a, b)| a != b)
            .map(|p| p.0)
            .collect();
        if diff.is_empty() {
            "default".to_string()
        } else {
            diff.join(",")
        }
    }

    /// Whether these variants change the walk of `structure` (the registry's structure name):
    /// the BVH's layout and stack apply to the BVH only.
    pub fn applies_to(&self, structure: &str) -> bool {
        let d = GpuVariants::default();
        let walk_only = self.bvh != d.bvh || self.stack != d.stack;
        let others = GpuVariants {
            bvh: d.bvh,
            stack: d.stack,
            ..*self
        } != d;
        others || (walk_only && structure == "bvh")
    }

    /// The pipeline-overridable constants these variants set (declared in common.wgsl): the same
    /// set for every pipeline, so that every kernel sees one consistent choice.
    pub fn overrides(&self) -> [(&'static str, f64); 4] {
        let short = match self.stack {
            BvhStack::Short(n) => n,
            BvhStack::Private => SHORT_STACK_DEFAULT,
        };
        [
            ("TILE_ORDER", (self.order == RayOrder::Tiles) as u8 as f64),
            ("WG_APPENDS", (self.appends == Appends::Workgroup) as u8 as f64),
            ("RAY_STATS", self.stats as u8 as f64),
            ("SHORT_STACK", short as f64),
        ]
    }
}

impl fmt::Display for GpuVariants {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let bvh = match self.bvh {
            BvhLayout::Binary => "binary",
            BvhLayout::Wide8 => "wide8",
        };
        let stack = match self.stack {
            BvhStack::Private => "private".to_string(),
            BvhStack::Short(SHORT_STACK_DEFAULT) => "short".to_string(),
            BvhStack::Short(n) => format!("short{n}"),
        };
        let order = match self.order {
            RayOrder::Rows => "rows",
            RayOrder::Tiles => "tiles",
        };
        let appends = match self.appends {
            Appends::PerRay => "per_ray",
            Appends::Workgroup => "workgroup",
            Appends::Subgroup => "subgroup",
        };
        write!(
            f,
            "bvh={bvh},stack={stack},order={order},appends={appends},stats={},checks={}",
            on_off(self.stats),
            on_off(self.checks)
        )
    }
}

impl FromStr for GpuVariants {
    type Err = String;

    /// `KEY=VALUE` pairs separated by commas, any subset in any order (the rest stay default);
    /// an empty string or `default` is the default.
    fn from_str(s: &str) -> Result<Self, String> {
        let mut v = GpuVariants::default();
        let s = s.trim();
        if s.is_empty() || s == "default" {
            return Ok(v);
        }
        let keys = || {
            KEYS.iter()
                .map(|(k, vals)| format!("{k}={vals}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        for pair in s.split(',').map(str::trim) {
            let Some((key, value)) = pair.split_once('=') else {
                return Err(format!("GPU variant '{pair}' is not KEY=VALUE; valid: {}", keys()));
            };
            let (key, value) = (key.trim(), value.trim());
            let Some(&(_, valid)) = KEYS.iter().find(|k| k.0 == key) else {
                return Err(format!("unknown GPU variant key '{key}'; valid: {}", keys()));
            };
            let bad = || format!("GPU variant {key}={value}: '{value}' is not one of {valid}");
            let flag = || match value {
                "on" => Ok(true),
                "off" => Ok(false),
                _ => Err(bad()),
            };
            match key {
                "bvh" => {
                    v.bvh = match value {
                        "binary" => BvhLayout::Binary,
                        "wide8" => BvhLayout::Wide8,
                        _ => return Err(bad()),
                    }
                }
                "stack" => {
                    v.stack = match value {
                        "private" => BvhStack::Private,
                        "short" => BvhStack::Short(SHORT_STACK_DEFAULT),
                        _ => match value.strip_prefix("short").map(str::parse::<u8>) {
                            Some(Ok(n)) if (1..=SHORT_STACK_MAX).contains(&n) => BvhStack::Short(n),
                            _ => return Err(bad()),
                        },
                    }
                }
                "order" => {
                    v.order = match value {
                        "rows" => RayOrder::Rows,
                        "tiles" => RayOrder::Tiles,
                        _ => return Err(bad()),
                    }
                }
                "appends" => {
                    v.appends = match value {
                        "per_ray" => Appends::PerRay,
                        "workgroup" => Appends::Workgroup,
                        "subgroup" => Appends::Subgroup,
                        _ => return Err(bad()),
                    }
                }
                "stats" => v.stats = flag()?,
                "checks" => v.checks = flag()?,
                _ => unreachable!("every key of KEYS has an arm"),
            }
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every value of every key parses and prints back to the same text; partial strings keep
    /// the other keys default; bad keys and values are errors that name them and the valid set.
    #[test]
    fn parse_and_print() {
        let d = GpuVariants::default();
        assert_eq!("".parse::<GpuVariants>().unwrap(), d);
        assert_eq!("default".parse::<GpuVariants>().unwrap(), d);
        assert_eq!(
            d.to_string(),
            "bvh=binary,stack=short,order=tiles,appends=workgroup,stats=off,checks=on"
        );
        assert_eq!(d.changes(), "default");
        let v: GpuVariants = "bvh=wide8, stack=short3,order=tiles,appends=workgroup,stats=off,checks=off"
            .parse()
            .unwrap();
        assert_eq!(
            v,
            GpuVariants {
                bvh: BvhLayout::Wide8,
                stack: BvhStack::Short(3),
                order: RayOrder::Tiles,
                appends: Appends::Workgroup,
                stats: false,
                checks: false,
            }
        );
        assert_eq!(v.to_string().parse::<GpuVariants>().unwrap(), v);
        let text = "bvh=wide8,stack=short,order=tiles,appends=workgroup,stats=off,checks=off";
        assert_eq!(text.parse::<GpuVariants>().unwrap().to_string(), text);
        let one: GpuVariants = "stack=private".parse().unwrap();
        assert_eq!(one.stack, BvhStack::Private);
        assert_eq!(one.changes(), "stack=private");
        assert_eq!("stack=short".parse::<GpuVariants>().unwrap().changes(), "default");
        assert_eq!(
            GpuVariants::before_hardware().changes(),
            "stack=private,order=rows,appends=per_ray,stats=on"
        );
        for (bad, names) in [
            ("bvh=wide4", ["bvh=wide4", "binary|wide8"]),
            ("colour=red", ["'colour'", "appends=workgroup|per_ray"]),
            ("stack=short17", ["short17", "shortN"]),
            ("stack=short0", ["short0", "shortN"]),
            ("stats", ["'stats'", "KEY=VALUE"]),
            ("checks=maybe", ["checks=maybe", "on|off"]),
        ] {
            let e = bad.parse::<GpuVariants>().unwrap_err();
            for n in names {
                assert!(e.contains(n), "{bad}: {e}");
            }
        }
    }

    /// The suite is the default, one change of each key (both other appends), each exactly one
    /// key off, and the kernels as first written.
    #[test]
    fn suite_is_default_plus_single_changes() {
        let s = GpuVariants::suite();
        assert_eq!(s[0], GpuVariants::default());
        assert_eq!(s.len(), 1 + KEYS.len() + 1 + 1);
        assert_eq!(s.last(), Some(&GpuVariants::before_hardware()));
        for v in &s[1..s.len() - 1] {
            assert_eq!(v.changes().split(',').count(), 1, "{v}");
            assert_ne!(v.changes(), "default");
        }
        let mut labels: Vec<String> = s.iter().map(|v| v.changes()).collect();
        labels.dedup();
        assert_eq!(labels.len(), s.len());
        assert!(!s[1].applies_to("grid") && s[1].applies_to("bvh"));
        assert!(s[3].applies_to("grid"));
    }
}
