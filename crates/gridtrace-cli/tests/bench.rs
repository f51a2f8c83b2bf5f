//! `gridtrace bench --quick`: the reports are written, well formed and agree with each other.

mod common;
use common::gridtrace;

#[test]
fn quick_bench_writes_consistent_reports() {
    let dir = std::env::temp_dir().join(format!("gridtrace-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let rays = dir.join("rays.bin");
    let hits = dir.join("hits.bin");
    std::fs::create_dir_all(&dir).unwrap();
    let (ok, text) = gridtrace(&[
        "bench",
        "--quick",
        "--backend",
        "cpu",
        "--out",
        dir.to_str().unwrap(),
        "--export-rays",
        rays.to_str().unwrap(),
        "--export-hits",
        hits.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    assert!(text.contains("scene torus-knot: 1020 triangles"), "{text}");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("bench.json")).unwrap()).expect("bench.json parses");
    assert!(json["machine"]["cpu_model"].as_str().is_some_and(|s| !s.is_empty()));
    assert!(json["machine"]["logical_cores"].as_u64().unwrap() >= 1);
    assert!(json["gridtrace_version"].as_str().is_some());
    assert!(json["command_line"].as_array().unwrap().len() > 2);
    let rows = json["rows"].as_array().unwrap();
    let scenes = json["scenes"].as_array().unwrap();
    assert!(!scenes.is_empty());
    // Every scene that ran: 3 modes x 2 accels at one resolution on the CPU.
    assert_eq!(rows.len(), scenes.len() * 6, "{text}");
    for s in scenes {
        assert!(s["triangles"].as_u64().unwrap() > 0);
        assert!(s["memory_cpu_total"].as_u64().unwrap() > 0);
        assert!(s["memory_paper_model"].as_u64().unwrap() > 0);
    }
    for r in rows {
        let best = r["best_ms"].as_f64().unwrap();
        let median = r["median_ms"].as_f64().unwrap();
        assert!(best > 0.0 && median >= best, "{r}");
        let times = r["times_ms"].as_array().unwrap();
        assert_eq!(times.len(), 3);
        let min = times.iter().map(|t| t.as_f64().unwrap()).fold(f64::INFINITY, f64::min);
        assert_eq!(min, best);
        assert_eq!((r["width"].as_u64(), r["height"].as_u64()), (Some(128), Some(128)));
        let eye = r["rays"]["eye"].as_u64().unwrap();
        assert_eq!(eye, 128 * 128, "one eye ray per pixel: {r}");
        let total = r["rays"]["total"].as_u64().unwrap();
        let shadow = r["rays"]["shadow"].as_u64().unwrap();
        let refl = r["rays"]["reflection"].as_u64().unwrap();
        assert_eq!(total, eye + shadow + refl);
        match r["mode"].as_str().unwrap() {
            "cast" => assert_eq!(total, 128 * 128, "cast: eye rays only"),
            "shadow" => assert!(shadow > 0 && refl == 0),
            "trace" => assert!(shadow > 0),
            m => panic!("unexpected mode {m}"),
        }
        // Not the paper's resolutions: no paper figure to compare with.
        assert!(r["paper_ms"].is_null());
    }

    let csv = std::fs::read_to_string(dir.join("bench.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert!(lines[0].starts_with("scene,backend,mode,accel,width,height"));
    assert_eq!(lines.len(), rows.len() + 1);
    let cols = lines[0].split(',').count();
    assert!(lines.iter().all(|l| l.split(',').count() == cols));

    let md = std::fs::read_to_string(dir.join("bench.md")).unwrap();
    for h in [
        "Table 1: ray casting",
        "Table 2: shadow casting",
        "Table 3: ray tracing",
    ] {
        assert!(md.contains(h), "missing {h}: {md}");
    }
    assert!(
        md.contains("| rendering resolution |") && md.contains("| 128 x 128 |"),
        "{md}"
    );
    assert!(md.contains("Torus knot n = 1020 (paper 1024) g"), "{md}");

    let pngs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    let named = |prefix: &str| {
        pngs.iter()
            .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with(prefix))
            .count()
    };
    assert_eq!(
        named("time_vs_resolution_"),
        scenes.len(),
        "one chart per scene: {pngs:?}"
    );
    assert_eq!(named("scene_"), scenes.len(), "one picture per scene: {pngs:?}");
    for p in pngs {
        let img = image::open(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(img.width() > 100 && img.height() > 100);
    }

    // Exported rays: the trace mode of the first scene at 128x128.
    let export = &json["ray_export"];
    let n =
        export["eye"].as_u64().unwrap() + export["shadow"].as_u64().unwrap() + export["reflection"].as_u64().unwrap();
    assert_eq!(export["eye"].as_u64(), Some(128 * 128));
    assert_eq!(std::fs::metadata(&rays).unwrap().len(), n * 24);
    assert_eq!(std::fs::metadata(&hits).unwrap().len(), n * 4);
}

#[test]
fn bench_rejects_unknown_scene() {
    let (ok, text) = gridtrace(&["bench", "--quick", "--scenes", "teapot", "--backend", "cpu"]);
    assert!(!ok);
    assert!(text.contains("unknown scene 'teapot'"), "{text}");
}

/// `bench --build-scaling`: one point per mesh, smallest first, with the grid's own figures (its
/// references are at least its triangles: each is in a cell), the exported triangles byte for
/// byte the right size, Embree's figures joined by name, and a malformed Embree file an error
/// that names it.
#[test]
fn build_scaling_exports_and_joins_embree() {
    let dir = std::env::temp_dir().join(format!("gridtrace-build-scaling-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let meshes = dir.join("meshes");
    let embree = dir.join("embree.json");
    std::fs::write(&embree, r#"{"icosphere-3": 0.5, "icosphere-4": 1.5}"#).unwrap();
    // An empty data folder: the procedural meshes only, the same on every machine.
    let no_files = dir.join("no-files");
    std::fs::create_dir_all(&no_files).unwrap();
    let args = |extra: &[&str]| {
        let mut v = vec![
            "bench",
            "--quick",
            "--backend",
            "cpu",
            "--scenes",
            "knot-box",
            "--build-scaling",
            "--build-max-tris",
            "6000",
            "--data-dir",
            no_files.to_str().unwrap(),
        ];
        v.extend_from_slice(extra);
        v.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let a = args(&[
        "--out",
        dir.to_str().unwrap(),
        "--export-meshes",
        meshes.to_str().unwrap(),
        "--embree",
        embree.to_str().unwrap(),
    ]);
    let (ok, text) = gridtrace(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{text}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("bench.json")).unwrap()).unwrap();
    let points = json["build_scaling"].as_array().unwrap();
    let names: Vec<&str> = points.iter().map(|p| p["mesh"].as_str().unwrap()).collect();
    assert_eq!(names, ["icosphere-3", "icosphere-4"], "{text}");
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(meshes.join("index.json")).unwrap()).unwrap();
    for p in points {
        let n = p["triangles"].as_u64().unwrap();
        assert_eq!(n, 20 * 4u64.pow(if p["mesh"] == "icosphere-3" { 3 } else { 4 }));
        assert!(p["references"].as_u64().unwrap() >= n, "{p}");
        for k in ["cpu_1t_ms", "cpu_ms", "bvh_ms"] {
            assert!(p[k].as_f64().unwrap() > 0.0, "{k}: {p}");
        }
        assert!(p["gpu_ms"].is_null(), "no GPU asked for: {p}");
        let name = p["mesh"].as_str().unwrap();
        assert_eq!(index[name].as_u64(), Some(n));
        let bytes = std::fs::metadata(meshes.join(format!("{name}.f32"))).unwrap().len();
        assert_eq!(bytes, n * 36, "{name}");
    }
    assert_eq!(points[0]["embree_ms"].as_f64(), Some(0.5));
    assert_eq!(points[1]["embree_ms"].as_f64(), Some(1.5));
    let md = std::fs::read_to_string(dir.join("bench.md")).unwrap();
    assert!(md.contains("## Build time against triangle count"), "{md}");
    assert!(dir.join("build_scaling.png").exists());

    std::fs::write(&embree, "[1, 2]").unwrap();
    let a = args(&["--embree", embree.to_str().unwrap()]);
    let (ok, text) = gridtrace(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!ok && text.contains("embree.json"), "{text}");
}

/// `bench --suite hardware --quick` on whatever adapter the machine has (lavapipe in CI): the
/// report says what the adapter is (loudly when it is a software one), every structure with a
/// GPU walk ran every mode on the GPU and the CPU, every GPU frame is one round trip and agrees
/// with the CPU's image, the ray batches agree with the CPU's hits, and the builds ran. Without
/// mesh data (an empty data folder here) the scanned meshes are listed as skipped.
#[test]
fn hardware_suite_quick_runs_every_part() {
    let dir = std::env::temp_dir().join(format!("gridtrace-hw-{}", std::process::id()));
    let data = dir.join("no-meshes");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&data).unwrap();
    let (ok, text) = gridtrace(&[
        "bench",
        "--suite",
        "hardware",
        "--quick",
        "--data-dir",
        data.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("hardware.json")).unwrap()).unwrap();
    let md = std::fs::read_to_string(dir.join("hardware.md")).unwrap();
    let adapter = &json["adapter"];
    assert!(adapter["name"].as_str().is_some_and(|s| !s.is_empty()));
    if adapter["software"].as_bool().unwrap() {
        assert!(
            md.contains("WARNING: SOFTWARE ADAPTER") && text.contains("WARNING"),
            "{md}"
        );
    }
    assert!(json["mismatches"].as_array().unwrap().is_empty(), "{md}");
    let skipped = json["skipped"].as_array().unwrap();
    assert!(
        skipped.iter().any(|s| s.as_str().unwrap().contains("stanford-bunny")),
        "{skipped:?}"
    );
    assert!(
        !skipped.iter().any(|s| s.as_str().unwrap().contains("time budget")),
        "the quick run must fit its budget: {skipped:?}"
    );
    let frames = json["frames"].as_array().unwrap();
    for accel in ["grid", "pc", "bvh", "irregular"] {
        for mode in ["cast", "shadow", "trace"] {
            for backend in ["cpu", "gpu"] {
                let row = frames
                    .iter()
                    .find(|r| {
                        r["accel"] == accel
                            && r["mode"] == mode
                            && r["backend"] == backend
                            && r["scene"] == "torus-knot"
                    })
                    .unwrap_or_else(|| panic!("no {backend} {accel} {mode} frame: {md}"));
                assert!(row["rays"].as_u64().unwrap() >= 96 * 54);
                assert!(row["median_ms"].as_f64().unwrap() > 0.0);
                if backend == "gpu" {
                    assert_eq!(row["round_trips"], 1, "{row}");
                    assert!(row["differing_from_cpu"].as_f64().unwrap() <= 0.002, "{row}");
                }
            }
        }
    }
    // Every GPU variant ran where it applies: the BVH's layout and stack on the BVH only.
    let variants = json["variants"].as_array().unwrap();
    assert!(variants.len() >= 7, "{variants:?}");
    let of = |accel: &str| -> std::collections::BTreeSet<String> {
        frames
            .iter()
            .filter(|r| r["backend"] == "gpu" && r["accel"] == accel)
            .map(|r| r["variant"].as_str().unwrap().to_string())
            .collect()
    };
    // And beside them the default's frames left on the device (as the viewer presents them)
    // and read back with frames in flight.
    assert_eq!(of("bvh").len(), variants.len() + 2, "{:?}", of("bvh"));
    assert!(of("bvh").iter().any(|v| v.contains("wide8")));
    assert_eq!(of("grid").len(), variants.len() - 2 + 2, "{:?}", of("grid"));
    let big = json["big_frame"].as_array().unwrap();
    assert_eq!(big.len(), 4, "{md}");
    assert!(big.iter().all(|r| r["width"] == 512 && r["height"] == 512));
    // A frame left on the device reads back its counters and timestamps only: the default's
    // row of the same frame reads 4 bytes a pixel more; both agree with the CPU.
    let on_device: Vec<&serde_json::Value> = frames
        .iter()
        .chain(big)
        .filter(|r| r["variant"] == "image=device")
        .collect();
    let defaults = frames.iter().chain(big).filter(|r| r["variant"] == "default").count();
    assert_eq!(on_device.len(), defaults, "one beside every default row: {md}");
    for r in on_device {
        let same = |q: &&serde_json::Value| {
            q["variant"] == "default"
                && q["scene"] == r["scene"]
                && q["accel"] == r["accel"]
                && q["mode"] == r["mode"]
                && q["width"] == r["width"]
        };
        let host = frames
            .iter()
            .chain(big)
            .find(same)
            .unwrap_or_else(|| panic!("no default row beside {r}"));
        let pixels = r["width"].as_u64().unwrap() * r["height"].as_u64().unwrap();
        assert_eq!(r["round_trips"], 1, "{r}");
        assert!(r["differing_from_cpu"].as_f64().unwrap() <= 0.002, "{r}");
        assert_eq!(
            host["bytes_down"].as_u64().unwrap() - r["bytes_down"].as_u64().unwrap(),
            4 * pixels,
            "{r}"
        );
    }
    // Frames in flight: one row beside every default row, the same frame (its rays, the CPU's
    // pixels), read back whole in one round trip each.
    let in_flight: Vec<&serde_json::Value> = frames
        .iter()
        .chain(big)
        .filter(|r| r["variant"] == "in-flight=2")
        .collect();
    assert_eq!(in_flight.len(), defaults, "one beside every default row: {md}");
    for r in in_flight {
        let host = frames
            .iter()
            .chain(big)
            .find(|q| {
                q["variant"] == "default"
                    && q["scene"] == r["scene"]
                    && q["accel"] == r["accel"]
                    && q["mode"] == r["mode"]
                    && q["width"] == r["width"]
            })
            .unwrap_or_else(|| panic!("no default row beside {r}"));
        assert_eq!(
            (&r["rays"], &r["round_trips"]),
            (&host["rays"], &host["round_trips"]),
            "{r}"
        );
        assert_eq!(r["bytes_down"], host["bytes_down"], "{r}");
        assert!(r["differing_from_cpu"].as_f64().unwrap() <= 0.002, "{r}");
    }
    let rays = json["rays"].as_array().unwrap();
    for set in ["camera", "incoherent"] {
        // Every structure the suite traces (hwrt too where the adapter has ray queries, as
        // lavapipe 25 has), the BVH with every variant, the others with those that apply, and
        // each structure's lean answers (t and triangle; occlusion bits; every hit counted and
        // listed) beside them.
        let gpu: Vec<&serde_json::Value> = rays
            .iter()
            .filter(|r| r["set"] == set && r["backend"] == "gpu")
            .collect();
        let accels: std::collections::BTreeSet<&str> = gpu.iter().map(|r| r["accel"].as_str().unwrap()).collect();
        assert!(
            ["grid", "pc", "bvh", "irregular"].iter().all(|a| accels.contains(a)),
            "{accels:?}"
        );
        let n = accels.len();
        assert_eq!(
            gpu.len(),
            variants.len() + (n - 1) * (variants.len() - 2) + n * 4,
            "{set}: {md}"
        );
        // Bytes a ray over the bus: 24 up (and the chunks' constants); down 16 with u, v, 8
        // without, an eighth of a byte for occlusion, 4 for a count (and the timestamps); a
        // list brings 4 a ray and 16 a hit.
        for r in rays.iter().filter(|r| r["set"] == set && r["backend"] == "gpu") {
            let (up, down) = (
                r["bytes_up_per_ray"].as_f64().unwrap(),
                r["bytes_down_per_ray"].as_f64().unwrap(),
            );
            let want = match r["variant"].as_str().unwrap() {
                "answers=t,tri" => 8.0..9.0,
                "answers=occlusion" => 0.125..1.125,
                "answers=counts" => 4.0..5.0,
                "answers=lists" => 4.0..f64::INFINITY,
                _ => 16.0..17.0,
            };
            assert!((24.0..25.0).contains(&up) && want.contains(&down), "{r}");
        }
    }
    assert!(rays.iter().all(|r| r["differing_from_cpu"].as_f64().unwrap() <= 0.001));
    // Point queries: nearest points through every structure and winding numbers, a CPU row
    // beside each GPU row; 12 bytes a point up, 32 down for a nearest point (triangle,
    // barycentrics and the search's work), 4 for a winding number.
    let points = json["points"].as_array().unwrap();
    for accel in ["grid", "pc", "bvh", "irregular", "-"] {
        let query = if accel == "-" { "winding" } else { "closest" };
        for backend in ["cpu", "gpu"] {
            let row = points
                .iter()
                .find(|r| r["accel"] == accel && r["query"] == query && r["backend"] == backend)
                .unwrap_or_else(|| panic!("no {backend} {query} {accel} row: {md}"));
            assert!(row["differing_from_cpu"].as_f64().unwrap() <= 0.001, "{row}");
            if backend == "gpu" {
                let (up, down) = (
                    row["bytes_up_per_point"].as_f64().unwrap(),
                    row["bytes_down_per_point"].as_f64().unwrap(),
                );
                let want = if query == "winding" { 4.0 } else { 32.0 };
                assert!(
                    (12.0..13.0).contains(&up) && (want..want + 1.0).contains(&down),
                    "{row}"
                );
            }
        }
    }
    assert!(md.contains("## Point queries"), "{md}");
    assert!(!json["builds"].as_array().unwrap().is_empty(), "{md}");
    let _ = std::fs::remove_dir_all(&dir);
}
