//! The command-line tool end to end: renders, statistics, and errors that name the file.

use std::process::Command;

fn gridtrace(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_gridtrace"))
        .args(args)
        .output()
        .expect("run gridtrace");
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}

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
    assert!(text.contains("6 triangles"), "4 + the 2-triangle floor: {text}");
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
        "pc",
        "--grid",
        "4x4x4",
        "-o",
        dir.join("b.png").to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    assert!(text.contains("grid 4x4x4"), "{text}");
}

/// The BVH renders on the CPU; `auto` picks the CPU for it and `gpu` is a clear error.
#[test]
fn bvh_renders_on_the_cpu_only() {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-bvh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("bvh.png");
    let args = |backend| {
        [
            "render",
            "--scene",
            "knot-box",
            "--accel",
            "bvh",
            "--res",
            "32",
            "--backend",
            backend,
            "-o",
            png.to_str().unwrap(),
        ]
    };
    let (ok, text) = gridtrace(&args("auto"));
    assert!(ok, "{text}");
    assert!(text.contains("CPU only") && png.exists(), "{text}");
    let (ok, text) = gridtrace(&args("gpu"));
    assert!(!ok && text.contains("bvh acceleration runs on the CPU only"), "{text}");
}

#[test]
fn info_prints_grid_and_memory() {
    let (ok, text) = gridtrace(&["info", "--scene", "knot-box", "--grid", "16"]);
    assert!(ok, "{text}");
    for want in ["triangles        1020", "16x16x16 = 4096 cells", "paper model", "refs"] {
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
    let (ok, text) = gridtrace(&["render", "--scene", "knot-box", "--grid", "0x1x1"]);
    assert!(!ok && text.contains("grid"), "{text}");
    let (ok, text) = gridtrace(&["info", dir.join("missing.ply").to_str().unwrap()]);
    assert!(!ok && text.contains("missing.ply"), "{text}");
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


/// Without XDG_RUNTIME_DIR (or with a missing one) no "XDG_RUNTIME_DIR is invalid" line from
/// the graphics drivers: `main` points it at a private folder before anything opens the GPU.
/// `--backend auto` opens the GPU adapter where there is one (lavapipe counts), which is where
/// the line came from.
#[test]
fn no_xdg_runtime_dir_complaint() {
    let dir = scratch("xdg");
    let png = dir.join("x.png");
    let args = ["render", "--scene", "knot-box", "--backend", "auto", "--mode", "cast", "--res", "8", "-o", png.to_str().unwrap()];
    let (ok, _, stderr) = gridtrace_env(&args, |c| {
        c.env_remove("XDG_RUNTIME_DIR");
    });
    assert!(ok && !stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
    let (ok, _, stderr) = gridtrace_env(&args, |c| {
        c.env("XDG_RUNTIME_DIR", dir.join("missing"));
    });
    assert!(ok && !stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
}