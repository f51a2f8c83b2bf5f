//! `gridtrace info FILE` on every file of the bad-input corpus: a non-zero exit, one error line
//! naming the file and the place in it, and never a panic.

use std::process::Command;

use gridtrace::testing::bad_input_corpus;

#[test]
fn info_on_bad_files_fails_cleanly() {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-corpus-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut failures = Vec::new();
    let corpus = bad_input_corpus();
    for f in &corpus {
        let path = dir.join(f.name);
        std::fs::write(&path, &f.bytes).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_gridtrace"))
            .args(["info", path.to_str().unwrap()])
            .output()
            .expect("run gridtrace");
        let stderr = String::from_utf8_lossy(&out.stderr);
        let line = stderr.lines().find(|l| l.starts_with("error: ")).unwrap_or("");
        if out.status.success() {
            failures.push(format!("{}: exit 0", f.name));
        } else if stderr.contains("panicked") || out.status.code() != Some(1) {
            failures.push(format!("{}: {:?}: {stderr}", f.name, out.status));
        } else if !line.contains(f.name) || !line.contains(f.location) {
            failures.push(format!("{}: want the name and '{}' in: {stderr}", f.name, f.location));
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        failures.is_empty(),
        "{} of {} files:\n{}",
        failures.len(),
        corpus.len(),
        failures.join("\n")
    );
}

/// `--backend gpu` with no adapter is an error; `auto` falls back to the CPU and says so.
/// `WGPU_BACKEND=dx12` leaves wgpu no adapter on Linux (`Backends::with_env`); elsewhere
/// `GRIDTRACE_ADAPTER` naming no adapter does the same.
#[test]
fn no_adapter_is_an_error_or_a_fallback() {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-noadapter-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |backend: &str, env: (&str, &str)| {
        let out = Command::new(env!("CARGO_BIN_EXE_gridtrace"))
            .args([
                "render",
                "--scene",
                "knot-box",
                "--res",
                "16x12",
                "--backend",
                backend,
                "-o",
            ])
            .arg(dir.join("x.png"))
            .env(env.0, env.1)
            .output()
            .expect("run gridtrace");
        let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
        (out.status.code(), text)
    };
    let envs: &[(&str, &str)] = if cfg!(target_os = "linux") {
        &[("WGPU_BACKEND", "dx12"), ("GRIDTRACE_ADAPTER", "no-such-adapter-xyz")]
    } else {
        &[("GRIDTRACE_ADAPTER", "no-such-adapter-xyz")]
    };
    for &env in envs {
        let (code, text) = run("gpu", env);
        assert_eq!(code, Some(1), "{env:?}: {text}");
        assert!(
            text.contains("error: gpu:") && !text.contains("panicked"),
            "{env:?}: {text}"
        );
        let (code, text) = run("auto", env);
        assert_eq!(code, Some(0), "{env:?}: {text}");
        assert!(
            text.contains("no usable GPU") && text.contains("backend cpu"),
            "{env:?}: {text}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
