//! Options shared by several commands: choosing the scene and the grid.

use std::path::{Path, PathBuf};

use clap::Args;
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use gridtrace::gpu::GpuVariants;
use gridtrace::scene::{Scene, builtin, file::load_scene};
use gridtrace::{AccelChoice, AccelKind, AccelParams, AccelSpec, TracedOn, Work};

#[derive(Args, Debug, Clone)]
pub struct SceneArgs {
    /// A scene file (TOML) or a mesh file (OBJ, PLY, glTF/GLB, STL, OFF).
    pub file: Option<PathBuf>,
    /// A built-in scene: knot-box, mirror-spheres, sparse-room.
    #[arg(long, conflicts_with_all = ["file", "mesh"])]
    pub scene: Option<String>,
    /// Any mesh, in an auto-framed scene with a floor, a light and a camera.
    #[arg(long, conflicts_with = "file")]
    pub mesh: Option<PathBuf>,
}

/// `--accel` and `--accel-params`: the structure and its build parameters, which the structure
/// reads itself (the registry lists each one's keys; this file names none).
#[derive(Args, Debug, Clone)]
pub struct AccelArgs {
    // The help is written from the registry (`accel::registry::ENTRIES`).
    #[arg(long, default_value = "auto", value_parser = |s: &str| s.parse::<AccelSpec>(), help = accel_help(), long_help = accel_long_help())]
    pub accel: AccelSpec,
    /// More build parameters for the structure --accel names, KEY=VALUE,... (as after NAME:; a
    /// key given in both takes this value).
    #[arg(long = "accel-params", default_value = "", value_parser = |s: &str| s.parse::<AccelParams>())]
    pub accel_params: AccelParams,
}

impl AccelArgs {
    /// `--accel` with `--accel-params` merged in.
    pub fn spec(&self) -> gridtrace::Result<AccelSpec> {
        self.accel
            .clone()
            .with_params(&self.accel_params)
            .map_err(gridtrace::Error::InvalidInput)
    }

    /// `--accel` with `--accel-params` read as the structure will read them when it builds
    /// (`Structure::check_params`), before any work: `main` makes an error here a usage error
    /// (exit status 2), as clap's own are, not a failure of the run.
    pub fn check(&self) -> Result<(), String> {
        let message = |e: gridtrace::Error| match e {
            gridtrace::Error::InvalidInput(m) => m,
            e => e.to_string(),
        };
        let spec = self.spec().map_err(message)?;
        match spec.choice {
            AccelChoice::Kind(kind) => gridtrace::accel::Structure::check_params(kind, &spec.params).map_err(message),
            AccelChoice::Auto => Ok(()),
        }
    }

    /// The traversal `--accel` names, or `auto`'s pick for `work` traced where `traced_on`
    /// says, with its note pushed to `notes`.
    pub fn accel_for(&self, traced_on: TracedOn, work: Work, notes: &mut Vec<String>) -> AccelKind {
        let (kind, note) = self.accel.resolve(traced_on, work);
        notes.extend(note);
        kind
    }
}

/// `--accel`'s help: the form, then each name with what it is and the parameters it reads.
fn accel_help() -> String {
    "Acceleration structure: auto (the one measured fastest for the work on the backend that traces it; it \
     says which and why), or NAME[:KEY=VALUE,...], the structure's build parameters after the colon \
     (grid:res=64, irregular:top=0.2,cell=4; --help lists each one's)"
        .into()
}

/// `--accel`'s `--help`: the short help, then `auto` and every traversal with what it is, its
/// aliases and its parameters, laid out as clap lays out possible values.
fn accel_long_help() -> String {
    let row = |name: &str, about: &str| format!("- {:<10} {about}", format!("{name}:"));
    let auto = row(
        "auto",
        "the structure measured fastest for the work (it says which and why)",
    );
    let rows = gridtrace::accel::registry::ENTRIES.iter().map(|e| {
        let mut about = e.about.to_string();
        if !e.aliases.is_empty() {
            about += &format!(" (also {})", e.aliases.join(", "));
        }
        if !e.params.is_empty() {
            about += &format!("\n             parameters: {}", e.params);
        }
        row(e.name, &about)
    });
    let rows: Vec<String> = std::iter::once(auto).chain(rows).collect();
    format!("{}\n\n{}", accel_help(), rows.join("\n"))
}

impl SceneArgs {
    /// Loads the scene the arguments name; a plain mesh file gets the auto-framed scene, with a
    /// floor under it when `floor` is set.
    pub fn load(&self, floor: bool) -> gridtrace::Result<(Scene, String)> {
        if let Some(name) = &self.scene {
            let s = builtin::scene(name).ok_or_else(|| {
                gridtrace::Error::InvalidInput(format!("unknown scene '{name}'; built-in scenes: {}", builtin_names()))
            })?;
            return Ok((s, name.clone()));
        }
        let path = match (&self.file, &self.mesh) {
            (Some(p), _) | (None, Some(p)) => p,
            (None, None) => return Ok((builtin::knot_box(), "knot-box".into())),
        };
        // `gridtrace render mirror-spheres`: a scene name given where a file goes.
        if self.file.is_some() && path.extension().is_none() && !path.exists() {
            return Err(gridtrace::Error::InvalidInput(format!(
                "{}: no such file; for a built-in scene use --scene NAME ({})",
                path.display(),
                builtin_names()
            )));
        }
        let is_scene = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml"));
        let scene = if is_scene && self.mesh.is_none() {
            load_scene(path)?
        } else {
            builtin::mesh_scene(gridtrace::io::load_mesh(path)?, floor)
        };
        Ok((scene, path.display().to_string()))
    }
}

/// The built-in scenes' names, comma separated.
fn builtin_names() -> String {
    builtin::SCENES.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
}

/// The registry's traversals as clap values: names, aliases and one-line help.
fn kind_values() -> impl Iterator<Item = PossibleValue> {
    gridtrace::accel::registry::ENTRIES.iter().map(|e| {
        PossibleValue::new(e.name)
            .aliases(e.aliases.iter().copied())
            .help(e.about)
    })
}

/// `bench --accel`: the registry's names (a benchmark names what it measures).
pub fn kind_parser() -> impl TypedValueParser<Value = AccelKind> {
    PossibleValuesParser::new(kind_values()).map(|s| s.parse::<AccelKind>().expect("every listed accel parses"))
}

/// `--mode`: the values are listed in `--help` and in the error for a wrong one.
pub fn mode_parser() -> impl TypedValueParser<Value = gridtrace::Mode> {
    PossibleValuesParser::new(["cast", "shadow", "trace", "heat"])
        .map(|s| s.parse::<gridtrace::Mode>().expect("every listed mode parses"))
}

/// `--gpu-variant`: the GPU kernels' variants (`gridtrace::gpu::variants`), flattened into the
/// commands that trace on a GPU.
#[derive(Args, Debug, Clone, Default)]
pub struct GpuVariantArgs {
    // The help is written from the library's table of variants (`gpu::variants::VARIANTS`).
    #[arg(
        long = "gpu-variant",
        default_value = "",
        value_parser = |s: &str| s.parse::<GpuVariants>(),
        help = gpu_variant_help(),
        long_help = gpu_variant_long_help()
    )]
    pub gpu_variant: GpuVariants,
}

/// `--gpu-variant`'s help: every key with its values.
fn gpu_variant_help() -> String {
    format!(
        "GPU variants, KEY=VALUE,... (any subset; the first value of each is the default): {}. Same images \
         and hits, other speed; the defaults are what the hardware suite found fastest on an NVIDIA H200 \
         (docs/benchmarks.md).",
        gridtrace::gpu::variants::keys_text()
    )
}

/// `--gpu-variant`'s `--help`: the short help, then each key's values and what it changes.
fn gpu_variant_long_help() -> String {
    let keys: Vec<String> = gridtrace::gpu::variants::VARIANTS
        .iter()
        .map(|r| {
            let only = if r.structures.is_empty() {
                String::new()
            } else {
                let names: Vec<&str> = r.structures.iter().map(|s| s.name()).collect();
                format!(" (--accel {} only)", names.join(", "))
            };
            format!("- {}={}: {}{only}", r.key, r.values_text(), r.help)
        })
        .collect();
    format!("{}\n\n{}", gpu_variant_help(), keys.join("\n"))
}

/// `--backend`: the values are listed in `--help` and in the error for a wrong one.
pub fn backend_parser() -> impl TypedValueParser<Value = Backend> {
    PossibleValuesParser::new(["auto", "gpu", "cpu"])
        .map(|s| s.parse::<Backend>().expect("every listed backend parses"))
}

// `--res` and `x,y,z` values are read by the library, so that the web page reads its URL's
// parameters as these options are read.
pub use gridtrace::render::parse_res;
pub use gridtrace::util::parse_vec3;

/// An output file's folder exists and the path is not a folder itself: checked when the
/// arguments are read, so a run of minutes is not lost to a typo at the end. The message leaves
/// the path to the caller (clap names the value it refuses).
pub fn check_output_path(path: &Path) -> Result<(), String> {
    if path.is_dir() {
        return Err("is a directory, not a file".into());
    }
    let folder = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !folder.is_dir() {
        return Err(format!(
            "the folder {} does not exist (make it first)",
            folder.display()
        ));
    }
    Ok(())
}

/// `-o`: an image whose format its extension names (`.png`, or another this build encodes, such
/// as `.jpg`), in a folder that exists; both checked before any work.
pub fn parse_image_output(s: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(s);
    check_output_path(&path)?;
    if !image::ImageFormat::from_path(&path).is_ok_and(|f| f.writing_enabled()) {
        let formats: Vec<&str> = image::ImageFormat::all()
            .filter(|f| f.writing_enabled())
            .filter_map(|f| f.extensions_str().first().copied())
            .collect();
        return Err(format!(
            "the image format follows the extension; this build writes .{}",
            formats.join(", .")
        ));
    }
    Ok(path)
}

/// An output file (not an image: `rays --hits-out`) in a folder that exists.
pub fn parse_output(s: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(s);
    check_output_path(&path)?;
    Ok(path)
}

pub use gridtrace::util::fmt_bytes;

pub use gridtrace::query::Backend;

/// The scene prepared with the structure that serves `accel` (which may differ from
/// `args.accel`: the viewer switches), built with the parameters given for it
/// (`gridtrace::placement::prepare`), and a scene-level error (nothing to trace, NaN camera...) naming
/// the scene or file it came from.
pub fn prepare(
    scene: &Scene,
    name: &str,
    accel: AccelKind,
    args: &AccelArgs,
) -> gridtrace::Result<gridtrace::PreparedScene> {
    gridtrace::placement::prepare(scene, accel, &args.spec()?).map_err(|e| named(name, e))
}

/// A scene's error with the scene's name in front, as every command reports it.
pub fn named(name: &str, e: gridtrace::Error) -> gridtrace::Error {
    match e {
        gridtrace::Error::Scene(m) => gridtrace::Error::Scene(format!("{name}: {m}")),
        e => e,
    }
}

/// The structure in a few words: a grid's dimensions and references per triangle, a BVH's
/// nodes and memory (each structure's `AccelStructure::summary`).
pub fn describe_structure(accel: &gridtrace::Accel) -> String {
    accel.summary()
}

/// What `render` and `rays` print of GPU work, with one meaning: wall time (first upload to the
/// result in host memory) beside the device's timestamps, the parts it was cut into, host
/// round trips and bytes each way.
pub struct GpuFigures<'a> {
    pub wall_ms: f64,
    pub timings: &'a gridtrace::gpu::GpuTimings,
    /// How many parts and their name (tiles of a frame, chunks of a batch).
    pub parts: (u32, &'static str),
    pub round_trips: u32,
    pub uploaded_bytes: u64,
    pub downloaded_bytes: u64,
}

/// Prints the `gpu` line (after `which`, e.g. "last frame: ") and, where the adapter has
/// timestamps, the `stages` line; returns the device's milliseconds then.
pub fn print_gpu_figures(which: &str, f: &GpuFigures) -> Option<f64> {
    let gpu_ms = f.timings.from_timestamps.then_some(f.timings.total_ms);
    let gpu = gpu_ms.map_or("no timestamp queries".to_string(), |ms| format!("GPU {ms:.2} ms"));
    let plural = |n: u32| if n == 1 { "" } else { "s" };
    println!(
        "gpu     {which}wall {:.2} ms, {gpu}; {} {}{}, {} round trip{}, {} B up, {} B down",
        f.wall_ms,
        f.parts.0,
        f.parts.1,
        plural(f.parts.0),
        f.round_trips,
        plural(f.round_trips),
        f.uploaded_bytes,
        f.downloaded_bytes
    );
    println!("host    {} (the wall time's parts on the host's clock)", f.timings.host);
    gpu_ms?;
    let stages: Vec<String> = f.timings.stages_ms.iter().map(|(k, v)| format!("{k} {v:.2}")).collect();
    println!("stages  {} ms (GPU timestamps)", stages.join(", "));
    gpu_ms
}

/// Writes frame `i` of an animation where `--sequence` (every frame, numbered) and `-o` (the
/// first frame) ask.
pub fn save_frame(image: &gridtrace::Image, i: u32, sequence: Option<&Path>, output: &Path) -> gridtrace::Result<()> {
    if let Some(dir) = sequence {
        image.save_png(&dir.join(format!("frame_{i:04}.png")))?;
    }
    if i == 0 {
        image.save_png(output)?;
    }
    Ok(())
}

/// The median of column `k` of an animation's frame rows after the first, which pays for
/// first-use costs (buffer growth, caches): the steady state.
pub fn median_after_first(rows: &[[f64; 3]], k: usize) -> f64 {
    let mut v: Vec<f64> = rows[1..].iter().map(|r| r[k]).collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The `backend` line of an animation: the GPU's adapter (and whether it is a software one,
/// whose speed is the CPU's) or the CPU's threads.
pub fn print_backend(placement: &gridtrace::Placement) {
    match &placement.device {
        Some(ctx) => {
            println!("backend gpu: {}", ctx.describe());
            if ctx.is_software() {
                println!("        (a software adapter: CPU speed, not GPU speed)");
            }
        }
        None => println!("backend {}", gridtrace::backend::describe_cpu()),
    }
}
