//! `gridtrace scan`: the point cloud lies where the sensor and the scene put it, the range image
//! has the sensor's layout, and bad sensors are refused naming the option or the file.

mod common;

use common::gridtrace;

/// A closed cube room `[-5, 5]^3` (faces either way: hits count either side).
const ROOM_OBJ: &str = "v -5 -5 -5\nv 5 -5 -5\nv -5 5 -5\nv 5 5 -5\nv -5 -5 5\nv 5 -5 5\nv -5 5 5\nv 5 5 5\n\
f 1 2 4\nf 1 4 3\nf 5 7 8\nf 5 8 6\nf 1 5 6\nf 1 6 2\nf 3 4 8\nf 3 8 7\nf 1 3 7\nf 1 7 5\nf 2 6 8\nf 2 8 4\n";

fn scratch(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("gridtrace-scan-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The `(x, y, z, range)` records of a binary PLY written by `scan -o`.
fn read_cloud(path: &std::path::Path) -> Vec<[f32; 4]> {
    let bytes = std::fs::read(path).unwrap();
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end).expect("a PLY header") + end.len();
    let header = String::from_utf8_lossy(&bytes[..at]);
    let count: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .expect("a vertex count")
        .parse()
        .unwrap();
    let body = &bytes[at..];
    assert_eq!(body.len(), count * 16, "{header}");
    body.chunks_exact(16)
        .map(|r| std::array::from_fn(|k| f32::from_le_bytes(r[4 * k..4 * k + 4].try_into().unwrap())))
        .collect()
}

/// `gridtrace scan` of the room mesh `obj` alone, z up, with `extra` arguments.
fn scan_room(obj: &std::path::Path, extra: &[&str]) -> (bool, String) {
    let mut args = vec!["scan", "--mesh", obj.to_str().unwrap(), "--no-floor", "--up", "0,0,1"];
    args.extend_from_slice(extra);
    gridtrace(&args)
}

/// Every point of `cloud` lies on a wall of the room (one coordinate at +-5) at its range's
/// distance from the sensor at `at`.
fn assert_on_walls_at_range(cloud: &[[f32; 4]], at: [f32; 3]) {
    for [x, y, z, range] in cloud {
        let p = [*x, *y, *z];
        assert!(p.iter().any(|c| (c.abs() - 5.0).abs() < 1e-4), "{p:?} is on no wall");
        let d = p.iter().zip(at).map(|(c, a)| (c - a) * (c - a)).sum::<f32>().sqrt();
        assert!((d - range).abs() <= 1e-5 * range, "{p:?}: range {range}, distance {d}");
    }
}

#[test]
fn a_lidar_in_a_room_returns_points_on_its_walls() {
    let dir = scratch("room");
    let obj = dir.join("room.obj");
    std::fs::write(&obj, ROOM_OBJ).unwrap();
    let (ply, png) = (dir.join("cloud.ply"), dir.join("range.png"));
    // A level VLP-16 at (1, 2, 0.5) facing +x, z up; 90 columns.
    let at = [1.0f32, 2.0, 0.5];
    let (ok, out) = scan_room(
        &obj,
        &[
            "--lidar",
            "vlp16",
            "--azimuth-steps",
            "90",
            "--at",
            "1,2,0.5",
            "--toward",
            "3,2,0.5",
            "-o",
            ply.to_str().unwrap(),
            "--range-png",
            png.to_str().unwrap(),
        ],
    );
    assert!(ok, "{out}");
    assert!(out.contains("returns 1440 of 1440 rays"), "{out}");
    let cloud = read_cloud(&ply);
    assert_eq!(cloud.len(), 16 * 90);
    assert_on_walls_at_range(&cloud, at);
    let mut rising = 0;
    for [_, _, z, range] in &cloud {
        // VLP-16 beams run +15..-15 degrees; none points further up or down.
        let slope = (z - at[2]) / range;
        assert!(
            slope.abs() <= (15.0f32 + 1e-3).to_radians().sin(),
            "z {z} at range {range}"
        );
        rising += (slope > 0.0) as usize;
    }
    // Eight beams look up, eight down.
    assert_eq!(rising, 8 * 90);
    let img = image::open(&png).unwrap();
    // 90 columns, the 16 rows repeated to no more than 8 widths to a height (here once).
    assert_eq!((img.width(), img.height()), (90, 16));
}

#[test]
fn a_camera_and_a_beam_table_file_scan_as_asked() {
    let dir = scratch("table");
    let obj = dir.join("room.obj");
    std::fs::write(&obj, ROOM_OBJ).unwrap();
    let table = dir.join("beams.toml");
    std::fs::write(&table, "elevations_deg = [0]\nazimuth_steps = 4\nmax_range = 5.5\n").unwrap();
    let ply = dir.join("c.ply");
    // One level beam, four columns at -135, -45, 45, 135 degrees from the centre: corners at
    // 5 * sqrt(2) = 7.07 are beyond max_range, so nothing returns.
    let (ok, out) = scan_room(
        &obj,
        &[
            "--lidar",
            table.to_str().unwrap(),
            "--at",
            "0,0,0",
            "--toward",
            "1,0,0",
            "-o",
            ply.to_str().unwrap(),
        ],
    );
    assert!(ok, "{out}");
    assert!(out.contains("returns 0 of 4 rays"), "{out}");
    assert!(read_cloud(&ply).is_empty());

    // A camera 2 from the centre facing it, carried round it over three frames: the files are
    // the last frame's, 240 degrees round, from (2 cos 240, 2 sin 240, 0). Every pixel returns
    // a point on a wall at its distance from there.
    let png = dir.join("depth.png");
    let (ok, out) = scan_room(
        &obj,
        &[
            "--camera",
            "9x7",
            "--fov",
            "90",
            "--at",
            "2,0,0",
            "--toward",
            "0,0,0",
            "-o",
            ply.to_str().unwrap(),
            "--range-png",
            png.to_str().unwrap(),
            "--frames",
            "3",
            "--orbit",
        ],
    );
    assert!(ok, "{out}");
    assert!(
        out.contains("returns 63 of 63 rays") && out.contains("3 scan(s)"),
        "{out}"
    );
    let turn = 240f32.to_radians();
    let at = [2.0 * turn.cos(), 2.0 * turn.sin(), 0.0];
    let cloud = read_cloud(&ply);
    assert_eq!(cloud.len(), 63);
    assert_on_walls_at_range(&cloud, at);
    for [x, y, z, _] in &cloud {
        let p = [*x, *y, *z];
        // In front of the camera: towards the centre from where it stands.
        assert!(p.iter().zip(at).map(|(c, a)| (c - a) * -a).sum::<f32>() > 0.0, "{p:?}");
    }
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (9, 7));
}

#[test]
fn bad_sensors_name_the_option_or_the_file() {
    let dir = scratch("bad");
    let table = dir.join("bad.toml");
    std::fs::write(&table, "elevations_deg = [0]\nazimuth_steps = 4\nmax_rnage = 3\n").unwrap();
    let cases: [(&[&str], &str); 5] = [
        (&["--lidar", "hdl32"], "--lidar: unknown LiDAR preset \"hdl32\""),
        (
            &["--lidar", "vlp16", "--azimuth-steps", "0"],
            "--lidar: azimuth_steps must be > 0",
        ),
        (&["--lidar", table.to_str().unwrap()], "bad.toml:line 3:"),
        (
            &["--camera", "8x8", "--fov", "190"],
            "--camera/--fov: fov_deg must be in (0, 180)",
        ),
        (
            &["--at", "0,0,0", "--toward", "0,1,0", "--up", "0,1,0"],
            "needs a view direction that is not along up",
        ),
    ];
    for (extra, want) in cases {
        let mut args = vec!["scan", "--scene", "knot-box"];
        args.extend_from_slice(extra);
        let (ok, out) = gridtrace(&args);
        assert!(
            !ok && out.contains(want) && !out.contains("panicked"),
            "{extra:?}: {out}"
        );
    }
}
