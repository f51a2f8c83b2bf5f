//! `scene::tumbling` (`render --animate --scene tumbling-bunnies`): frames of rigid instances
//! moved through a `QueryScene`'s top level equal the same instances merged flat into one mesh,
//! on the CPU and on the GPU (lavapipe in CI), build no structure after the first, and move.
//!
//! The mesh is a torus knot (no data file needed); with the Stanford Bunny found
//! (`GRIDTRACE_DATA_DIR`, else `shared/data/meshes` beside the checkout) the same checks run
//! on it too. Fails, not skips, without a GPU adapter; GRIDTRACE_SKIP_GPU=1 skips knowingly.

use glam::Vec3;
use gridtrace::query::{Backend, QueryOptions};
use gridtrace::query_scene::{INVALID_ID, RayHits};
use gridtrace::render::differing_pixels;
use gridtrace::scene::procedural::torus_knot;
use gridtrace::scene::tumbling::Tumbling;
use gridtrace::testing::{on_triangle_boundary, ray_hit, skip_gpu, t_close};
use gridtrace::{AccelKind, QueryScene, Ray};

const W: u32 = 64;
const H: u32 = 48;
const INSTANCES: u32 = 20;
/// Animation times of the frames compared, seconds.
const TIMES: [f32; 3] = [0.0, 0.4, 1.1];

fn opts(backend: Backend) -> QueryOptions {
    QueryOptions {
        accel: AccelKind::Bvh.into(),
        backend,
        ..Default::default()
    }
}

/// The flat scene's hits named as the two levels name them: instance k's faces are faces
/// `k * faces ..` of the merged mesh.
fn as_instances(flat: &RayHits, faces: usize) -> RayHits {
    let mut h = flat.clone();
    for i in 0..h.t_hit.len() {
        if h.geometry_ids[i] != INVALID_ID {
            h.geometry_ids[i] = h.primitive_ids[i] / faces as u32;
            h.primitive_ids[i] %= faces as u32;
        }
    }
    h
}

/// What a frame's comparison found.
#[derive(Default, Debug)]
struct Tally {
    hits: usize,
    /// Hits on the same instance and face with the same t to the bit.
    t_equal: usize,
    /// Same face, t apart by more than 1e-5 relative but within the triangle tests' rounding.
    rounding: usize,
    /// Another face or instance, or hit against miss, where a hit lies on its face's boundary.
    boundary: usize,
}

/// Compares the two levels' frame with the flat one's, pixel by pixel; panics on any
/// difference that is not a tie on a face's boundary.
fn compare(rays: &[[f32; 6]], two: &RayHits, flat: &RayHits, what: &str) -> Tally {
    let mut tally = Tally::default();
    for (i, q) in rays.iter().enumerate() {
        let (a, b) = (ray_hit(two, i), ray_hit(flat, i));
        let same = (two.geometry_ids[i], two.primitive_ids[i]) == (flat.geometry_ids[i], flat.primitive_ids[i]);
        if same && two.geometry_ids[i] == INVALID_ID {
            continue;
        }
        if !same {
            assert!(
                on_triangle_boundary(&a) || on_triangle_boundary(&b),
                "{what} pixel {i}: two levels {:?}/{} t {}, flat {:?}/{} t {}",
                two.geometry_ids[i],
                two.primitive_ids[i],
                a.t,
                flat.geometry_ids[i],
                flat.primitive_ids[i],
                b.t
            );
            tally.boundary += 1;
            continue;
        }
        tally.hits += 1;
        if a.t == b.t {
            tally.t_equal += 1;
        } else if (a.t - b.t).abs() > 1e-5 * a.t.abs().max(b.t.abs()) {
            let r = Ray::new(Vec3::new(q[0], q[1], q[2]), Vec3::new(q[3], q[4], q[5]));
            assert!(t_close(&r, a.t, b.t), "{what} pixel {i}: t {} vs {}", a.t, b.t);
            tally.rounding += 1;
        }
        let (na, nb) = (
            Vec3::from(two.primitive_normals[i]),
            Vec3::from(flat.primitive_normals[i]),
        );
        assert!(na.abs_diff_eq(nb, 1e-4), "{what} pixel {i}: normal {na} vs {nb}");
    }
    tally
}

/// Plays `TIMES` through the two levels on `backend` and checks each frame against the flat
/// mesh on the same backend; returns the frames' images (sRGB bytes).
fn play(t: &Tumbling, backend: Backend, what: &str) -> Vec<Vec<u8>> {
    let rays = t.primary_rays(W, H);
    let (mut scene, ids) = t.query_scene(opts(backend), 0.0).unwrap();
    let mut images = Vec::new();
    for (f, &time) in TIMES.iter().enumerate() {
        scene.set_transforms(&ids, &t.transforms_at(time)).unwrap();
        let two = scene.cast_rays(&rays).unwrap();
        // (a) One structure, the mesh's, however many frames: a move builds none.
        assert_eq!(scene.structure_builds(), 1, "{what} frame {f}");
        let on = scene.last_query().device;
        assert_eq!(on, if backend == Backend::Gpu { "gpu" } else { "cpu" }, "{what}");
        let (v, faces) = t.flat_at(time);
        let mut flat_scene = QueryScene::new(opts(backend));
        flat_scene.add_triangles(v, faces, None).unwrap();
        let flat = as_instances(&flat_scene.cast_rays(&rays).unwrap(), t.faces.len());
        // (b) The same hits as the instances merged flat into one structure.
        let tally = compare(&rays, &two, &flat, &format!("{what} frame {f}"));
        eprintln!("{what} frame {f}: {tally:?} of {} pixels", rays.len());
        assert!(
            tally.hits * 20 > rays.len(),
            "{what} frame {f}: the instances fill a twentieth of the view: {tally:?}"
        );
        assert!(tally.boundary * 200 < rays.len(), "{what} frame {f}: {tally:?}");
        assert!(tally.rounding * 100 < tally.hits, "{what} frame {f}: {tally:?}");
        let image = t.shade(&rays, &two, W, H).to_rgb8();
        let flat_image = t.shade(&rays, &flat, W, H).to_rgb8();
        let d = differing_pixels(&image, &flat_image, 1);
        assert!(
            d < 0.005,
            "{what} frame {f}: {d} of the pixels differ from the flat frame's"
        );
        images.push(image);
    }
    if let Some(up) = scene.gpu_uploads() {
        assert_eq!(up.mesh_uploads, 1, "{what}: the mesh went up once: {up:?}");
    }
    // (c) Things move: each frame differs from the one before.
    for f in 1..images.len() {
        let d = differing_pixels(&images[f - 1], &images[f], 2);
        assert!(d > 0.02, "{what}: frames {} and {f} differ in {d} of the pixels", f - 1);
    }
    images
}

fn knot() -> Tumbling {
    let m = torus_knot(2, 3, 0.35, 120, 10);
    let v = m.positions.iter().map(|p| p.to_array()).collect();
    Tumbling::new(v, m.triangles, INSTANCES, "knot").unwrap()
}

/// The Stanford Bunny, where the mesh folder has it.
fn bunny() -> Option<Tumbling> {
    let dir = std::env::var_os("GRIDTRACE_DATA_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/meshes"));
    let path = dir.join("bunny/bun_zipper.ply");
    if !path.is_file() {
        eprintln!("{} not found: the Bunny's frames are not compared", path.display());
        return None;
    }
    let m = gridtrace::io::load_mesh(&path).unwrap();
    let v = m.positions.iter().map(|p| p.to_array()).collect();
    Some(Tumbling::new(v, m.triangles, INSTANCES, "bunny").unwrap())
}

#[test]
fn cpu_frames_equal_flat() {
    let t = knot();
    let cpu = play(&t, Backend::Cpu, "knot cpu");
    if let Some(b) = bunny() {
        play(&b, Backend::Cpu, "bunny cpu");
    }
    // The same frames on every run: the motions are fixed.
    assert_eq!(cpu, play(&knot(), Backend::Cpu, "knot cpu again"));
}

#[test]
fn gpu_frames_equal_flat() {
    if skip_gpu() {
        return;
    }
    let t = knot();
    let gpu = play(&t, Backend::Gpu, "knot gpu");
    let cpu = play(&t, Backend::Cpu, "knot cpu");
    for (f, (g, c)) in gpu.iter().zip(&cpu).enumerate() {
        let d = differing_pixels(g, c, 1);
        assert!(
            d < 0.005,
            "frame {f}: the GPU's and the CPU's images differ in {d} of the pixels"
        );
    }
    if let Some(b) = bunny() {
        play(&b, Backend::Gpu, "bunny gpu");
    }
}
