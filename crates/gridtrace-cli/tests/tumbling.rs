//! `render --animate --scene tumbling-bunnies`: rigid instances moved by the top level alone.
//! Frames are played end to end on the CPU and on the GPU (lavapipe in CI): the structure
//! builds stay 1 in every frame's row, the frames written differ (things move), and bad
//! counts and missing meshes are errors naming the argument or the file. --mode, --light and
//! the camera options change the frames (shadows only darken), and what cannot apply (heat,
//! shadows of the headlight, a camera that makes no rays) is refused naming the option. (That
//! the frames equal the instances merged flat is `gridtrace`'s `tests/tumbling.rs`.)

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::gridtrace;

fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("gridtrace-tumbling-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A lopsided double pyramid (its turns show in an image), as an OBJ in `dir`.
fn write_mesh(dir: &Path) -> PathBuf {
    let obj = dir.join("gem.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 2 0 0\nv 0 1 0\nv 0 0 1.5\nv 0 0 -0.5\n\
         f 1 2 3\nf 2 4 3\nf 1 4 2\nf 1 3 4\nf 1 3 5\nf 3 2 5\nf 2 1 5\n",
    )
    .unwrap();
    obj
}

/// The table's rows: (frame, builds, where traced).
fn rows(text: &str) -> Vec<(u32, usize, String)> {
    text.lines()
        .skip_while(|l| !l.starts_with("frame "))
        .skip(1)
        .map_while(|l| {
            let c: Vec<&str> = l.split_whitespace().collect();
            Some((c.first()?.parse().ok()?, c.get(6)?.parse().ok()?, c.get(7)?.to_string()))
        })
        .collect()
}

/// Plays 3 frames of 20 instances at 64x48 on `backend`; checks the table and the frames.
fn play(backend: &str, mesh: Option<&Path>, tag: &str) -> String {
    let dir = scratch(tag);
    let (png, seq) = (dir.join("first.png"), dir.join("seq"));
    let mut args = vec![
        "render",
        "--animate",
        "--scene",
        "tumbling-bunnies",
        "--instances",
        "20",
        "--frames",
        "3",
        "--fps",
        "4",
        "--res",
        "64x48",
        "--backend",
        backend,
        "--sequence",
        seq.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
    ];
    if let Some(m) = mesh {
        args.extend(["--instance-mesh", m.to_str().unwrap()]);
    }
    let (ok, text) = gridtrace(&args);
    assert!(ok, "{text}");
    let rows = rows(&text);
    assert_eq!(rows.len(), 3, "{text}");
    for (f, (frame, builds, on)) in rows.iter().enumerate() {
        assert_eq!(*frame as usize, f, "{text}");
        assert_eq!(*builds, 1, "frame {f}: the one mesh's structure alone: {text}");
        assert_eq!(on, if backend == "gpu" { "gpu" } else { "cpu" }, "{text}");
    }
    assert!(text.contains("median of frames 1-2: move "), "{text}");
    assert!(text.contains("structure builds 1 [20 instances bvh 64x48]"), "{text}");
    let frames: Vec<Vec<u8>> = (0..3)
        .map(|i| {
            let img = image::open(seq.join(format!("frame_{i:04}.png"))).unwrap().to_rgb8();
            assert_eq!(img.dimensions(), (64, 48));
            img.into_raw()
        })
        .collect();
    assert_eq!(
        image::open(&png).unwrap().to_rgb8().into_raw(),
        frames[0],
        "-o is frame 0"
    );
    for f in 1..3 {
        let moved = frames[f - 1]
            .chunks(3)
            .zip(frames[f].chunks(3))
            .filter(|(a, b)| a != b)
            .count();
        assert!(moved > 64, "frames {} and {f}: {moved} pixels differ: {text}", f - 1);
    }
    text
}

#[test]
fn plays_on_the_cpu() {
    let dir = scratch("cpu-mesh");
    play("cpu", Some(&write_mesh(&dir)), "cpu");
    // The Bunny itself, where the mesh folder has it (the default mesh).
    let (ok, text) = gridtrace(&[
        "render",
        "--animate",
        "--scene",
        "tumbling-bunnies",
        "--instances",
        "1",
        "--frames",
        "2",
        "--res",
        "4",
        "--backend",
        "cpu",
        "-o",
        dir.join("b.png").to_str().unwrap(),
    ]);
    if ok {
        // One instance: no `add_instance`, still the two levels from the first query (one
        // structure, not a merged mesh and then the two levels' mesh).
        assert!(text.contains("structure builds 1 [1 instances"), "{text}");
        play("cpu", None, "cpu-bunny");
    } else {
        assert!(text.contains("bun_zipper.ply"), "{text}");
        eprintln!("no Bunny here: {text}");
    }
}

#[test]
fn plays_on_the_gpu() {
    if std::env::var_os("GRIDTRACE_SKIP_GPU").is_some() {
        eprintln!("GRIDTRACE_SKIP_GPU is set: skipping");
        return;
    }
    let dir = scratch("gpu-mesh");
    let text = play("gpu", Some(&write_mesh(&dir)), "gpu");
    assert!(text.contains("gpu     meshes uploaded 1 time(s)"), "{text}");
    // The shadow rays on the GPU too: the CPU's frame but for a few pixels at the gems' edges
    // (the GPU's triangle test rounds in f32 where the CPU decides exact zeros in f64).
    let lit = ["--light", "0.5,3.5,0.5", "--mode", "shadow"];
    let (ok, text, gpu) = frame_on("gpu", "gpu-shadow", &lit);
    assert!(ok && text.contains("with shadows"), "{text}");
    let (_, _, cpu) = frame("cpu-shadow", &lit);
    assert!(differing(&cpu, &gpu) <= 20, "{} pixels differ", differing(&cpu, &gpu));
}

#[test]
fn bad_input_names_the_argument_or_file() {
    let dir = scratch("bad");
    let png = dir.join("x.png");
    let png = png.to_str().unwrap();
    let mesh = write_mesh(&dir);
    let base = [
        "render",
        "--animate",
        "--scene",
        "tumbling-bunnies",
        "--res",
        "8",
        "--backend",
        "cpu",
        "-o",
        png,
    ];
    let run = |more: &[&str]| {
        let mut a: Vec<&str> = base.to_vec();
        a.extend(more);
        gridtrace(&a)
    };
    for n in ["0", "-3", "1000001", "99999999999", "many"] {
        let (ok, text) = run(&["--instance-mesh", mesh.to_str().unwrap(), "--instances", n]);
        assert!(!ok, "--instances {n}: {text}");
        assert!(
            text.contains("--instances") && text.contains(n),
            "--instances {n}: {text}"
        );
        assert!(!text.contains("panicked"), "{text}");
    }
    let missing = dir.join("no-such-mesh.ply");
    let (ok, text) = run(&["--instance-mesh", missing.to_str().unwrap()]);
    assert!(!ok && text.contains("no-such-mesh.ply"), "{text}");
    // The default mesh missing from the mesh folder names the file it looked for.
    let empty = scratch("empty-data");
    let out = Command::new(env!("CARGO_BIN_EXE_gridtrace"))
        .args(base)
        .env("GRIDTRACE_DATA_DIR", &empty)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{text}");
    assert!(
        text.contains(&empty.join("bunny/bun_zipper.ply").display().to_string()) && text.contains("--instance-mesh"),
        "{text}"
    );
    // --instances belongs to this scene alone.
    let (ok, text) = gridtrace(&[
        "render",
        "--animate",
        "--scene",
        "bouncing-spheres",
        "--instances",
        "5",
        "--res",
        "8",
        "-o",
        png,
    ]);
    assert!(
        !ok && text.contains("--instances") && text.contains("tumbling-bunnies"),
        "{text}"
    );
}

/// One frame of 8 gems at 96x72 on the CPU with the options `more`: whether it ran, the text,
/// and the frame's RGB bytes (empty where it failed).
fn frame(tag: &str, more: &[&str]) -> (bool, String, Vec<u8>) {
    frame_on("cpu", tag, more)
}

/// `frame` on `backend`.
fn frame_on(backend: &str, tag: &str, more: &[&str]) -> (bool, String, Vec<u8>) {
    let dir = scratch(tag);
    let png = dir.join("f.png");
    let mesh = write_mesh(&dir);
    let mut args = vec![
        "render",
        "--animate",
        "--scene",
        "tumbling-bunnies",
        "--instance-mesh",
        mesh.to_str().unwrap(),
        "--instances",
        "8",
        "--frames",
        "1",
        "--res",
        "96x72",
        "--backend",
        backend,
        "-o",
        png.to_str().unwrap(),
    ];
    args.extend(more);
    let (ok, text) = gridtrace(&args);
    let rgb = if ok {
        image::open(&png).unwrap().to_rgb8().into_raw()
    } else {
        Vec::new()
    };
    (ok, text, rgb)
}

/// Pixels (RGB triples) that differ between two frames.
fn differing(a: &[u8], b: &[u8]) -> usize {
    a.chunks(3).zip(b.chunks(3)).filter(|(p, q)| p != q).count()
}

/// Issue 52: the tumbling frames take --mode, --light and the camera as a still frame does.
/// (The gems cover about 400 of the 6,912 pixels; the light shadows about 70 of them.)
/// Cast is the default (the headlight); a light above the lattice (the upper gems over the
/// lower ones) lights otherwise; its shadows only darken, somewhere; trace is shadow (nothing
/// reflects, and the run says so); another eye sees another frame.
#[test]
fn mode_light_and_camera_change_the_frames() {
    let ok_frame = |tag: &str, more: &[&str]| {
        let (ok, text, rgb) = frame(tag, more);
        assert!(ok, "{more:?}: {text}");
        (text, rgb)
    };
    let (text, headlight) = ok_frame("default", &[]);
    assert!(text.contains("mode cast, lit by a headlight"), "{text}");
    assert_eq!(
        ok_frame("cast", &["--mode", "cast"]).1,
        headlight,
        "cast is the default"
    );
    let light = ["--light", "0.5,3.5,0.5"];
    let (text, lit) = ok_frame("lit", &light);
    assert!(text.contains("mode cast, 1 light(s)"), "{text}");
    assert!(differing(&headlight, &lit) > 150, "the light changes the frame");
    let (text, shadowed) = ok_frame("shadow", &[&light[..], &["--mode", "shadow"]].concat());
    assert!(text.contains("mode shadow, 1 light(s) with shadows"), "{text}");
    let darker = lit
        .chunks(3)
        .zip(shadowed.chunks(3))
        .filter(|(l, s)| {
            assert!(
                s.iter().zip(l.iter()).all(|(s, l)| s <= l),
                "a shadow brightens: {l:?} {s:?}"
            );
            s != l
        })
        .count();
    assert!(darker > 20, "{darker} pixels in shadow");
    let (text, traced) = ok_frame("trace", &[&light[..], &["--mode", "trace"]].concat());
    assert_eq!(traced, shadowed, "trace is shadow: nothing reflects");
    assert!(text.contains("nothing in tumbling-bunnies reflects"), "{text}");
    let (_, moved) = ok_frame("eye", &["--eye", "0.5,0.5,6"]);
    assert!(differing(&headlight, &moved) > 150, "another eye");
    let (_, narrow) = ok_frame("vfov", &["--vfov", "20"]);
    assert!(differing(&headlight, &narrow) > 150, "another field of view");
}

/// What cannot apply is refused, naming the option: heat (no traversal counts through the two
/// levels), shadows without --light (the headlight's are out of sight), a camera that makes
/// no rays, and the still renders' --orbit, --stats and --in-flight (clap's conflict, naming
/// both options: they were silently ignored).
#[test]
fn modes_and_cameras_that_cannot_apply_are_refused() {
    for (more, words) in [
        (&["--mode", "heat"][..], &["--mode heat", "count no traversal work"][..]),
        (&["--mode", "shadow"], &["--mode shadow", "--light X,Y,Z"]),
        (&["--mode", "trace"], &["--mode trace", "--light X,Y,Z"]),
        (
            &["--eye", "1,2,3", "--target", "1,2,3"],
            &["--eye 1,2,3 --target 1,2,3", "eye equals target"],
        ),
        (&["--vfov", "190"], &["--vfov 190", "(0, 180)"]),
        // Straight down onto the lattice's middle (0.5, 0.5, 0.5), with y up.
        (
            &["--eye", "0.5,3,0.5", "--up", "0,1,0"],
            &["--eye 0.5,3,0.5 --up 0,1,0", "parallel"],
        ),
        (&["--orbit"], &["--orbit", "--animate", "cannot be used with"]),
        (&["--stats"], &["--stats", "--animate", "cannot be used with"]),
        (
            &["--in-flight", "1"],
            &["--in-flight", "--animate", "cannot be used with"],
        ),
    ] {
        let (ok, text, _) = frame("bad-view", more);
        assert!(!ok, "{more:?}: {text}");
        for w in words {
            assert!(text.contains(w), "{more:?}: lacks '{w}': {text}");
        }
        assert!(!text.contains("panicked"), "{text}");
    }
}

/// The vertex animations take the camera options too (they traced the scene's own camera).
#[test]
fn vertex_animations_take_the_camera() {
    let dir = scratch("spheres");
    let run = |tag: &str, more: &[&str]| {
        let png = dir.join(format!("{tag}.png"));
        let mut args = vec![
            "render",
            "--animate",
            "--scene",
            "bouncing-spheres",
            "--frames",
            "1",
            "--res",
            "48x36",
            "--mode",
            "cast",
            "--backend",
            "cpu",
            "-o",
            png.to_str().unwrap(),
        ];
        args.extend(more);
        let (ok, text) = gridtrace(&args);
        assert!(ok, "{more:?}: {text}");
        image::open(&png).unwrap().to_rgb8().into_raw()
    };
    let (a, b) = (run("own", &[]), run("narrow", &["--vfov", "15"]));
    assert!(differing(&a, &b) > 200, "--vfov changes the frame");
}
