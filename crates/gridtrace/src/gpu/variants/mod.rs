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

use crate::accel::StructureId;
use std::fmt;
use std::str::FromStr;

// The BVH's two keys take values of its own (`walks/bvh`).
pub use super::walks::bvh::{BvhLayout, BvhStack, BvhWalk, SHORT_STACK_DEFAULT, SHORT_STACK_MAX};

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

/// One choice of every GPU variant. Its default, the kernels as first written
/// (`before_hardware`), its text and the hardware suite all come from `VARIANTS`.
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

/// Sets one key of a `GpuVariants` to one value.
type Set = fn(&mut GpuVariants);

/// A family of numbered values beside a key's named ones: `{prefix}N` for N in `min..=max`
/// (`stack=shortN`).
#[derive(Debug, Clone, Copy)]
pub struct Numbered {
    pub prefix: &'static str,
    pub min: u8,
    pub max: u8,
    set: fn(&mut GpuVariants, u8),
}

/// One key of `--gpu-variant` (Python's `gpu_variant=`) and everything about it: parsing,
/// printing, the default, the hardware suite, the overrides and the help texts all read its
/// row. A new variant is its field of `GpuVariants`, one row of `VARIANTS` and its use in the
/// kernels.
#[derive(Debug, Clone, Copy)]
pub struct VariantSpec {
    pub key: &'static str,
    /// The named values as typed and printed, each with what it sets; the default first (help
    /// texts say "the first value of each is the default").
    values: &'static [(&'static str, Set)],
    pub numbered: Option<Numbered>,
    /// The value the kernels as first written had, before any ran on a GPU (`before_hardware`).
    first_written: &'static str,
    /// The values the hardware suite runs, each as the one change from the default, in order.
    suite: &'static [&'static str],
    /// The structures whose walk it changes; empty: every
    /// structure's kernels.
    pub structures: &'static [StructureId],
    /// One line for help texts.
    pub help: &'static str,
    /// The pipeline-overridable constant of common.wgsl it sets.
    wgsl_override: Option<WgslOverride>,
}

/// A pipeline-overridable constant of common.wgsl and its value for a choice of variants.
#[derive(Debug, Clone, Copy)]
struct WgslOverride {
    name: &'static str,
    value: fn(&GpuVariants) -> f64,
}

/// Every GPU variant, in the order they are printed (`Display`) and listed.
pub const VARIANTS: [VariantSpec; 6] = [
    VariantSpec {
        key: "bvh",
        values: &[
            ("binary", |v| v.bvh = BvhLayout::Binary),
            ("wide8", |v| v.bvh = BvhLayout::Wide8),
        ],
        numbered: None,
        first_written: "binary",
        suite: &["wide8"],
        structures: &[StructureId::Bvh],
        help: "the BVH's GPU layout: two-child nodes (binary), or Ylitie et al.'s 8-wide compressed nodes (wide8)",
        wgsl_override: None,
    },
    VariantSpec {
        key: "stack",
        values: &[
            ("short", |v| v.stack = BvhStack::Short(SHORT_STACK_DEFAULT)),
            ("private", |v| v.stack = BvhStack::Private),
        ],
        numbered: Some(Numbered {
            prefix: "short",
            min: 1,
            max: SHORT_STACK_MAX,
            set: |v, n| v.stack = BvhStack::Short(n),
        }),
        first_written: "private",
        suite: &["private"],
        structures: &[StructureId::Bvh],
        help: "the BVH walk's stack: a ring of 8 (shortN: N) entries in workgroup memory that climbs by \
               parent links when it runs dry, or a private array per thread",
        wgsl_override: Some(WgslOverride {
            name: "SHORT_STACK",
            value: |v| match v.stack {
                BvhStack::Short(n) => n as f64,
                // The private stack's walk never reads it; any valid ring size compiles.
                BvhStack::Private => SHORT_STACK_DEFAULT as f64,
            },
        }),
    },
    VariantSpec {
        key: "order",
        values: &[
            ("tiles", |v| v.order = RayOrder::Tiles),
            ("rows", |v| v.order = RayOrder::Rows),
        ],
        numbered: None,
        first_written: "rows",
        suite: &["rows"],
        structures: &[],
        help: "which pixels a workgroup's 64 eye rays start from: an 8x8 tile, or a 64x1 strip of a row",
        wgsl_override: Some(WgslOverride {
            name: "TILE_ORDER",
            value: |v| (v.order == RayOrder::Tiles) as u8 as f64,
        }),
    },
    VariantSpec {
        key: "appends",
        values: &[
            ("workgroup", |v| v.appends = Appends::Workgroup),
            ("per_ray", |v| v.appends = Appends::PerRay),
            ("subgroup", |v| v.appends = Appends::Subgroup),
        ],
        numbered: None,
        first_written: "per_ray",
        suite: &["per_ray", "subgroup"],
        structures: &[],
        help: "how kernels append to the ray queues: one global atomic per workgroup, per ray, or per \
               subgroup (needs the adapter's subgroup operations)",
        wgsl_override: Some(WgslOverride {
            name: "WG_APPENDS",
            value: |v| (v.appends == Appends::Workgroup) as u8 as f64,
        }),
    },
    VariantSpec {
        key: "stats",
        values: &[("off", |v| v.stats = false), ("on", |v| v.stats = true)],
        numbered: None,
        first_written: "on",
        suite: &["on"],
        structures: &[],
        help: "per-ray statistics atomics in shading (off: the same counts read off the queue lengths)",
        wgsl_override: Some(WgslOverride {
            name: "RAY_STATS",
            value: |v| v.stats as u8 as f64,
        }),
    },
    VariantSpec {
        key: "checks",
        values: &[("on", |v| v.checks = true), ("off", |v| v.checks = false)],
        numbered: None,
        first_written: "on",
        suite: &["off"],
        structures: &[],
        help: "bounds checks and loop bounding in the shader modules (off: trusted modules, every index \
               in bounds by construction)",
        wgsl_override: None,
    },
];

impl VariantSpec {
    /// The named values, the default first.
    pub fn values(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.values.iter().map(|(name, _)| *name)
    }

    pub fn default_value(&self) -> &'static str {
        self.values[0].0
    }

    /// The valid values in words, as errors and help list them: `short|private|shortN (N =
    /// 1..16)`.
    pub fn values_text(&self) -> String {
        let named: Vec<&str> = self.values().collect();
        match self.numbered {
            Some(n) => format!("{}|{}N (N = {}..{})", named.join("|"), n.prefix, n.min, n.max),
            None => named.join("|"),
        }
    }

    /// Sets this key of `v` to `value`; `None` where `value` is not one of its values.
    fn set(&self, v: &mut GpuVariants, value: &str) -> Option<()> {
        if let Some((_, set)) = self.values.iter().find(|(name, _)| *name == value) {
            set(v);
            return Some(());
        }
        let n = self.numbered?;
        match value.strip_prefix(n.prefix).map(str::parse::<u8>) {
            Some(Ok(i)) if (n.min..=n.max).contains(&i) => {
                (n.set)(v, i);
                Some(())
            }
            _ => None,
        }
    }

    /// This key's value in `v`, as printed: the value whose setting leaves `v` as it is (a
    /// named one before a numbered one: `short`, not `short8`).
    fn value_in(&self, v: &GpuVariants) -> String {
        let keeps = |set: &dyn Fn(&mut GpuVariants)| {
            let mut w = *v;
            set(&mut w);
            w == *v
        };
        if let Some((name, _)) = self.values.iter().find(|(_, set)| keeps(set)) {
            return name.to_string();
        }
        // Numbered values outside the parsed range too: a `GpuVariants` written in code prints
        // what it holds.
        let n = self
            .numbered
            .expect("a key without numbered values names every value of its field");
        let i = (0..=u8::MAX)
            .find(|&i| keeps(&|w: &mut GpuVariants| (n.set)(w, i)))
            .expect("every value of a numbered key's field is a number");
        format!("{}{i}", n.prefix)
    }
}

/// Every key with its values, as errors and the CLI's help list them:
/// `bvh=binary|wide8, stack=...`.
pub fn keys_text() -> String {
    VARIANTS
        .iter()
        .map(|r| format!("{}={}", r.key, r.values_text()))
        .collect::<Vec<_>>()
        .join(", ")
}

impl Default for GpuVariants {
    /// Each key's first value (`VARIANTS`): what the H200 runs chose (module docs).
    fn default() -> Self {
        GpuVariants::from_table(|r| r.default_value())
    }
}

impl GpuVariants {
    /// The BVH walk its `bvh` and `stack` keys choose (what `walks` reads of the variants).
    pub fn bvh_walk(&self) -> BvhWalk {
        BvhWalk {
            layout: self.bvh,
            stack: self.stack,
        }
    }

    /// Every key set to `value_of` its row: the rows set every field, so the starting value
    /// does not show (a test checks it).
    fn from_table(value_of: impl Fn(&VariantSpec) -> &'static str) -> GpuVariants {
        GpuVariants::from_table_over(
            GpuVariants {
                bvh: BvhLayout::Binary,
                stack: BvhStack::Private,
                order: RayOrder::Rows,
                appends: Appends::PerRay,
                stats: false,
                checks: false,
            },
            value_of,
        )
    }

    fn from_table_over(mut v: GpuVariants, value_of: impl Fn(&VariantSpec) -> &'static str) -> GpuVariants {
        for r in &VARIANTS {
            r.set(&mut v, value_of(r))
                .unwrap_or_else(|| panic!("VARIANTS: '{}' is not a value of {}", value_of(r), r.key));
        }
        v
    }

    /// What the hardware suite runs: the default, then each single change from it (`VARIANTS`'
    /// suite values, in order), then the kernels as first written (`before_hardware`), so that
    /// every run measures what the defaults gained on its GPU.
    pub fn suite() -> Vec<GpuVariants> {
        let d = GpuVariants::default();
        let changes = VARIANTS.iter().flat_map(|r| {
            r.suite.iter().map(move |value| {
                let mut v = d;
                r.set(&mut v, value)
                    .unwrap_or_else(|| panic!("VARIANTS: suite value '{value}' is not a value of {}", r.key));
                v
            })
        });
        std::iter::once(d)
            .chain(changes)
            .chain(std::iter::once(GpuVariants::before_hardware()))
            .collect()
    }

    /// The kernels as first written, before any ran on a GPU: a private stack, rows, an atomic
    /// per appended ray, statistics atomics. The first H200 runs measured each of these against
    /// the others (module docs).
    pub fn before_hardware() -> GpuVariants {
        GpuVariants::from_table(|r| r.first_written)
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

    /// The keys whose value differs from the default's.
    fn changed(&self) -> impl Iterator<Item = (&'static VariantSpec, String)> + '_ {
        let d = GpuVariants::default();
        VARIANTS.iter().filter_map(move |r| {
            let own = r.value_in(self);
            (own != r.value_in(&d)).then_some((r, own))
        })
    }

    /// Only the keys that differ from the default (`default` when none): a short label.
    pub fn changes(&self) -> String {
        let diff: Vec<String> = self.changed().map(|(r, value)| format!("{}={value}", r.key)).collect();
        if diff.is_empty() {
            "default".to_string()
        } else {
            diff.join(",")
        }
    }

    /// Whether these variants change the walk of `structure`: the BVH's layout and stack apply
    /// to the BVH only (`VariantSpec::structures`).
    pub fn applies_to(&self, structure: StructureId) -> bool {
        self.changed()
            .any(|(r, _)| r.structures.is_empty() || r.structures.contains(&structure))
    }

    /// The pipeline-overridable constants these variants set (declared in common.wgsl): the same
    /// set for every pipeline, so that every kernel sees one consistent choice.
    pub fn overrides(&self) -> Vec<(&'static str, f64)> {
        VARIANTS
            .iter()
            .filter_map(|r| r.wgsl_override.map(|o| (o.name, (o.value)(self))))
            .collect()
    }
}

impl fmt::Display for GpuVariants {
    /// Every key, `KEY=VALUE` in `VARIANTS`' order, comma separated.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, r) in VARIANTS.iter().enumerate() {
            let comma = if i == 0 { "" } else { "," };
            write!(f, "{comma}{}={}", r.key, r.value_in(self))?;
        }
        Ok(())
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
        for pair in s.split(',').map(str::trim) {
            let Some((key, value)) = pair.split_once('=') else {
                return Err(format!("GPU variant '{pair}' is not KEY=VALUE; valid: {}", keys_text()));
            };
            let (key, value) = (key.trim(), value.trim());
            let Some(row) = VARIANTS.iter().find(|r| r.key == key) else {
                return Err(format!("unknown GPU variant key '{key}'; valid: {}", keys_text()));
            };
            row.set(&mut v, value).ok_or_else(|| {
                format!(
                    "GPU variant {key}={value}: '{value}' is not one of {}",
                    row.values_text()
                )
            })?;
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests;
