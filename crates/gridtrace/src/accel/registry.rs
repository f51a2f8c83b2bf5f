//! The one list of structures: each traversal's name and aliases as users type them
//! (`--accel`, Python's `accel=`), the structure it walks, what it is for, and the build
//! parameters it reads (in words: each structure parses its own, `params.rs`). The CLI's
//! values and help, Python's accepted names, the viewer's G
//! cycle, the benchmarks' columns and the tests' "every structure" all come from here.
//!
//! Adding a structure: its folder (implementing `contract::AccelStructure` and `Walks`), one
//! `StructureId` and one `AccelKind` variant and one `ENTRIES` row here, one arm of `Structure`
//! in `mod.rs` (whose matches on `StructureId` are exhaustive: the compiler lists what is left).

use super::AccelParams;

/// Which traversal (and so which structure) is used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AccelKind {
    /// Plain uniform grid: one DDA step per cell.
    Grid,
    /// Uniform grid with proximity clouds: empty space is crossed in jumps.
    ProximityCloud,
    /// Bounding volume hierarchy (binned SAH), the comparison the paper left as future work.
    Bvh,
    /// Irregular grid (merged and expanded cells, no DDA), the grid that adapts.
    Irregular,
    /// No structure: every triangle tested against every ray (the oracle).
    Brute,
    /// The GPU's ray-tracing hardware through ray queries (the driver's structure; GPU only).
    Hwrt,
}

/// A structure, typed once here: what every comparison of structures takes (traversals with
/// the same structure share one build: `grid` and `pc`), and `Structure`'s arms match. Its
/// name is for messages and reports only.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StructureId {
    Grid,
    Bvh,
    Irregular,
    Brute,
    Hwrt,
}

impl StructureId {
    /// The structure's name in messages, reports and GPU labels.
    pub const fn name(self) -> &'static str {
        match self {
            StructureId::Grid => "grid",
            StructureId::Bvh => "bvh",
            StructureId::Irregular => "irregular",
            StructureId::Brute => "brute",
            StructureId::Hwrt => "hwrt",
        }
    }
}

impl std::fmt::Display for StructureId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One row of the registry.
#[derive(Debug, Clone, Copy)]
pub struct AccelEntry {
    pub kind: AccelKind,
    /// The name users type and every report prints.
    pub name: &'static str,
    /// Other accepted spellings.
    pub aliases: &'static [&'static str],
    /// The structure this traversal walks: traversals with the same structure share one build
    /// (`grid` and `pc`).
    pub structure: StructureId,
    /// One line for help texts.
    pub about: &'static str,
    /// The build parameters its structure reads, for help texts (`NAME:KEY=VALUE,...`); the
    /// structure parses them itself (`AccelStructure::build`), so this is words only.
    pub params: &'static str,
    /// Whether a ray tests every triangle (brute force): tests on large meshes give it a sample
    /// of their rays.
    pub every_triangle: bool,
    /// Whether the GPU backend has a walk for it (else `auto` traces it on the CPU, and
    /// `--backend gpu` says so).
    pub gpu: bool,
    /// Whether interactive use (the viewer's G cycle) offers it: brute force costs the whole
    /// triangle count per ray, `hwrt` needs a GPU with ray queries.
    pub interactive: bool,
    /// Whether the CPU backend traces it (else asking for it on the CPU is an error that says
    /// so: `hwrt` means the GPU's ray-tracing hardware).
    pub cpu: bool,
}

/// Every traversal, in the order help texts and reports list them.
pub const ENTRIES: [AccelEntry; 6] = [
    AccelEntry {
        kind: AccelKind::Grid,
        name: "grid",
        aliases: &["g"],
        structure: StructureId::Grid,
        about: "the paper's uniform grid, one DDA step per cell",
        params: "res=auto|auto:LAMBDA|N|AxBxC (cells: auto at LAMBDA=4 cells per triangle)",
        every_triangle: false,
        gpu: true,
        interactive: true,
        cpu: true,
    },
    AccelEntry {
        kind: AccelKind::ProximityCloud,
        name: "pc",
        aliases: &["proximity"],
        structure: StructureId::Grid,
        about: "the uniform grid with proximity clouds: jumps over empty cells",
        params: "res=auto|auto:LAMBDA|N|AxBxC (cells: auto at LAMBDA=4 cells per triangle)",
        every_triangle: false,
        gpu: true,
        interactive: true,
        cpu: true,
    },
    AccelEntry {
        kind: AccelKind::Bvh,
        name: "bvh",
        aliases: &[],
        structure: StructureId::Bvh,
        about: "an eight-wide SAH bounding volume hierarchy (fastest for incoherent rays)",
        params: "",
        every_triangle: false,
        gpu: true,
        interactive: true,
        cpu: true,
    },
    AccelEntry {
        kind: AccelKind::Irregular,
        name: "irregular",
        aliases: &["irr"],
        structure: StructureId::Irregular,
        about: "an irregular grid: merged and expanded cells, point lookups instead of a DDA",
        params: "top=0.12,cell=2,alpha=1,merge=8,expand=3 (top cells per triangle, cells per reference, merge alpha, merge and expansion passes)",
        every_triangle: false,
        gpu: true,
        interactive: true,
        cpu: true,
    },
    AccelEntry {
        kind: AccelKind::Brute,
        name: "brute",
        aliases: &["brute-force"],
        structure: StructureId::Brute,
        about: "no structure: every triangle per ray (the oracle; small meshes and checks)",
        params: "",
        every_triangle: true,
        gpu: true,
        interactive: false,
        cpu: true,
    },
    AccelEntry {
        kind: AccelKind::Hwrt,
        name: "hwrt",
        aliases: &["ray-query"],
        structure: StructureId::Hwrt,
        about: "the GPU's ray-tracing hardware by ray query (GPU only; closest points by a BVH)",
        params: "",
        every_triangle: false,
        gpu: true,
        // The G cycle must run on every tracer, and this one only on a GPU with ray queries:
        // `view --accel hwrt` opens the viewer on it.
        interactive: false,
        cpu: false,
    },
];

impl AccelKind {
    /// Every kind, in registry order (the CPU and the GPU run them all).
    pub const ALL: [AccelKind; ENTRIES.len()] = {
        let mut all = [AccelKind::Grid; ENTRIES.len()];
        let mut i = 0;
        while i < ENTRIES.len() {
            all[i] = ENTRIES[i].kind;
            i += 1;
        }
        all
    };

    /// The kinds interactive use cycles through, in registry order.
    pub fn interactive() -> impl Iterator<Item = AccelKind> {
        ENTRIES.iter().filter(|e| e.interactive).map(|e| e.kind)
    }

    /// This kind's registry row.
    pub fn entry(self) -> &'static AccelEntry {
        ENTRIES
            .iter()
            .find(|e| e.kind == self)
            .expect("every AccelKind has a registry entry")
    }

    pub fn name(self) -> &'static str {
        self.entry().name
    }

    /// Whether this kind runs on the uniform grid (`grid` and `pc` share one).
    pub fn uses_grid(self) -> bool {
        self.structure() == StructureId::Grid
    }

    /// The structure this kind traverses.
    pub fn structure(self) -> StructureId {
        self.entry().structure
    }

    /// Its name, for messages (`StructureId::name`).
    pub fn structure_name(self) -> &'static str {
        self.structure().name()
    }

    /// An error unless this kind walks `structure` (the registry's `structure` column): the one
    /// check of every switch of traversal (`set_traversal` on the CPU's structure and on a GPU's
    /// upload); `what` names the scene in the message ("scene prepared").
    pub fn check_walks(self, structure: StructureId, what: &str) -> crate::Result<()> {
        if self.structure() == structure {
            return Ok(());
        }
        Err(crate::Error::InvalidInput(format!(
            "accel '{}' asked of a {what} with a {structure}: prepare the scene for '{}'",
            self.name(),
            self.name()
        )))
    }

    /// Every accepted spelling with its kind: names first, then aliases.
    pub fn spellings() -> impl Iterator<Item = (&'static str, AccelKind)> {
        let names = ENTRIES.iter().map(|e| (e.name, e.kind));
        names.chain(ENTRIES.iter().flat_map(|e| e.aliases.iter().map(move |a| (*a, e.kind))))
    }

    /// The names, quoted and joined for messages: `'grid', 'pc', ... or 'brute'`.
    pub fn names_list() -> String {
        let names: Vec<String> = ENTRIES.iter().map(|e| format!("'{}'", e.name)).collect();
        match names.split_last() {
            Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
            _ => names.join(""),
        }
    }
}

impl std::str::FromStr for AccelKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        AccelKind::spellings()
            .find(|(n, _)| *n == s)
            .map(|(_, k)| k)
            .ok_or_else(|| format!("accel must be {}, got '{s}'", AccelKind::names_list()))
    }
}

/// What a structure is asked to do, as `auto` weighs it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Work {
    /// Frames of an image: camera, shadow and mirror rays (`render`, `view`).
    Render,
    /// Frames of a mesh that moves: a structure update per frame (`render --animate`).
    Animate,
    /// Batches of rays from a program (`rays`, Python), coherent or not.
    Rays,
}

/// Where the traversal will run, as `auto` weighs it. The caller says so: it has opened the
/// device (`backend::traced_on`) or decided where the work runs (`Backend::traced_on`), and
/// this file stays below the backend that knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TracedOn {
    Cpu,
    /// A GPU; `hardware_ray_queries`: a hardware adapter with ray queries, where `auto` picks
    /// `hwrt` (a software adapter's ray queries run on the CPU's cores: it never decides).
    Gpu {
        hardware_ray_queries: bool,
    },
}

impl TracedOn {
    /// Whether the work runs on a GPU, hardware or software.
    pub fn on_gpu(self) -> bool {
        matches!(self, TracedOn::Gpu { .. })
    }
}

/// What `--accel` (Python's `accel=`) asks for: one traversal by name, or `auto`, the one
/// measured fastest for the work on the backend that traces it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AccelChoice {
    #[default]
    Auto,
    Kind(AccelKind),
}

impl From<AccelKind> for AccelChoice {
    fn from(k: AccelKind) -> Self {
        AccelChoice::Kind(k)
    }
}

impl std::str::FromStr for AccelChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(AccelChoice::Auto);
        }
        s.parse::<AccelKind>()
            .map(AccelChoice::Kind)
            .map_err(|_| format!("accel must be 'auto', {}, got '{s}'", AccelKind::names_list()))
    }
}

/// What `--accel` (Python's `accel=`, `accel_params=`) asks for: a choice, and the parameters
/// its structure is built with (`irregular:top=0.2,cell=4`; `grid:res=64`). The parameters are
/// words here; the structure reads them when it is built (`AccelStructure::build`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AccelSpec {
    pub choice: AccelChoice,
    pub params: AccelParams,
}

impl From<AccelKind> for AccelSpec {
    fn from(k: AccelKind) -> Self {
        AccelSpec {
            choice: AccelChoice::Kind(k),
            params: AccelParams::NONE,
        }
    }
}

impl std::str::FromStr for AccelSpec {
    type Err = String;
    /// `NAME`, `NAME:KEY=VALUE,...` or `auto`.
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, params) = s.split_once(':').unwrap_or((s, ""));
        AccelSpec {
            choice: name.trim().parse()?,
            params: AccelParams::NONE,
        }
        .with_params(&params.parse()?)
    }
}

impl std::fmt::Display for AccelSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.choice {
            AccelChoice::Auto => f.write_str("auto")?,
            AccelChoice::Kind(k) => f.write_str(k.name())?,
        }
        if !self.params.is_empty() {
            write!(f, ":{}", self.params)?;
        }
        Ok(())
    }
}

impl AccelSpec {
    /// More parameters (`--accel-params`, Python's `accel_params=`): a key given twice takes
    /// the later value. `auto` takes none, since which structure would read them is not known
    /// until it has picked.
    pub fn with_params(mut self, more: &AccelParams) -> Result<AccelSpec, String> {
        if self.choice == AccelChoice::Auto && !more.is_empty() {
            return Err(format!(
                "parameters '{more}' need a structure named: 'auto' picks one itself (accel NAME:{more})"
            ));
        }
        self.params = self.params.merged(more);
        Ok(self)
    }

    /// `AccelChoice::resolve`'s pick, with these parameters.
    pub fn resolve(&self, traced_on: TracedOn, work: Work) -> (AccelKind, Option<String>) {
        self.choice.resolve(traced_on, work)
    }
}

impl AccelChoice {
    /// The traversal to use for `work` traced where `traced_on` says, with a note saying what
    /// `auto` picked and why (`None` when a kind was named).
    ///
    /// The rule, from the measurements in docs/benchmarks.md ("Which structure for what", 2 CPU
    /// cores): on the CPU the BVH is the fastest structure for ray batches (1M incoherent rays
    /// at the Stanford Bunny: 10.34 Mrays/s against the irregular grid's 3.59, pc's 1.83 and the
    /// grid's 1.46; 1.15x embreex's speed where the grid is at 0.18x), the fastest in renders
    /// except on scenes of large empty spaces (the irregular grid 0.58-1.21x it), and for moving
    /// meshes its refit beats every rebuild (3.6 ms refit + 12.6 ms trace a frame against the
    /// irregular grid's 43.3 + 24.0). On a GPU (the hardware suite on an NVIDIA H200,
    /// 2026-11-26) the BVH had the lowest GPU time in 10 of the 12 1080p frames (the Stanford
    /// Bunny, the Dragon, the Knight and the Torus Knot; cast, shadow, trace; the plain grid won
    /// the Stanford Bunny's cast and shadow frames, 0.51 ms against 1.53 and 2.18 against 2.37)
    /// and in every incoherent ray batch (Dragon: 4.1 ms for 1M rays against 5.7-6.5); the
    /// software adapter, which runs on the CPU's cores, had picked otherwise. On a hardware
    /// adapter with ray queries (`TracedOn::Gpu { hardware_ray_queries: true }`) it picks `hwrt`: the
    /// GPU's ray-tracing units (DGriffin91/tray_racing, wgpu on an RTX 4070 Ti: 0.51 ms a 1080p
    /// frame by ray query against 2.75-3.53 ms for its best software BVH); the H100 and H200
    /// have no such units, and a software adapter never decides.
    pub fn resolve(self, traced_on: TracedOn, work: Work) -> (AccelKind, Option<String>) {
        let kind = match (self, traced_on) {
            (AccelChoice::Kind(k), _) => return (k, None),
            (
                AccelChoice::Auto,
                TracedOn::Gpu {
                    hardware_ray_queries: true,
                },
            ) => AccelKind::Hwrt,
            (AccelChoice::Auto, _) => AccelKind::Bvh,
        };
        let why = match (traced_on.on_gpu(), work) {
            _ if kind == AccelKind::Hwrt => {
                "the GPU has ray queries: its ray-tracing units walk the driver's structure, several times faster \
                 than a software BVH walk on the same GPU in the literature (not yet measured here)"
            }
            (false, Work::Rays) => "the fastest for ray batches on the CPU: 1.15x embreex on incoherent rays",
            (false, Work::Render) => "the fastest renders on the CPU on most scenes measured",
            (_, Work::Animate) => "a refit per frame beats every rebuild",
            (true, _) => "the lowest GPU time on an H200 in most frames and every incoherent batch measured",
        };
        (
            kind,
            Some(format!("accel auto: {} ({why}; --accel NAME to choose)", kind.name())),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `auto` always names a structure and says why; a named kind is kept as it is.
    #[test]
    fn auto_names_its_pick() {
        let places = [
            TracedOn::Cpu,
            TracedOn::Gpu {
                hardware_ray_queries: false,
            },
            TracedOn::Gpu {
                hardware_ray_queries: true,
            },
        ];
        for traced_on in places {
            for work in [Work::Render, Work::Animate, Work::Rays] {
                let (k, note) = AccelChoice::Auto.resolve(traced_on, work);
                let note = note.expect("auto explains itself");
                assert!(note.contains(k.name()) && note.contains('('), "{note}");
                let on_gpu = traced_on.on_gpu();
                assert!(!on_gpu || k.entry().gpu, "auto picked {k:?}, which has no GPU walk");
                assert!(on_gpu || k.entry().cpu, "auto picked {k:?}, which the CPU cannot trace");
                let hwrt = traced_on
                    == TracedOn::Gpu {
                        hardware_ray_queries: true,
                    };
                assert_eq!(k == AccelKind::Hwrt, hwrt, "{traced_on:?} {work:?}: {note}");
                assert_eq!(
                    AccelChoice::Kind(AccelKind::Grid).resolve(traced_on, work),
                    (AccelKind::Grid, None)
                );
            }
        }
    }

    /// `Structure::check_params` (the CLI's check before any work) refuses exactly what a
    /// build refuses, for every traversal: the same keys and values, good and bad.
    #[test]
    fn checking_parameters_agrees_with_building() {
        use crate::accel::{Structure, TriAccel};
        use glam::Vec3;
        let tris = [TriAccel::new(Vec3::ZERO, Vec3::X, Vec3::Y)];
        let cases = [
            "",
            "res=4",
            "res=2x3x4",
            "res=auto:2",
            "res=0x1x1",
            "res=x",
            "top=0.5,cell=2",
            "top=-1",
            "merge=a",
            "alpha=1,expand=2",
            "bogus=1",
        ];
        let mut refused = 0;
        for k in AccelKind::ALL {
            for case in cases {
                let p: AccelParams = case.parse().unwrap();
                let checked = Structure::check_params(k, &p).map_err(|e| e.to_string());
                let built = Structure::build(k, &tris, &p).map(drop).map_err(|e| e.to_string());
                assert_eq!(checked, built, "{k:?} '{case}'");
                refused += checked.is_err() as usize;
            }
        }
        // Both outcomes seen: every structure refuses "bogus=1" and takes "".
        assert!(refused >= AccelKind::ALL.len() && refused < AccelKind::ALL.len() * cases.len());
    }

    #[test]
    fn every_kind_has_one_entry_and_every_spelling_parses_to_it() {
        for k in AccelKind::ALL {
            assert_eq!(ENTRIES.iter().filter(|e| e.kind == k).count(), 1, "{k:?}");
            assert_eq!(k.name().parse::<AccelKind>(), Ok(k));
            for a in k.entry().aliases {
                assert_eq!(a.parse::<AccelKind>(), Ok(k));
            }
        }
        let mut seen = std::collections::HashSet::new();
        assert!(AccelKind::spellings().all(|(n, _)| seen.insert(n)), "a spelling twice");
        assert_eq!("auto".parse::<AccelChoice>(), Ok(AccelChoice::Auto));
        assert_eq!(
            "irr".parse::<AccelChoice>(),
            Ok(AccelChoice::Kind(AccelKind::Irregular))
        );
        assert!("auto".parse::<AccelKind>().is_err());
        let e = "nope".parse::<AccelKind>().unwrap_err();
        assert!(
            e.contains("'grid'") && e.contains("'brute'") && e.contains("or 'hwrt'"),
            "{e}"
        );
    }
}
