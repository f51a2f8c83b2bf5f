//! `gridtrace rays --counts` and the `query` line of `rays`: the counts of every hit on the GPU
//! equal the CPU's, ray for ray; the line names the query and the device that answered, and
//! for GPU work the bytes each way (24 up a ray for the rays themselves).

mod common;

use common::gridtrace;

/// Two octahedra, the second shifted half its size along x: rays through both cross four
/// faces, rays through their overlap more; rays through a vertex or an edge meet faces at one
/// `t` (Open3D's rule counts each such crossing once).
const TWO_OCTAHEDRA: &str = "\
v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n\
v 1.5 0.2 0\nv -0.5 0.2 0\nv 0.5 1.2 0\nv 0.5 -0.8 0\nv 0.5 0.2 1\nv 0.5 0.2 -1\n\
f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n\
f 7 9 11\nf 9 8 11\nf 8 10 11\nf 10 7 11\nf 9 7 12\nf 8 9 12\nf 10 8 12\nf 7 10 12\n";

fn scratch(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("gridtrace-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// 500 rays from a ring around the octahedra towards points near them: misses, and hits of
/// one octahedron, of both, and of their overlap.
fn ring_rays(path: &std::path::Path) -> usize {
    let mut bytes = Vec::new();
    let n = 500;
    for i in 0..n {
        let a = i as f32 * 0.137;
        let o = [3.0 * a.cos(), 3.0 * a.sin(), 0.4 * ((i % 9) as f32 - 4.0) / 4.0];
        let target = [
            0.3 * (i % 7) as f32 - 0.6,
            0.2 * (i % 5) as f32 - 0.3,
            0.1 * (i % 3) as f32,
        ];
        let d = [target[0] - o[0], target[1] - o[1], target[2] - o[2]];
        for f in o.iter().chain(&d) {
            bytes.extend_from_slice(&f.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
    n
}

/// The `query` line of a run's output.
fn query_line(text: &str) -> &str {
    text.lines()
        .find(|l| l.starts_with("query "))
        .unwrap_or_else(|| panic!("no query line:\n{text}"))
}

/// The number before `what` on `line` ("9856 B up" gives 9856 for " B up").
fn number_before(line: &str, what: &str) -> u64 {
    let head = line.split(what).next().unwrap_or_else(|| panic!("{what} in {line}"));
    head.rsplit(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap_or_else(|e| panic!("{line}: {e}"))
}

#[test]
fn counts_on_the_gpu_equal_the_cpu_and_say_where_they_ran() {
    let dir = scratch("rays-counts");
    let obj = dir.join("two.obj");
    std::fs::write(&obj, TWO_OCTAHEDRA).unwrap();
    let rays = dir.join("ring.rays");
    let n = ring_rays(&rays);
    let (obj, rays) = (obj.to_str().unwrap(), rays.to_str().unwrap());
    let skip_gpu = std::env::var_os("GRIDTRACE_SKIP_GPU").is_some();
    for accel in ["bvh", "irregular"] {
        let run = |backend: &str| {
            let out = dir.join(format!("{accel}-{backend}.counts"));
            let args = [
                "rays",
                obj,
                "--rays",
                rays,
                "--counts",
                "--accel",
                accel,
                "--backend",
                backend,
                "--hits-out",
                out.to_str().unwrap(),
            ];
            let (ok, text) = gridtrace(&args);
            assert!(ok, "rays --counts --backend {backend}:\n{text}");
            let counts: Vec<u32> = std::fs::read(&out)
                .unwrap()
                .chunks(4)
                .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
                .collect();
            (counts, text)
        };
        let (cpu, text) = run("cpu");
        assert_eq!(cpu.len(), n);
        // The summary is the file's: the total of hits and the rays with one.
        let total: u64 = cpu.iter().map(|&c| u64::from(c)).sum();
        let with = cpu.iter().filter(|&&c| c > 0).count();
        let summary = text.lines().find(|l| l.starts_with("rays ")).unwrap();
        assert!(
            summary.contains(&format!(" {total} hits, {with} rays hit,")),
            "{summary}"
        );
        assert!(with > 50 && with < n, "{with} of {n} rays hit");
        assert!(cpu.iter().any(|&c| c >= 4), "rays through both octahedra");
        assert_eq!(query_line(&text), "query   count_intersections on cpu", "{text}");
        if skip_gpu {
            continue;
        }
        let (gpu, text) = run("gpu");
        assert_eq!(gpu, cpu, "{accel}: the GPU's counts");
        let line = query_line(&text);
        assert!(line.starts_with("query   count_intersections on gpu, "), "{line}");
        // The rays go up as they are in the file, 24 bytes each, with the chunk's constants;
        // a count comes down for each, with the timestamps.
        let (up, down) = (number_before(line, " B up"), number_before(line, " B down"));
        assert!(up >= 24 * n as u64 && up < 24 * n as u64 + 4096, "{line}");
        assert!(down >= 4 * n as u64 && down < 4 * n as u64 + 4096, "{line}");
    }
}

/// Closest hits and occlusion say where they ran too; on the GPU, closest hits bring 24 bytes
/// a ray up and the chunk's constants (256 bytes: counters 64, the batch's constants 48, the
/// pass uniforms 3 x 48), exactly, and 16 bytes a ray down with the timestamps.
#[test]
fn closest_hits_and_occlusion_say_where_they_ran() {
    let dir = scratch("rays-query-line");
    let obj = dir.join("two.obj");
    std::fs::write(&obj, TWO_OCTAHEDRA).unwrap();
    let rays = dir.join("ring.rays");
    let n = ring_rays(&rays) as u64;
    let (obj, rays) = (obj.to_str().unwrap(), rays.to_str().unwrap());
    let out = dir.join("hits.bin");
    let out = out.to_str().unwrap();
    let run = |backend: &str, occluded: bool| {
        let mut args = vec!["rays", obj, "--rays", rays, "--backend", backend, "--hits-out", out];
        if occluded {
            args.push("--occluded");
        }
        let (ok, text) = gridtrace(&args);
        assert!(ok, "{text}");
        query_line(&text).to_string()
    };
    assert_eq!(run("cpu", false), "query   intersect on cpu");
    assert_eq!(run("cpu", true), "query   occluded on cpu");
    if std::env::var_os("GRIDTRACE_SKIP_GPU").is_some() {
        return;
    }
    let line = run("gpu", false);
    assert!(line.starts_with("query   intersect on gpu, "), "{line}");
    assert_eq!(number_before(&line, " B up"), 24 * n + 256, "{line}");
    let down = number_before(&line, " B down");
    assert!(down >= 16 * n && down < 16 * n + 4096, "{line}");
    let line = run("gpu", true);
    assert!(line.starts_with("query   occluded on gpu, "), "{line}");
    assert!(number_before(&line, " B up") >= 24 * n, "{line}");
}
