//! The command-line tool end to end: renders, statistics, and errors that name the file.

use std::process::Command;

mod common;
use common::gridtrace;

#[test]
fn render_builtin_scene_writes_png() {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("knot.png");
    let (ok, text) = gridtrace(&[
        "render",
        "--scene",
        "knot-box",
        "--backend",
        "cpu",
        "--mode",
        "shadow",
        "--res",
        "64x48",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    assert!(text.contains("Mrays/s") && text.contains("eye 3072"), "{text}");
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (64, 48));
}

#[test]
fn render_from_mesh_file_and_scene_file() {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let obj = dir.join("tet.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .unwrap();
    let (ok, text) = gridtrace(&[
        "render",
        "--mesh",
        obj.to_str().unwrap(),
        "--backend",
        "cpu",
        "--res",
        "32",
        "-o",
        dir.join("a.png").to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    assert!(
        text.contains("6 triangles"),
        "render adds a 2-triangle floor to the 4: {text}"
    );
    let toml = dir.join("s.toml");
    std::fs::write(&toml, "[camera]\neye=[0,1,4]\ntarget=[0,0,0]\n[[light]]\nposition=[1,3,2]\nintensity=9\n[[object]]\nmesh=\"tet.obj\"\n").unwrap();
    let (ok, text) = gridtrace(&[
        "render",
        toml.to_str().unwrap(),
        "--backend",
        "cpu",
        "--res",
        "32",
        "--accel",
        "pc:res=4x4x4",
        "-o",
        dir.join("b.png").to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    assert!(text.contains("grid 4x4x4"), "{text}");
}

/// The structures with walks of their own (the BVH, the irregular grid) render on every
/// backend, and the GPU's image is the CPU's (lavapipe in CI).
#[test]
fn bvh_and_irregular_render_on_cpu_and_gpu() {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-bvh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("own.png");
    for accel in ["bvh", "irregular"] {
        let args = |backend| {
            [
                "render",
                "--scene",
                "knot-box",
                "--accel",
                accel,
                "--res",
                "32",
                "--backend",
                backend,
                "-o",
                png.to_str().unwrap(),
            ]
        };
        let mut images = Vec::new();
        for backend in ["cpu", "gpu"] {
            let (ok, text) = gridtrace(&args(backend));
            assert!(ok, "{accel} {backend}: {text}");
            assert!(text.contains(accel) && !text.contains("CPU only"), "{text}");
            images.push(image::open(&png).unwrap().to_rgb8());
        }
        let differing = images[0]
            .pixels()
            .zip(images[1].pixels())
            .filter(|(a, b)| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 2))
            .count();
        // The CPU/GPU image tolerance of tests/gpu.rs: 0.5% of pixels beyond 2 levels.
        assert!(differing * 200 <= 32 * 32, "{accel}: {differing} pixels differ");
    }
}

/// `info` describes the irregular grid's build phase by phase, takes its parameters, and
/// refuses bad ones with a message naming the parameter.
#[test]
fn info_prints_the_irregular_grid() {
    let (ok, text) = gridtrace(&[
        "info",
        "--scene",
        "knot-box",
        "--accel",
        "irregular:top=0.2",
        "--accel-params",
        "expand=1",
    ]);
    assert!(ok, "{text}");
    for want in [
        "irregular grid   top",
        "before merging",
        "second level",
        "expand",
        "voxel map",
        "refs",
    ] {
        assert!(text.contains(want), "missing '{want}' in:\n{text}");
    }
    for (bad, says) in [
        ("top=0", "top density"),
        ("cell=1e9", "cell density"),
        (
            "size=3",
            "'size=3': unknown key ('irregular' takes top, cell, alpha, merge, expand)",
        ),
    ] {
        let (ok, text) = gridtrace(&["info", "--scene", "knot-box", "--accel", &format!("irregular:{bad}")]);
        assert!(!ok && text.contains(says), "{bad}: {text}");
    }
}

#[test]
fn info_prints_grid_and_memory() {
    let (ok, text) = gridtrace(&["info", "--scene", "knot-box", "--accel", "grid:res=16"]);
    assert!(ok, "{text}");
    for want in ["triangles        1020", "16x16x16 = 4096 cells", "paper model", "refs"] {
        assert!(text.contains(want), "missing '{want}' in:\n{text}");
    }
}

/// `info` says what it describes, as the README does: by default the structure `auto` picks
/// (the BVH), named, with where the paper's memory model is; with `--accel pc` the grid and the
/// paper's model, M = n*96 + cells*16 = 1020*96 + 4096*16 = 163,456 B for the knot box.
#[test]
fn info_says_which_structure_it_describes() {
    let (ok, text) = gridtrace(&["info", "--scene", "knot-box"]);
    assert!(ok, "{text}");
    for want in [
        "accel            bvh (auto's pick; --accel grid or pc for the grid and the paper's memory model)",
        "structure        bvh ",
        "the paper's model is a uniform grid's: --accel grid or pc",
    ] {
        assert!(text.contains(want), "missing '{want}' in:\n{text}");
    }
    let (ok, text) = gridtrace(&[
        "info",
        "--scene",
        "knot-box",
        "--accel",
        "pc",
        "--accel-params",
        "res=16",
    ]);
    assert!(ok, "{text}");
    for want in [
        "accel            pc\n",
        "triangles        1020 ",
        "16x16x16 = 4096 cells",
        "159.6 KiB   (paper's model M = n*96 + cells*16)",
    ] {
        assert!(text.contains(want), "missing '{want}' in:\n{text}");
    }
}

#[test]
fn bad_input_gives_located_errors() {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let obj = dir.join("bad.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n").unwrap();
    let (ok, text) = gridtrace(&["info", obj.to_str().unwrap()]);
    assert!(!ok);
    assert!(text.contains("bad.obj") && text.contains("line 3"), "{text}");
    let (ok, text) = gridtrace(&["render", "--scene", "nope"]);
    assert!(!ok && text.contains("knot-box"), "{text}");
    // A scene name where a file goes: no such file, and the way to name a built-in scene.
    let (ok, text) = gridtrace(&["render", "mirror-spheres"]);
    assert!(
        !ok && text.contains("mirror-spheres: no such file; for a built-in scene use --scene NAME (knot-box"),
        "{text}"
    );
    let (ok, text) = gridtrace(&["render", "--scene", "knot-box", "--accel", "grid:res=0x1x1"]);
    assert!(
        !ok && text.contains("'res=0x1x1' of 'grid': grid resolution must be"),
        "{text}"
    );
    // Parameters for `auto`, which has not picked the structure that would read them; and a
    // key the structure does not read.
    let (ok, text) = gridtrace(&["render", "--scene", "knot-box", "--accel-params", "res=4"]);
    assert!(
        !ok && text.contains("parameters 'res=4' need a structure named"),
        "{text}"
    );
    let (ok, text) = gridtrace(&["render", "--scene", "knot-box", "--accel", "bvh:res=4"]);
    assert!(
        !ok && text.contains("'res=4': unknown key ('bvh' takes no parameters)"),
        "{text}"
    );
    let (ok, text) = gridtrace(&["info", dir.join("missing.ply").to_str().unwrap()]);
    assert!(!ok && text.contains("missing.ply"), "{text}");
    // Thread counts out of range are refused before any work (100,000 used to start that many
    // threads and sit for minutes).
    for bad in ["0", "100000", "1025"] {
        let (ok, text) = gridtrace(&["--threads", bad, "info"]);
        assert!(!ok && text.contains(&format!("'{bad}' for '--threads")), "{text}");
    }
}

/// A reader that leaves early (`gridtrace render ... | head -1`) ends the tool quietly, as it
/// ends Unix tools: by SIGPIPE at its next write, with nothing on stderr, never the panic
/// "failed printing to stdout: Broken pipe" (exit 101). Each command's stdout is closed before it
/// writes anything (so its first line meets a closed pipe), and the README's pipeline runs
/// through the shell, whose status is `head`'s.
#[cfg(unix)]
#[test]
fn closed_pipe_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;
    // SIGPIPE is 13 on Linux, macOS and the BSDs.
    const SIGPIPE: i32 = 13;
    let dir = scratch("pipe");
    let obj = dir.join("tet.obj");
    std::fs::write(&obj, TET_OBJ).unwrap();
    let rays = dir.join("one.rays");
    let ray: Vec<u8> = [0.2f32, 0.2, 2.0, 0.0, 0.0, -1.0]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .collect();
    std::fs::write(&rays, ray).unwrap();
    let path = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let (obj, rays) = (obj.to_str().unwrap(), rays.to_str().unwrap());
    let (png, hits, bench) = (path("k.png"), path("hits.bin"), path("bench"));
    let commands: Vec<Vec<&str>> = vec![
        vec![
            "render",
            "--scene",
            "knot-box",
            "--backend",
            "cpu",
            "--res",
            "32x24",
            "-o",
            &png,
        ],
        vec!["info", "--scene", "knot-box"],
        vec!["rays", obj, "--rays", rays, "--backend", "cpu", "--hits-out", &hits],
        vec![
            "view",
            "--headless",
            "--scene",
            "knot-box",
            "--backend",
            "cpu",
            "--res",
            "32x24",
            "--frames",
            "2",
        ],
        vec!["bench", "--quick", "--backend", "cpu", "--out", &bench],
        vec!["--version"],
    ];
    for args in &commands {
        let mut child = Command::new(env!("CARGO_BIN_EXE_gridtrace"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("run gridtrace");
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        // Killed by SIGPIPE at its first write to the closed pipe, as Unix tools are; or, when
        // it had written everything before the pipe was closed (`--version` can, it is quick),
        // a clean exit. Never the panic's exit 101.
        assert!(
            out.status.signal() == Some(SIGPIPE) || out.status.success(),
            "{args:?}: {:?}, stderr:\n{stderr}",
            out.status
        );
        assert!(
            !stderr.contains("panicked") && !stderr.contains("Broken pipe"),
            "{args:?}: {stderr}"
        );
    }
    let pipeline = format!(
        "'{}' render --scene knot-box --backend cpu --res 32x24 -o '{png}' | head -1",
        env!("CARGO_BIN_EXE_gridtrace")
    );
    let out = Command::new("sh").args(["-c", &pipeline]).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{pipeline}: {:?}, stderr:\n{stderr}", out.status);
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 1);
    assert!(
        !stderr.contains("panicked") && !stderr.contains("Broken pipe"),
        "{stderr}"
    );
}

/// Like [`gridtrace`], with stderr apart and the environment adjusted by `env`.
fn gridtrace_env(args: &[&str], env: impl FnOnce(&mut Command)) -> (bool, String, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_gridtrace"));
    cmd.args(args);
    env(&mut cmd);
    let out = cmd.output().expect("run gridtrace");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).to_string(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

/// A fresh scratch folder for one test.
fn scratch(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const TET_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

/// Every number and x,y,z option takes a value that starts with '-'. Without
/// `allow_hyphen_values`, clap reads `-0.0169,...` as an unknown flag ("unexpected argument
/// '-0' found") and advises "-- -1"; each case checks that the value reached its parser or
/// the command instead: a success, or an error about the value itself.
#[test]
fn negative_values_reach_every_number_and_vector_option() {
    let dir = scratch("negative");
    let png = dir.join("n.png");
    let png = png.to_str().unwrap();
    let obj = dir.join("tet.obj");
    std::fs::write(&obj, TET_OBJ).unwrap();
    let obj = obj.to_str().unwrap();
    // One ray from (0.2, 0.2, 2) down -z: it hits the tetrahedron.
    let rays = dir.join("one.rays");
    let ray: Vec<u8> = [0.2f32, 0.2, 2.0, 0.0, 0.0, -1.0]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .collect();
    std::fs::write(&rays, ray).unwrap();
    let rays = rays.to_str().unwrap();
    let hits = dir.join("hits.bin");
    let hits = hits.to_str().unwrap();
    let render = |extra: &[&str]| {
        let mut args = vec![
            "render",
            "--scene",
            "knot-box",
            "--backend",
            "cpu",
            "--mode",
            "cast",
            "--res",
            "8",
        ];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["-o", png]);
        args.iter().map(|s| s.to_string()).collect::<Vec<_>>()
    };
    let owned = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    // (option under test, arguments, None for success or Some(text the error must contain))
    let cases: Vec<(&str, Vec<String>, Option<&str>)> = vec![
        // The user report: a target with negative coordinates.
        (
            "render --target",
            render(&["--eye", "0.04,0.19,0.2", "--target", "-0.0169,0.1101,-0.0016"]),
            None,
        ),
        ("render --eye", render(&["--eye", "-1,2,3", "--target", "0,0,0"]), None),
        ("render --up", render(&["--up", "0,-1,0"]), None),
        (
            "render --light",
            render(&["--light", "-1,2,-3", "--light", "1,-2,3"]),
            None,
        ),
        (
            "render --vfov",
            render(&["--vfov", "-30"]),
            Some("vfov must be in (0, 180) degrees, got -30"),
        ),
        (
            "render --res",
            owned(&["render", "--scene", "knot-box", "--res", "-8"]),
            Some("invalid value '-8' for '--res"),
        ),
        (
            "rays --tmin",
            owned(&[
                "rays",
                obj,
                "--rays",
                rays,
                "--backend",
                "cpu",
                "--hits-out",
                hits,
                "--tmin",
                "-1",
            ]),
            Some("need 0 <= --tmin <= --tmax, got --tmin -1"),
        ),
        (
            "rays --tmax",
            owned(&[
                "rays",
                obj,
                "--rays",
                rays,
                "--backend",
                "cpu",
                "--hits-out",
                hits,
                "--tmax",
                "-1",
            ]),
            Some("need 0 <= --tmin <= --tmax, got --tmin 0 --tmax -1"),
        ),
        (
            "bench --warmup",
            owned(&["bench", "--quick", "--warmup", "-1"]),
            Some("invalid value '-1' for '--warmup"),
        ),
        (
            "bench --reps",
            owned(&["bench", "--quick", "--reps", "-2"]),
            Some("invalid value '-2' for '--reps"),
        ),
        (
            "bench --query-rays",
            owned(&["bench", "--quick", "--query-rays", "-5"]),
            Some("invalid value '-5' for '--query-rays"),
        ),
        (
            "bench --res",
            owned(&["bench", "--quick", "--res", "-64"]),
            Some("invalid value '-64' for '--res"),
        ),
        // Counts below their least: the value's own error, never clap's tip to write `-- -5`
        // (which makes -5 the scene file).
        (
            "render --frames",
            render(&["--frames", "-5"]),
            Some("invalid value '-5' for '--frames <FRAMES>': -5 is not in 1..=100000"),
        ),
        (
            "render --in-flight",
            render(&["--frames", "2", "--in-flight", "-1"]),
            Some("invalid value '-1' for '--in-flight"),
        ),
        (
            "render --fps",
            owned(&["render", "--animate", "--fps", "-30", "-o", png]),
            Some("--fps must be positive, got -30"),
        ),
        (
            "view --frames",
            owned(&["view", "--headless", "--frames", "-5"]),
            Some("invalid value '-5' for '--frames"),
        ),
        (
            "view --scale",
            owned(&["view", "--scale", "-1"]),
            Some("invalid value '-1' for '--scale"),
        ),
        (
            "view --budget-ms",
            owned(&["view", "--budget-ms", "-30"]),
            Some("--budget-ms must be positive, got -30"),
        ),
        (
            "--threads",
            owned(&["--threads", "-1", "info"]),
            Some("invalid value '-1' for '--threads"),
        ),
        (
            "rays --reps",
            owned(&["rays", obj, "--rays", rays, "--hits-out", hits, "--reps", "-2"]),
            Some("invalid value '-2' for '--reps"),
        ),
        (
            "rays --count",
            owned(&["rays", obj, "--rays", rays, "--make", "random", "--count", "-2"]),
            Some("invalid value '-2' for '--count"),
        ),
    ];
    let mut failures = Vec::new();
    for (what, args, want_err) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (ok, text) = gridtrace(&args);
        let clap_misread = text.contains("unexpected argument") || text.contains("-- -");
        let right = match want_err {
            None => ok,
            Some(want) => !ok && text.contains(want),
        };
        if clap_misread || !right {
            failures.push(format!("{what}: want {}:\n{text}", want_err.unwrap_or("success")));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// `--help` shows the x,y,z format, the values of --accel, --mode, --backend and
/// --gpu-variant, and that --res takes N; a zero size says it must be positive.
#[test]
fn help_shows_formats_and_values() {
    let (ok, help) = gridtrace(&["render", "--help"]);
    assert!(ok, "{help}");
    for want in [
        "--eye <X,Y,Z>",
        "--target <X,Y,Z>",
        "--up <X,Y,Z>",
        "--light <X,Y,Z[:R,G,B]>",
        "--res <WxH|N>",
        "N for a square N x N image",
        "- auto:      the structure measured fastest",
        "- brute:     no structure",
        "- irregular: an irregular grid",
        "parameters: top=0.12,cell=2,alpha=1,merge=8,expand=3",
        "--accel-params <ACCEL_PARAMS>",
        "[default: auto]",
        "[possible values: cast, shadow, trace, heat]",
        "[possible values: auto, gpu, cpu]",
    ] {
        assert!(help.contains(want), "render --help lacks '{want}':\n{help}");
    }
    // Every GPU variant key with its values, from the library's table, default first.
    for r in &gridtrace::gpu::variants::VARIANTS {
        let want = format!("- {}={}: ", r.key, r.values_text());
        assert!(help.contains(&want), "render --help lacks '{want}':\n{help}");
    }
    assert!(help.contains("appends=workgroup|per_ray|subgroup"), "{help}");
    let (ok, help) = gridtrace(&["bench", "--help"]);
    assert!(
        ok && help.contains("- irregular: ")
            && !help.contains("- auto:      the structure")
            && help.contains("--res <WxH|N>"),
        "{help}"
    );
    let (ok, help) = gridtrace(&["info", "--help"]);
    assert!(ok && help.contains("--with-floor"), "{help}");

    let (ok, text) = gridtrace(&["render", "--res", "0x0"]);
    assert!(!ok && text.contains("image size must be positive"), "{text}");
    let (ok, text) = gridtrace(&["render", "--res", "64x0"]);
    assert!(!ok && text.contains("image size must be positive"), "{text}");
    let (ok, text) = gridtrace(&["render", "--accel", "kd-tree"]);
    assert!(
        !ok && text
            .contains("accel must be 'auto', 'grid', 'pc', 'bvh', 'irregular', 'brute' or 'hwrt', got 'kd-tree'"),
        "{text}"
    );
    // The short aliases the library accepts still work.
    let (ok, text) = gridtrace(&["info", "--scene", "knot-box", "--accel", "proximity:res=4"]);
    assert!(ok, "{text}");
}

/// `--accel auto` (the default) names the structure it picked and why; under `--backend auto`
/// a software adapter alone is passed over for the CPU tracer, with a note saying so, and
/// `--backend gpu` still takes it.
#[test]
fn auto_says_what_it_picked() {
    let dir = scratch("auto");
    let png = dir.join("a.png");
    let args = |backend: &'static str| {
        [
            "render",
            "--scene",
            "knot-box",
            "--mode",
            "cast",
            "--res",
            "16",
            "--backend",
            backend,
            "-o",
        ]
        .map(String::from)
        .into_iter()
        .chain([png.display().to_string()])
        .collect::<Vec<_>>()
    };
    let run = |backend| {
        let a = args(backend);
        gridtrace(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let (ok, text) = run("cpu");
    assert!(
        ok && text.contains("note: accel auto: bvh (") && text.contains("scene knot-box") && text.contains("bvh "),
        "{text}"
    );
    let (ok, auto) = run("auto");
    assert!(ok, "{auto}");
    let (ok, gpu) = run("gpu");
    assert!(ok, "GPU tests need an adapter: {gpu}");
    if gpu.contains("Cpu, driver") || gpu.contains("software adapter") {
        assert!(
            auto.contains("note: the only adapter is a software rasteriser") && auto.contains("backend cpu"),
            "{auto}"
        );
    } else {
        assert!(auto.contains("backend gpu"), "{auto}");
    }
}

/// `info` on a mesh file describes the file: its own triangle count, no floor unless asked.
#[test]
fn info_counts_the_file_without_the_floor() {
    let dir = scratch("info-floor");
    let obj = dir.join("tet.obj");
    std::fs::write(&obj, TET_OBJ).unwrap();
    let (ok, text) = gridtrace(&["info", obj.to_str().unwrap()]);
    assert!(
        ok && text.contains("triangles        4 (0 degenerate"),
        "the file has 4: {text}"
    );
    let (ok, text) = gridtrace(&["info", "--mesh", obj.to_str().unwrap()]);
    assert!(ok && text.contains("triangles        4 ("), "{text}");
    let (ok, text) = gridtrace(&["info", obj.to_str().unwrap(), "--with-floor"]);
    assert!(
        ok && text.contains("triangles        6 ("),
        "4 + the 2-triangle floor: {text}"
    );
}

/// Without XDG_RUNTIME_DIR (or with a missing one) no "XDG_RUNTIME_DIR is invalid" line from
/// the graphics drivers: `main` points it at a private folder before anything opens the GPU.
/// `--backend auto` opens the GPU adapter where there is one (lavapipe counts), which is where
/// the line came from.
#[test]
fn no_xdg_runtime_dir_complaint() {
    let dir = scratch("xdg");
    let png = dir.join("x.png");
    let args = [
        "render",
        "--scene",
        "knot-box",
        "--backend",
        "auto",
        "--mode",
        "cast",
        "--res",
        "8",
        "-o",
        png.to_str().unwrap(),
    ];
    let (ok, _, stderr) = gridtrace_env(&args, |c| {
        c.env_remove("XDG_RUNTIME_DIR");
    });
    assert!(ok && !stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
    let (ok, _, stderr) = gridtrace_env(&args, |c| {
        c.env("XDG_RUNTIME_DIR", dir.join("missing"));
    });
    assert!(ok && !stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
}

/// A scene without lights renders (ambient only) with a warning that names it.
#[test]
fn scene_without_lights_warns() {
    let dir = scratch("nolights");
    let toml = dir.join("dark.toml");
    std::fs::write(
        &toml,
        "[camera]\neye=[0,1,4]\ntarget=[0,0,0]\n[[object]]\nshape=\"icosphere\"\nlevel=1\n",
    )
    .unwrap();
    let png = dir.join("d.png");
    let base = [
        "render",
        toml.to_str().unwrap(),
        "--backend",
        "cpu",
        "--res",
        "8",
        "-o",
        png.to_str().unwrap(),
    ];
    let (ok, _, stderr) = gridtrace_env(&base, |_| {});
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("warning: scene") && stderr.contains("dark.toml") && stderr.contains("no lights"),
        "{stderr}"
    );
    // A light from the command line silences it; so do the built-in scenes' own lights.
    let mut lit = base.to_vec();
    lit.extend_from_slice(&["--light", "1,3,2"]);
    let (ok, _, stderr) = gridtrace_env(&lit, |_| {});
    assert!(ok && !stderr.contains("no lights"), "{stderr}");
}

/// The shipped example scene renders, so the example and docs/scene-format.md cannot rot.
#[test]
fn example_scene_renders() {
    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/scene.toml");
    let dir = scratch("example");
    let png = dir.join("e.png");
    let (ok, stdout, stderr) = gridtrace_env(
        &[
            "render",
            example,
            "--backend",
            "cpu",
            "--res",
            "24x16",
            "-o",
            png.to_str().unwrap(),
        ],
        |_| {},
    );
    assert!(ok, "{stdout}{stderr}");
    assert!(!stderr.contains("warning"), "the example has lights: {stderr}");
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (24, 16));
}

/// `--frames N` renders N frames and reports the first and the median and best of the rest;
/// the PNG is the first frame, which `--orbit` leaves at the scene's own view. On the CPU and
/// on the GPU (lavapipe in CI).
#[test]
fn frames_and_orbit() {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-frames-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for backend in ["cpu", "gpu"] {
        let one = dir.join(format!("one-{backend}.png"));
        let many = dir.join(format!("many-{backend}.png"));
        let common = [
            "render",
            "--scene",
            "knot-box",
            "--mode",
            "shadow",
            "--res",
            "48x32",
            "--backend",
            backend,
        ];
        let (ok, text) = gridtrace(&[&common[..], &["-o", one.to_str().unwrap()]].concat());
        assert!(ok, "{text}");
        assert!(!text.contains("more"), "one frame reports no others: {text}");
        let (ok, text) =
            gridtrace(&[&common[..], &["--frames", "4", "--orbit", "-o", many.to_str().unwrap()]].concat());
        assert!(ok, "{text}");
        let line = text
            .lines()
            .find(|l| l.starts_with("frames"))
            .unwrap_or_else(|| panic!("no frames line: {text}"));
        // On the GPU two frames are in flight by default: a frame's time is its latency, and
        // the rate is the run's (frames/s and Mrays/s of wall time).
        let median = match backend {
            "cpu" => "3 more along the orbit: median",
            _ => "3 more along the orbit: latency median",
        };
        assert!(line.contains(median) && line.contains("best"), "{line}");
        assert!(backend == "gpu" || line.contains("Mrays/s"), "{line}");
        let rate = text
            .lines()
            .find(|l| l.starts_with("rate "))
            .unwrap_or_else(|| panic!("no rate line: {text}"));
        let how = if backend == "cpu" {
            "(one by one)"
        } else {
            "(2 in flight)"
        };
        assert!(
            rate.contains("frames/s") && rate.contains("Mrays/s") && rate.ends_with(how),
            "{rate}"
        );
        assert!(text.contains("first "), "the first frame is reported as such: {text}");
        let (a, b) = (
            image::open(&one).unwrap().to_rgb8(),
            image::open(&many).unwrap().to_rgb8(),
        );
        assert_eq!(
            a.as_raw(),
            b.as_raw(),
            "{backend}: the written image is the first frame"
        );
    }
    let (ok, text) = gridtrace(&["render", "--scene", "knot-box", "--frames", "0", "-o", "x.png"]);
    assert!(!ok && text.contains("--frames"), "{text}");
}

/// A scene over the GPU's buffer limits (a 300x300x160 grid: 173 MB of cells, over lavapipe's
/// 128 MiB per binding): `auto` traces it on the CPU with a note naming the limit, `gpu` fails
/// and suggests the CPU. On a GPU with larger bindings both render on the GPU.
#[test]
fn auto_falls_back_to_the_cpu_when_the_scene_does_not_fit() {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-fit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("fit.png");
    let args = |backend| {
        [
            "render",
            "--scene",
            "knot-box",
            "--accel",
            "grid:res=300x300x160",
            "--mode",
            "cast",
            "--res",
            "16",
            "--backend",
            backend,
            "-o",
            png.to_str().unwrap(),
        ]
        .map(String::from)
    };
    let run = |backend| {
        let a = args(backend);
        gridtrace(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let (ok, text) = run("auto");
    assert!(ok, "{text}");
    let on_gpu = text.lines().any(|l| l.starts_with("backend gpu"));
    // A software adapter alone (lavapipe in CI) is passed over before the scene is checked
    // (the library's own test covers the fallback on a given device: tests/gpu.rs).
    let software = text.contains("software rasteriser");
    assert!(
        on_gpu || software || (text.contains("note: the GPU cannot trace this scene") && text.contains("'cells'")),
        "{text}"
    );
    let (ok, text) = run("gpu");
    assert_eq!(ok, on_gpu, "{text}");
    if !ok {
        assert!(text.contains("use --backend cpu"), "{text}");
    }
}

#[test]
fn version_names_the_release_the_commit_and_the_cpu_path() {
    // The commit the build script read: this checkout's HEAD, or "unknown" outside git.
    let head = Command::new("git")
        .args(["-C", env!("CARGO_MANIFEST_DIR"), "rev-parse", "--short", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    let commit = std::env::var("GRIDTRACE_GIT_COMMIT")
        .ok()
        .filter(|c| !c.trim().is_empty())
        .or(head)
        .unwrap_or_else(|| "unknown".into());
    let first = format!("gridtrace {} (commit {commit})", env!("CARGO_PKG_VERSION"));

    let (ok, text) = gridtrace(&["--version"]);
    assert!(ok, "{text}");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 2, "{text}");
    assert_eq!(lines[0], first);
    assert_eq!(lines[1], format!("cpu: {}", gridtrace::cpu_features()));

    let (ok, text) = gridtrace(&["-V"]);
    assert!(ok, "{text}");
    assert_eq!(text.trim_end(), first);
}

/// `rays` on the GPU answers as on the CPU (closest hits: the same triangle, t within 1e-5;
/// occlusion: the same bits) and reports the batch as `render` reports a frame: wall and GPU
/// time, one round trip, the bytes each way (16 down a ray for closest hits).
#[test]
fn rays_on_the_gpu_answer_as_on_the_cpu_and_report_the_batch() {
    let dir = scratch("rays-gpu");
    let obj = dir.join("tet.obj");
    std::fs::write(&obj, TET_OBJ).unwrap();
    // 400 rays from a ring around the tetrahedron towards points near it: hits and misses.
    let mut bytes = Vec::new();
    for i in 0..400 {
        let a = i as f32 * 0.137;
        let o = [2.0 * a.cos(), 2.0 * a.sin(), 0.3 + (i % 7) as f32 * 0.1];
        let target = [0.3 * (i % 5) as f32 - 0.2, 0.25 * (i % 3) as f32, 0.2];
        let d = [target[0] - o[0], target[1] - o[1], target[2] - o[2]];
        for f in o.iter().chain(&d) {
            bytes.extend_from_slice(&f.to_le_bytes());
        }
    }
    let rays = dir.join("ring.rays");
    std::fs::write(&rays, bytes).unwrap();
    let (obj, rays) = (obj.to_str().unwrap(), rays.to_str().unwrap());
    let run = |backend: &str, occluded: bool| {
        let out = dir.join(format!("{backend}-{occluded}.bin"));
        let mut args = vec!["rays", obj, "--rays", rays, "--backend", backend, "--hits-out"];
        args.push(out.to_str().unwrap());
        if occluded {
            args.extend_from_slice(&["--occluded", "--tmax", "2.0"]);
        }
        let (ok, text) = gridtrace(&args);
        assert!(ok, "rays --backend {backend}:\n{text}");
        (std::fs::read(&out).unwrap(), text)
    };
    let (cpu, _) = run("cpu", false);
    let (gpu, text) = run("gpu", false);
    assert_eq!(cpu.len(), 400 * 16);
    let mut hit = 0;
    for (c, g) in cpu.chunks(16).zip(gpu.chunks(16)) {
        let t = |b: &[u8]| f32::from_le_bytes(b[0..4].try_into().unwrap());
        assert_eq!(c[4..8], g[4..8], "triangle");
        if t(c).is_finite() {
            hit += 1;
            assert!(
                (t(c) - t(g)).abs() <= 1e-5 * t(c).abs().max(1.0),
                "t {} vs {}",
                t(c),
                t(g)
            );
        }
    }
    assert!(hit > 0 && hit < 400, "{hit} of 400 rays hit");
    let line = text
        .lines()
        .find(|l| l.starts_with("gpu "))
        .unwrap_or_else(|| panic!("no gpu line:\n{text}"));
    assert!(line.contains("wall ") && line.contains("1 round trip,"), "{line}");
    let down: u64 = line
        .split(" B down")
        .next()
        .unwrap()
        .rsplit(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(down >= 400 * 16, "{line}");
    // The wall time's parts on the host: prepare, wait, readout, each a number of ms.
    let host = text
        .lines()
        .find(|l| l.starts_with("host "))
        .unwrap_or_else(|| panic!("no host line:\n{text}"));
    let parts: Vec<f64> = ["prepare ", "wait ", "readout "]
        .iter()
        .map(|k| {
            let v = host.split(k).nth(1).unwrap_or_else(|| panic!("{k}in {host}"));
            v.split([',', ' ']).next().unwrap().parse().unwrap()
        })
        .collect();
    assert!(parts.iter().all(|&ms| ms >= 0.0) && parts[1] > 0.0, "{host}");
    let (cpu, _) = run("cpu", true);
    let (gpu, _) = run("gpu", true);
    assert_eq!(cpu, gpu, "occlusion");
    assert!(cpu.contains(&0) && cpu.contains(&1));

    // `--reps 3`: three passes timed, the answers those of one pass, the GPU's figures one
    // pass's (one round trip, not three).
    for backend in ["cpu", "gpu"] {
        let out = dir.join(format!("{backend}-reps.bin"));
        let args = [
            "rays",
            obj,
            "--rays",
            rays,
            "--backend",
            backend,
            "--reps",
            "3",
            "--hits-out",
            out.to_str().unwrap(),
        ];
        let (ok, text) = gridtrace(&args);
        assert!(ok, "{text}");
        assert_eq!(
            std::fs::read(&out).unwrap(),
            run(backend, false).0,
            "{backend}: --reps 3 answers otherwise"
        );
        let line = text
            .lines()
            .find(|l| l.starts_with("rays "))
            .unwrap_or_else(|| panic!("{text}"));
        assert!(
            line.contains("median of 3 passes") && line.ends_with("Mrays/s"),
            "{line}"
        );
        if backend == "gpu" {
            assert!(
                text.lines()
                    .any(|l| l.starts_with("gpu ") && l.contains("1 round trip,")),
                "{text}"
            );
        }
    }
}

/// A run's exit code (`None` when a signal ended it) and its stdout then stderr.
type Status = (Option<i32>, String);

/// Runs the `gridtrace` binary; its exit status and its stdout then stderr.
fn gridtrace_status(args: &[&str]) -> Status {
    let out = Command::new(env!("CARGO_BIN_EXE_gridtrace"))
        .args(args)
        .output()
        .expect("run gridtrace");
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.code(), text)
}

/// What a new user runs into, refused before any work and in words that say what is wrong:
/// argument errors exit 2 (clap's status) without a line of work printed ("scene ..."), a
/// renamed image says it is not OBJ text, a folder given for rays says it is a folder.
#[test]
fn mistakes_are_refused_before_any_work_in_plain_words() {
    let dir = scratch("mistakes");
    let png = dir.join("n.png");
    let png = png.to_str().unwrap();
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "--scene", "knot-box", "--backend", "cpu"];
        args.extend_from_slice(extra);
        gridtrace_status(&args)
    };
    let missing = dir.join("no-such-folder").join("x.png");
    let hits = dir.join("hits.bin");
    // (what, (exit code, what the command printed), the words the error must hold)
    let cases: Vec<(&str, Status, &str)> = vec![
        (
            "a size above the tracers' largest",
            render(&["--res", "100000x100000", "-o", png]),
            "image size 100000x100000 is too large: at most 16384 pixels a side",
        ),
        (
            "-o into a missing folder",
            render(&["-o", missing.to_str().unwrap()]),
            "/no-such-folder does not exist (make it first)",
        ),
        (
            "-o a folder",
            render(&["-o", dir.to_str().unwrap()]),
            "is a directory, not a file",
        ),
        (
            "-o a format no encoder writes",
            render(&["-o", dir.join("x.tiff").to_str().unwrap()]),
            "x.tiff' for '--output <OUTPUT>': the image format follows the extension; this build writes .",
        ),
        (
            "--frames below 1",
            render(&["--frames", "-5", "-o", png]),
            "invalid value '-5' for '--frames <FRAMES>': -5 is not in 1..=100000",
        ),
        (
            "a bad grid parameter",
            render(&["--accel", "grid:res=0x1x1", "-o", png]),
            "accel parameter 'res=0x1x1' of 'grid': grid resolution must be",
        ),
        (
            "a key the structure does not read",
            render(&["--accel", "bvh", "--accel-params", "res=4", "-o", png]),
            "'res=4': unknown key ('bvh' takes no parameters)",
        ),
        (
            "rays --hits-out into a missing folder",
            gridtrace_status(&[
                "rays",
                "x.obj",
                "--rays",
                "r.bin",
                "--hits-out",
                missing.to_str().unwrap(),
            ]),
            "/no-such-folder does not exist (make it first)",
        ),
    ];
    let mut failures = Vec::new();
    for (what, (code, text), want) in cases {
        if code != Some(2) || !text.contains(want) || text.contains("scene knot-box") || text.contains("-- -") {
            failures.push(format!("{what}: want exit 2 and '{want}', got {code:?}:\n{text}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));

    // A PNG renamed .obj: not OBJ text, where that was seen, and what it looks like.
    let fake = dir.join("image.obj");
    std::fs::write(&fake, b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0\0\x10\0\0\0\x10\x08\x02").unwrap();
    let (code, text) = gridtrace_status(&["info", fake.to_str().unwrap()]);
    assert!(
        code == Some(1)
            && text.contains("image.obj:line 1: not an OBJ text file: binary data")
            && text.contains("it starts as a PNG image does"),
        "{code:?}: {text}"
    );
    // A folder given as the ray file: "is a directory", as render says of a folder for a mesh
    // (its size, 4096 bytes, is no count of rays).
    let obj = dir.join("tet.obj");
    std::fs::write(&obj, TET_OBJ).unwrap();
    let (code, text) = gridtrace_status(&[
        "rays",
        obj.to_str().unwrap(),
        "--rays",
        dir.to_str().unwrap(),
        "--hits-out",
        hits.to_str().unwrap(),
    ]);
    assert!(
        code == Some(1) && text.contains("is a directory, not a ray file") && !text.contains("4096"),
        "{code:?}: {text}"
    );
    // `-o o.jpg` writes a JPEG, as --help says it does.
    let jpg = dir.join("o.jpg");
    let (code, text) = render(&["--res", "8", "-o", jpg.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{text}");
    assert_eq!(std::fs::read(&jpg).unwrap()[..3], [0xFF, 0xD8, 0xFF], "a JPEG");
    let (_, help) = gridtrace_status(&["render", "--help"]);
    assert!(
        help.contains("Output image: PNG, or JPEG for a .jpg or .jpeg name"),
        "{help}"
    );
}

/// `rays --make` writes ray files the `rays` command reads: `random` from a sphere of one
/// bounding-box diagonal around the mesh, aimed into its box; `camera` from one eye (the
/// auto-framed view's), onto the mesh.
#[test]
fn rays_make_writes_ray_files() {
    let dir = scratch("make-rays");
    let obj = dir.join("tet.obj");
    std::fs::write(&obj, TET_OBJ).unwrap();
    let obj = obj.to_str().unwrap();
    let read = |path: &std::path::Path| -> Vec<[f32; 6]> {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(bytes.len() % 24, 0);
        bytes
            .chunks(24)
            .map(|r| std::array::from_fn(|k| f32::from_le_bytes(r[4 * k..4 * k + 4].try_into().unwrap())))
            .collect()
    };
    // The tetrahedron's box is [0, 1]^3: centre 0.5, diagonal sqrt(3).
    let random = dir.join("random.bin");
    let (code, text) = gridtrace_status(&[
        "rays",
        obj,
        "--make",
        "random",
        "--count",
        "500",
        "--rays",
        random.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("500 random rays"), "{text}");
    let rays = read(&random);
    assert_eq!(rays.len(), 500);
    for r in &rays {
        let o = [r[0] - 0.5, r[1] - 0.5, r[2] - 0.5];
        let dist = (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt();
        assert!((dist - 3f32.sqrt()).abs() < 1e-4, "origin {r:?} at {dist}");
        // Aimed at a point of the box: the ray's line passes through it (slab test).
        let (mut t0, mut t1) = (f32::NEG_INFINITY, f32::INFINITY);
        for k in 0..3 {
            let (a, b) = ((0.0 - r[k]) / r[k + 3], (1.0 - r[k]) / r[k + 3]);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        assert!(t0 <= t1 + 1e-5 && t1 > 0.0, "ray {r:?} misses the box");
    }
    let camera = dir.join("camera.bin");
    let (code, text) = gridtrace_status(&[
        "rays",
        obj,
        "--make",
        "camera",
        "--count",
        "64",
        "--rays",
        camera.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{text}");
    let cam = read(&camera);
    assert_eq!(cam.len(), 64);
    assert!(cam.iter().all(|r| r[..3] == cam[0][..3]), "one eye");
    // Both files traced: camera rays hit the mesh they frame, some random rays hit and some
    // miss (the box's far corner is empty).
    let trace = |rays: &std::path::Path| {
        let out = rays.with_extension("hits");
        let (code, text) = gridtrace_status(&[
            "rays",
            obj,
            "--backend",
            "cpu",
            "--rays",
            rays.to_str().unwrap(),
            "--hits-out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(code, Some(0), "{text}");
        let bytes = std::fs::read(out).unwrap();
        bytes
            .chunks(16)
            .map(|h| u32::from_le_bytes(h[4..8].try_into().unwrap()) != u32::MAX)
            .collect::<Vec<bool>>()
    };
    let hit = trace(&camera);
    assert!(hit.iter().any(|h| *h), "no camera ray hits the mesh it frames");
    let hit = trace(&random);
    let n = hit.iter().filter(|h| **h).count();
    assert!(n > 0 && n < 500, "{n} of 500 random rays hit");
}

/// `render --animate` names the frames its median covers as its table numbers them (from 0).
#[test]
fn animate_median_names_the_table_frames() {
    let dir = scratch("animate");
    let (code, text) = gridtrace_status(&[
        "render",
        "--animate",
        "--scene",
        "bouncing-spheres",
        "--frames",
        "3",
        "--res",
        "8",
        "--backend",
        "cpu",
        "--accel",
        "bvh",
        "-o",
        dir.join("a.png").to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{text}");
    let frames: Vec<u32> = text
        .lines()
        .skip_while(|l| !l.starts_with("frame "))
        .skip(1)
        .map_while(|l| l.split_whitespace().next()?.parse().ok())
        .collect();
    assert_eq!(frames, [0, 1, 2], "{text}");
    assert!(text.contains("median of frames 1-2:"), "{text}");
}

/// `render --animate` opens its tracer as a still frame does: `--gpu-variant` reaches the GPU
/// (it once opened the device with the default variants, whatever was asked), and the
/// `backend` line names the variants as `render`'s does.
#[test]
fn animate_runs_the_gpu_variant_asked_for() {
    if std::env::var_os("GRIDTRACE_SKIP_GPU").is_some() {
        eprintln!("GRIDTRACE_SKIP_GPU is set: skipping");
        return;
    }
    let dir = scratch("animate-variant");
    let args = |animate: bool| {
        let scene = if animate { "bouncing-spheres" } else { "knot-box" };
        let mut v = vec!["render", "--scene", scene, "--res", "8", "--backend", "gpu"];
        v.extend(["--accel", "bvh", "--gpu-variant", "bvh=wide8,stack=private"]);
        if animate {
            v.extend(["--animate", "--frames", "2"]);
        }
        v
    };
    for animate in [false, true] {
        let mut a = args(animate);
        let png = dir.join(format!("{animate}.png"));
        a.extend(["-o", png.to_str().unwrap()]);
        let (code, text) = gridtrace_status(&a);
        assert_eq!(code, Some(0), "{text}");
        assert!(
            text.contains("gpu variants: bvh=wide8,stack=private"),
            "animate {animate}: {text}"
        );
    }
}
