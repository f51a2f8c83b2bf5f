//! `render --animate --scene tumbling-bunnies`: rigid instances moved by the top level alone.
//! Frames are played end to end on the CPU and on the GPU (lavapipe in CI): the structure
//! builds stay 1 in every frame's row, the frames written differ (things move), and bad
//! counts and missing meshes are errors naming the argument or the file. (That the frames
//! equal the instances merged flat is `gridtrace`'s `tests/tumbling.rs`.)

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
