//! `gridtrace view` in a real window, driven by a script (Xvfb + lavapipe in CI): each
//! screenshot equals `gridtrace render` of the camera, mode and structure it prints.
//!
//! Without a display these tests fail when `CI` is set (CI runs them under xvfb-run: a window
//! test that skips there proves nothing) and are skipped with a message otherwise.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::gridtrace;

fn have_display() -> bool {
    if std::env::var_os("DISPLAY").is_some() {
        return true;
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "no DISPLAY: CI runs the window tests under xvfb-run (scripts/test.sh)"
    );
    eprintln!("no DISPLAY: window test skipped (run under xvfb-run)");
    false
}

fn dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("gridtrace-view-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A screenshot's file and the `key=value` fields its line printed.
type Shot = (PathBuf, HashMap<String, String>);

/// The `key=value` fields of each "screenshot PATH ..." line.
fn screenshots(out: &str) -> Vec<Shot> {
    out.lines()
        .filter_map(|l| l.strip_prefix("screenshot "))
        .map(|l| {
            let mut words = l.split_whitespace();
            let path = PathBuf::from(words.next().unwrap());
            let kv = words
                .filter_map(|w| w.split_once('='))
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect();
            (path, kv)
        })
        .collect()
}

/// Fraction of pixels whose channels differ by more than 2 levels.
fn differing(a: &Path, b: &Path) -> f64 {
    let (a, b) = (image::open(a).unwrap().to_rgb8(), image::open(b).unwrap().to_rgb8());
    assert_eq!(a.dimensions(), b.dimensions());
    let n = a
        .pixels()
        .zip(b.pixels())
        .filter(|(p, q)| p.0.iter().zip(q.0).any(|(x, y)| x.abs_diff(y) > 2))
        .count();
    n as f64 / (a.width() * a.height()) as f64
}

/// Runs `view` with `script` (written to the test's folder) on `backend` and extra
/// arguments; the folder, the output (stdout then stderr) and the screenshots it printed.
fn run_script(tag: &str, backend: &str, args: &[&str], script: &str) -> (PathBuf, String, Vec<Shot>) {
    let d = dir(&format!("{tag}-{backend}"));
    let file = d.join("s.txt");
    std::fs::write(&file, script).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_gridtrace"))
        .current_dir(&d)
        .arg("view")
        .args(args)
        .args(["--backend", backend, "--script"])
        .arg(&file)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{backend}: {text}");
    let shots = screenshots(&text);
    (d, text, shots)
}

/// `render`'s image of what a screenshot line printed (camera, lights, mode, structure, size)
/// of `scene` (render's arguments naming it) equals the screenshot: on the CPU bit for bit, on
/// the GPU within the CPU/GPU tolerance of the GPU tests (0.5% of pixels beyond 2 levels).
fn equals_render(d: &Path, backend: &str, scene: &[&str], (path, kv): &Shot) {
    let shot = d.join(path);
    let reference = d.join(format!("render-{}", path.display()));
    let mut args: Vec<String> = vec!["render".into()];
    args.extend(scene.iter().map(|s| s.to_string()));
    for k in ["eye", "target", "up", "vfov", "mode", "accel", "res"] {
        args.push(format!("--{k}"));
        args.push(kv[k].clone());
    }
    for l in kv["lights"].split(';').filter(|l| !l.is_empty()) {
        args.push("--light".into());
        args.push(l.into());
    }
    args.extend([
        "--backend".into(),
        "cpu".into(),
        "-o".into(),
        reference.display().to_string(),
    ]);
    let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let (ok, rtext) = gridtrace(&args);
    assert!(ok, "{rtext}");
    let frac = differing(&shot, &reference);
    if backend == "cpu" {
        assert_eq!(
            frac,
            0.0,
            "{}: the viewer's CPU frame differs from render's",
            path.display()
        );
    } else {
        assert!(
            frac <= 0.005,
            "{}: {:.3}% of pixels differ",
            path.display(),
            frac * 100.0
        );
    }
}

/// Orbit, zoom, switch modes and structures (grid, bvh, then the irregular grid), move the
/// lights (a gizmo drag, a key), change the resolution scale, resize (to 1x1, to nothing, back):
/// every screenshot is `render`'s image of the camera, lights, mode and size it printed.
#[test]
fn scripted_session_equals_render() {
    if !have_display() {
        return;
    }
    for backend in ["cpu", "gpu"] {
        let (d, text, shots) = run_script(
            "session",
            backend,
            &["--scene", "knot-box", "--res", "96x72", "--accel", "grid"],
            "key 2\ndrag 40 -20\nzoom 1\npan 6 -4\nscreenshot a.png\nkey g\nkey g\nkey 3\nlight 12 -6\nscreenshot b.png\n\
             resize 1 1\nresize 0 0\nresize 120 90\nkey g\nkey 1\ndrag -80 10\nkey f\nkey w\nkey d\nkey e\n\
             key l\nkey right\nkey pageup\nkey [\nscreenshot c.png\nkey ]\nkey 4\nscreenshot d.png\n",
        );
        let want = [
            ("shadow", "grid", "96x72"),
            ("trace", "bvh", "96x72"),
            ("cast", "irregular", "60x45"),
            ("heat", "irregular", "120x90"),
        ];
        assert_eq!(shots.len(), want.len(), "{text}");
        for (shot, (mode, accel, res)) in shots.iter().zip(want) {
            let kv = &shot.1;
            assert_eq!(
                (kv["mode"].as_str(), kv["accel"].as_str(), kv["res"].as_str()),
                (mode, accel, res)
            );
            equals_render(&d, backend, &["--scene", "knot-box"], shot);
        }
        // The orbit moved the camera between the first and the last screenshot, and the
        // gizmo drag and the keys moved the lights.
        assert_ne!(shots[0].1["eye"], shots[2].1["eye"]);
        assert_ne!(shots[0].1["lights"], shots[1].1["lights"]);
        assert_ne!(shots[1].1["lights"], shots[2].1["lights"]);
    }
}

/// Files dropped on the window: a malformed one leaves the scene on screen and shows its error
/// (in the overlay and on stderr), a good one replaces the scene; the overlay names the tracer
/// and the scene and counts under 1 KiB sent to the GPU per frame; resizing to 8192x8192 and
/// back works; a capture of the window has its size.
#[test]
fn dropped_files_and_the_overlay() {
    if !have_display() {
        return;
    }
    for backend in ["cpu", "gpu"] {
        let d = dir(&format!("drop-files-{backend}"));
        let good = d.join("good.obj");
        std::fs::write(
            &good,
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
        )
        .unwrap();
        let bad = d.join("bad.obj");
        std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
        let script = format!(
            "overlay o1.txt\ndrop {}\noverlay o2.txt\nscreenshot a.png\ndrop {}\nscreenshot b.png\noverlay o3.txt\n\
             resize 8192 8192\nkey [\nkey [\nkey [\nresize 100 80\nkey ]\nkey ]\nkey ]\ncapture w.png\n",
            bad.display(),
            good.display()
        );
        let (d2, text, shots) = run_script("drop", backend, &["--scene", "knot-box", "--res", "96x72"], &script);
        let read = |f: &str| std::fs::read_to_string(d2.join(f)).unwrap();
        let (o1, o2, o3) = (read("o1.txt"), read("o2.txt"), read("o3.txt"));
        let tracer = if backend == "gpu" {
            "tracer    gpu:"
        } else {
            "tracer    cpu"
        };
        assert!(
            o1.contains(tracer) && o1.contains("scene     knot-box: 1020 triangles"),
            "{o1}"
        );
        assert!(!o1.contains("error"), "{o1}");
        if backend == "gpu" {
            let bytes_of = |prefix: &str| {
                let line = o1
                    .lines()
                    .find(|l| l.starts_with(prefix))
                    .unwrap_or_else(|| panic!("no {prefix} line: {o1}"));
                let bytes: u64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
                (bytes, line.to_string())
            };
            let (up, line) = bytes_of("uploaded");
            assert!(up > 0 && up < 1024, "{line}");
            // The window is presented from the tracer's device: the frame's 96x72 pixels are
            // not read back, only its counters and timestamps.
            assert!(o1.contains("the tracer's device: frames stay on the GPU"), "{o1}");
            let (down, line) = bytes_of("readback");
            assert!(
                down > 0 && down < 96 * 72 * 4 && line.contains("stayed on the GPU"),
                "{line}"
            );
        }
        // The bad file: its error names the file and line, the scene stays.
        assert!(
            text.contains(&format!("drop {}: error: {}:line 4", bad.display(), bad.display())),
            "{text}"
        );
        assert!(
            o2.contains("error") && o2.contains("bad.obj:line 4") && o2.contains("knot-box"),
            "{o2}"
        );
        equals_render(&d2, backend, &["--scene", "knot-box"], &shots[0]);
        // The good file replaces it (four triangles and the floor under them).
        assert!(
            text.contains(&format!("drop {}: loaded 6 triangles", good.display())),
            "{text}"
        );
        assert!(!o3.contains("error") && o3.contains("good.obj: 6 triangles"), "{o3}");
        equals_render(&d2, backend, &[good.to_str().unwrap()], &shots[1]);
        let w = image::open(d2.join("w.png")).unwrap().to_rgb8();
        assert_eq!(w.dimensions(), (100, 80));
        assert!(w.pixels().any(|p| p != w.get_pixel(0, 0)), "the capture is blank");
    }
}

/// What the window shows is the traced frame: with the overlay hidden, a capture of the window
/// equals the screenshot (read back from the tracer's device on the GPU, where the frame is
/// presented from; from the host's image on the CPU), within one level for a surface's sRGB
/// round trip; at half resolution each traced pixel covers a 2x2 block; a heat frame (made on
/// the host, drawn from the texture) equals its screenshot too.
#[test]
fn the_window_shows_the_traced_frame() {
    if !have_display() {
        return;
    }
    for backend in ["cpu", "gpu"] {
        let (d, text, shots) = run_script(
            "window",
            backend,
            &["--scene", "knot-box", "--res", "96x72", "--accel", "bvh"],
            "key h\nscreenshot a.png\ncapture a-window.png\noverlay a.txt\nkey 3\nkey [\nscreenshot b.png\ncapture b-window.png\n\
             key ]\nkey 4\nscreenshot c.png\ncapture c-window.png\n",
        );
        assert_eq!(shots.len(), 3, "{text}");
        let overlay = std::fs::read_to_string(d.join("a.txt")).unwrap();
        assert_eq!(
            overlay.contains("the image stayed on the GPU"),
            backend == "gpu",
            "{backend}: {overlay}"
        );
        for (shot, block) in [("a", 1), ("b", 2), ("c", 1)] {
            let traced = image::open(d.join(format!("{shot}.png"))).unwrap().to_rgb8();
            let window = image::open(d.join(format!("{shot}-window.png"))).unwrap().to_rgb8();
            assert_eq!(window.dimensions(), (96, 72), "{backend} {shot}");
            assert_eq!(traced.dimensions(), (96 / block, 72 / block), "{backend} {shot}");
            let mut worst = 0;
            for (x, y, p) in window.enumerate_pixels() {
                let q = traced.get_pixel(x / block, y / block);
                for c in 0..3 {
                    worst = worst.max(p.0[c].abs_diff(q.0[c]));
                }
            }
            assert!(
                worst <= 1,
                "{backend} {shot}: the window is {worst} levels off the frame"
            );
            assert!(
                traced.pixels().any(|p| p != traced.get_pixel(0, 0)),
                "{backend} {shot}: a blank frame"
            );
        }
        equals_render(&d, backend, &["--scene", "knot-box"], &shots[0]);
    }
}

/// A bad script is an error naming the file and line, before any window opens (no display
/// needed).
#[test]
fn bad_script_names_file_and_line() {
    let d = dir("bad");
    let script = d.join("bad.txt");
    std::fs::write(&script, "key 2\nfly 3 4\n").unwrap();
    let (ok, text) = gridtrace(&["view", "--scene", "knot-box", "--script", script.to_str().unwrap()]);
    assert!(!ok);
    assert!(
        text.contains("bad.txt:2") && text.contains("unknown command 'fly'"),
        "{text}"
    );
}

/// An animated scene plays in the window (a fixed step per presented frame in scripts), space
/// pauses it, and a structure opened later starts at the animation's time.
#[test]
fn animated_scene_plays_and_pauses() {
    if !have_display() {
        return;
    }
    let (d, text, _) = run_script(
        "anim",
        "cpu",
        &["--scene", "bouncing-spheres", "--res", "64x48", "--accel", "pc"],
        "overlay a1.txt\nkey 2\noverlay a2.txt\nkey space\noverlay a3.txt\nkey 1\noverlay a4.txt\nkey g\noverlay a5.txt\n",
    );
    let time = |f: &str| -> (f32, String) {
        let o = std::fs::read_to_string(d.join(f)).unwrap();
        let line = o
            .lines()
            .find(|l| l.starts_with("animation"))
            .unwrap_or_else(|| panic!("no animation line in {f}: {o}\n{text}"))
            .to_string();
        let t: f32 = line.split_whitespace().nth(3).unwrap().parse().unwrap();
        (t, line)
    };
    let (t1, _) = time("a1.txt");
    let (t2, l2) = time("a2.txt");
    let (t3, l3) = time("a3.txt");
    let (t4, l4) = time("a4.txt");
    let (t5, l5) = time("a5.txt");
    assert!(t2 > t1 && l2.contains("playing"), "{l2}");
    assert!(l3.contains("paused") && l4.contains("paused"), "{l3} / {l4}");
    assert_eq!((t3, t4, t5), (t3, t3, t3), "{l5}");
    // The BVH, opened while paused, was refitted to the paused pose.
    assert!(l5.contains("refit"), "{l5}");
}
