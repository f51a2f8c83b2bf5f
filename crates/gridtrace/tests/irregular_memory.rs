//! The irregular grid's build stays within `IrregularGrid::memory_bound`, measured: a counting
//! global allocator records the heap's peak while each mesh is built, against the bound on the
//! build's peak; the grid it makes is within the bounds on cells, references and bytes. Alone in
//! its binary, so no other test allocates meanwhile.
//!
//! `ten_million_triangles` is the 10-million-triangle mesh: about 12 s and a 1.4 GB peak
//! (2.4 GB resident), within CI's 24 GiB. The two tests take turns (`ONE_AT_A_TIME`): the
//! counter sees the whole process.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

use glam::{Mat4, Vec3};
use gridtrace::accel::{IrregularGrid, IrregularParams, TriAccel};
use gridtrace::scene::procedural;
use gridtrace::util::Rng;

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(by: usize) {
    let now = LIVE.fetch_add(by, Relaxed) + by;
    PEAK.fetch_max(now, Relaxed);
}

// SAFETY: every call forwards to the system allocator with the caller's own arguments, whose
// contracts are the caller's; the counters only observe sizes.
// Blocks are counted before they are asked for (and uncounted if refused), so a peak that
// threads reach together is never missed.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        grew(layout.size());
        // SAFETY: as above.
        let p = unsafe { System.alloc(layout) };
        if p.is_null() {
            LIVE.fetch_sub(layout.size(), Relaxed);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        grew(layout.size());
        // SAFETY: as above.
        let p = unsafe { System.alloc_zeroed(layout) };
        if p.is_null() {
            LIVE.fetch_sub(layout.size(), Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Relaxed);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // Counted as a new block beside the old one (a moving realloc holds both), then the
        // old one freed.
        grew(new_size);
        // SAFETY: as above.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        LIVE.fetch_sub(if p.is_null() { new_size } else { layout.size() }, Relaxed);
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn tris_of(mut m: gridtrace::Mesh, at: Mat4) -> Vec<TriAccel> {
    procedural::transform(&mut m, at);
    TriAccel::from_mesh(&m)
}

/// Builds the grid, checks it and the heap's peak against the bound; returns (peak, bound).
fn check(name: &str, tris: &[TriAccel], params: IrregularParams) -> (usize, u64) {
    let bound = IrregularGrid::memory_bound(tris, params).unwrap();
    let base = LIVE.load(Relaxed);
    PEAK.store(base, Relaxed);
    let g = IrregularGrid::build(tris, params).unwrap();
    let peak = PEAK.load(Relaxed) - base;
    let s = &g.stats;
    eprintln!(
        "{name}: {} triangles, peak {} of {} bytes bound ({:.2}); {} of {} cells, {} of {} references, {} of {} structure bytes",
        tris.len(),
        peak,
        bound.build_peak_bytes,
        peak as f64 / bound.build_peak_bytes as f64,
        s.initial_cells,
        bound.initial_cells,
        s.references,
        bound.references,
        g.bytes(),
        bound.structure_bytes
    );
    assert!(
        peak as u64 <= bound.build_peak_bytes,
        "{name}: peak {peak} over the bound {bound:?}"
    );
    assert!(
        s.initial_cells as u64 <= bound.initial_cells,
        "{name}: {:?} {bound:?}",
        s
    );
    assert!(s.references as u64 <= bound.references, "{name}: {:?} {bound:?}", s);
    assert!(
        g.bytes() as u64 <= bound.structure_bytes,
        "{name}: {} {bound:?}",
        g.bytes()
    );
    // The bound is a bound, not a guess an order of magnitude off: 1.2-3.6x on these meshes,
    // 5.7x on the 10M torus knot, whose slivers have bounding boxes much larger than their
    // cells (its reference bound is 4.1x the references). It was 4.6x there until the build
    // stopped holding arrays for every second-level cell (the merge inside each top cell
    // keeps only the survivors): the peak fell from 2.54 to 1.39 GB, and the bound, which
    // must count the late arrays at the second level's cell count, fell less.
    assert!(
        bound.build_peak_bytes < 7 * peak as u64 + (1 << 20),
        "{name}: {peak} against {bound:?}"
    );
    (peak, bound.build_peak_bytes)
}

/// Clusters of small triangles in a large empty box, with two far corners and a long sliver
/// (the teapot in a stadium).
fn clusters(n: usize, seed: u64) -> Vec<TriAccel> {
    let mut rng = Rng::new(seed);
    let centres: Vec<Vec3> = (0..5)
        .map(|_| Vec3::new(rng.range(0.0, 100.0), rng.range(0.0, 100.0), rng.range(0.0, 100.0)))
        .collect();
    let mut tris: Vec<TriAccel> = (0..n)
        .map(|i| {
            let p = centres[i % centres.len()]
                + Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
            let mut q = || p + Vec3::new(rng.range(-0.1, 0.1), rng.range(-0.1, 0.1), rng.range(-0.1, 0.1));
            TriAccel::new(p, q(), q())
        })
        .collect();
    tris.push(TriAccel::new(
        Vec3::ZERO,
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ));
    tris.push(TriAccel::new(
        Vec3::splat(100.0),
        Vec3::new(99.0, 100.0, 100.0),
        Vec3::new(100.0, 99.0, 100.0),
    ));
    tris.push(TriAccel::new(Vec3::ZERO, Vec3::splat(100.0), Vec3::new(0.0, 0.1, 0.0)));
    tris
}

#[test]
fn builds_stay_within_the_bound() {
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let params = IrregularParams::default();
    // Start the thread pool and whatever else a first build allocates once.
    let _ = IrregularGrid::build(&clusters(100, 1), params).unwrap();
    let knot = tris_of(procedural::torus_knot(2, 3, 0.16, 1000, 64), Mat4::IDENTITY);
    check("torus knot", &knot, params);
    check(
        "icosphere",
        &tris_of(procedural::icosphere(Vec3::ZERO, 1.0, 6), Mat4::IDENTITY),
        params,
    );
    check("clusters", &clusters(60_000, 7), params);
    // Flat: the top grid's budget goes to two axes.
    check("plane", &tris_of(procedural::plane(10.0, 200), Mat4::IDENTITY), params);
    // Other parameters: fine cells, many top cells, no merging or expansion.
    let fine = IrregularParams {
        cell_density: 8.0,
        top_density: 0.5,
        merge_passes: 0,
        expand_passes: 0,
        ..params
    };
    check("torus knot, fine cells", &knot, fine);
}

#[test]
fn ten_million_triangles() {
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let params = IrregularParams::default();
    let _ = IrregularGrid::build(&clusters(100, 1), params).unwrap();
    let knot = tris_of(procedural::torus_knot(2, 3, 0.16, 40_000, 128), Mat4::IDENTITY);
    assert!(knot.len() >= 10_000_000);
    check("torus knot, 10.24 M", &knot, params);
}
