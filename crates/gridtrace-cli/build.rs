//! Records the git commit the tool is built from, for `gridtrace --version`: `GRIDTRACE_GIT_COMMIT`
//! when set (a packager's override), else `git rev-parse --short HEAD`, else "unknown" (no git, or
//! not a checkout: an sdist, a copied tree).

use std::path::{Path, PathBuf};
use std::process::Command;

fn git(dir: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git").arg("-C").arg(dir).args(args).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let s = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (!s.is_empty()).then_some(s)
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=GRIDTRACE_GIT_COMMIT");
    let dir = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap());
    let commit = match std::env::var("GRIDTRACE_GIT_COMMIT") {
        Ok(c) if !c.trim().is_empty() => c.trim().to_string(),
        _ => git(&dir, &["rev-parse", "--short", "HEAD"]).unwrap_or_else(|| "unknown".into()),
    };
    println!("cargo:rustc-env=GRIDTRACE_GIT_COMMIT={commit}");

    // Build again when HEAD moves: HEAD itself (a checkout, a detached commit), the branch it
    // names (a commit on it) and packed-refs (where the branch may live). In a worktree HEAD is
    // in the worktree's git dir and the branches in the common one. Only files that exist: cargo
    // reruns every build for a missing one.
    let abs = |p: String| {
        let p = PathBuf::from(p);
        if p.is_absolute() { p } else { dir.join(p) }
    };
    let (Some(git_dir), Some(common)) = (
        git(&dir, &["rev-parse", "--git-dir"]).map(abs),
        git(&dir, &["rev-parse", "--git-common-dir"]).map(abs),
    ) else {
        return;
    };
    let mut watch = vec![git_dir.join("HEAD"), common.join("packed-refs")];
    if let Some(branch) = git(&dir, &["symbolic-ref", "-q", "HEAD"]) {
        watch.push(common.join(branch));
    }
    for p in watch.iter().filter(|p| p.is_file()) {
        println!("cargo:rerun-if-changed={}", p.display());
    }
}
