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

/// The `key=value` fields of each "screenshot PATH ..." line.
fn screenshots(out: &str) -> Vec<(PathBuf, HashMap<String, String>)> {
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

/// Orbit, zoom, switch modes and structures (grid, bvh, then the irregular grid), resize (to 1x1, to nothing, back): every
/// screenshot is `render`'s image of what it printed, on the CPU bit for bit, and on the GPU
/// within the CPU/GPU tolerance of the GPU tests (0.5% of pixels beyond 2 levels).
#[test]
fn scripted_session_equals_render() {
    if !have_display() {
        return;
    }
    for backend in ["cpu", "gpu"] {
        let d = dir(backend);
        let script = d.join("s.txt");
        std::fs::write(
            &script,
            "key 2\ndrag 40 -20\nzoom 1\nscreenshot a.png\nkey g\nkey g\nkey 3\nscreenshot b.png\n\
             resize 1 1\nresize 0 0\nresize 120 90\nkey g\nkey 1\ndrag -80 10\nkey f\nkey w\nkey d\nkey e\nscreenshot c.png\n",
        )
        .unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_gridtrace"))
            .current_dir(&d)
            .args([
                "view",
                "--scene",
                "knot-box",
                "--res",
                "96x72",
                "--backend",
                backend,
                "--script",
            ])
            .arg(&script)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{backend}: {text}");
        let shots = screenshots(&text);
        let want = [
            ("shadow", "grid", "96x72"),
            ("trace", "bvh", "96x72"),
            ("cast", "irregular", "120x90"),
        ];
        assert_eq!(shots.len(), want.len(), "{text}");
        for ((path, kv), (mode, accel, res)) in shots.iter().zip(want) {
            assert_eq!(
                (kv["mode"].as_str(), kv["accel"].as_str(), kv["res"].as_str()),
                (mode, accel, res)
            );
            let shot = d.join(path);
            let reference = d.join(format!("render-{}", path.display()));
            let (ok, rtext) = gridtrace(&[
                "render",
                "--scene",
                "knot-box",
                "--backend",
                "cpu",
                "--eye",
                &kv["eye"],
                "--target",
                &kv["target"],
                "--up",
                &kv["up"],
                "--vfov",
                &kv["vfov"],
                "--mode",
                mode,
                "--accel",
                accel,
                "--res",
                res,
                "-o",
                reference.to_str().unwrap(),
            ]);
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
        // The orbit moved the camera between the first and the last screenshot.
        assert_ne!(shots[0].1["eye"], shots[2].1["eye"]);
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
