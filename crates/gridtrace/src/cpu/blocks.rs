//! The renderer's pixels in 4x2 blocks: every structure traces a packet of rays faster than
//! its rays one by one (the irregular grid walks them together; the BVH and the uniform grids
//! interleave their walks, so that each ray's chain of dependent steps overlaps the others').
//! The eight pixels' paths (`path.rs`) go through the stages side by side: their rays' closest
//! hits as one packet (`Accel::intersect_packet`), then per light the shadow rays from those
//! hits as one packet (`Accel::occluded_packet`), then their mirror rays as the next packet,
//! until every path has ended. Neighbouring pixels' rays are coherent at every bounce off a
//! smooth surface, which is what the irregular grid's packet walk needs (docs/design.md "The
//! irregular grid": packets); interleaving needs no coherence. The same rays and stages as
//! pixel by pixel (`trace_pixel`), so the same image, bit for bit.

use glam::Vec3;

use crate::accel::{PACKET, Ray, TraversalCounters};
use crate::render::{RayCounts, RenderOptions};
use crate::scene::{CameraFrame, PointLight, PreparedScene};
use crate::util::set_bits;

use super::path::{Collect, Path, Shading, pixel_value, shadow_query};

/// A block's width and height in pixels: a packet's rays. Four wide and two high rather than
/// eight by one: the rays stay closer together, so more of them share each cell (measured:
/// docs/benchmarks-history.md "Packets of eight").
const BLOCK_W: usize = 4;
const BLOCK_H: usize = PACKET / BLOCK_W;

/// A ray for the unused lanes of a packet (never traced: packets are cut to their length).
const IDLE: Ray = Ray::new(Vec3::ZERO, Vec3::X);

/// Traces the pixels of a band of rows (frame rows `first_y..`, `rows` holding them) block by
/// block, adding what it traced to `rays` and its work to `total`.
pub(super) fn trace_blocks<C: Collect>(
    scene: &PreparedScene,
    cam: &CameraFrame,
    lights: &[PointLight],
    opts: &RenderOptions,
    (first_y, rows): (u32, &mut [Vec3]),
    (rays, total): (&mut RayCounts, &mut TraversalCounters),
) {
    let width = opts.width as usize;
    let band_rows = rows.len() / width;
    for by in (0..band_rows).step_by(BLOCK_H) {
        for bx in (0..width).step_by(BLOCK_W) {
            let mut at = [0usize; PACKET];
            let mut paths = [Path::new(IDLE); PACKET];
            let mut n = 0;
            for j in 0..PACKET {
                let (row, col) = (by + j / BLOCK_W, bx + j % BLOCK_W);
                if row < band_rows && col < width {
                    at[n] = row * width + col;
                    paths[n] = Path::new(cam.ray(col as u32, first_y + row as u32));
                    n += 1;
                }
            }
            rays.eye += n as u64;
            let mut counters: [C; PACKET] = std::array::from_fn(|_| C::default());
            trace_paths(scene, lights, opts, &mut paths[..n], &mut counters[..n], rays);
            for k in 0..n {
                rows[at[k]] = pixel_value(opts, paths[k].color, &counters[k]);
                *total += counters[k].total();
            }
        }
    }
}

/// Runs up to `PACKET` paths to their ends, each stage's rays as one packet, each path's work
/// counted into its own `counters[k]`.
fn trace_paths<C: Collect>(
    scene: &PreparedScene,
    lights: &[PointLight],
    opts: &RenderOptions,
    paths: &mut [Path],
    counters: &mut [C],
    rays: &mut RayCounts,
) {
    let mut live = (1u32 << paths.len()) - 1;
    let mut shadings: [Option<Shading>; PACKET] = [None; PACKET];
    while live != 0 {
        // The live paths' rays, packed into the first lanes.
        let (mut lane_of, mut m) = ([0usize; PACKET], 0);
        let mut traced = [IDLE; PACKET];
        for k in set_bits(live) {
            (lane_of[m], traced[m]) = (k, paths[k].ray);
            m += 1;
        }
        let mut counted: [C; PACKET] = std::array::from_fn(|_| C::default());
        let hits = scene.accel.intersect_packet(&traced[..m], &mut counted[..m]);
        for (j, counted) in counted.into_iter().take(m).enumerate() {
            let k = lane_of[j];
            counters[k].absorb(counted);
            shadings[k] = paths[k].shade(scene, opts, &hits[j]);
            if shadings[k].is_none() {
                live &= !(1 << k);
            }
        }
        for light in lights {
            // The shadow rays towards this light, packed; with the light's contribution each
            // adds if nothing occludes it.
            let (mut shadow, mut adds, mut m) = ([IDLE; PACKET], [(0, Vec3::ZERO); PACKET], 0);
            for k in set_bits(live) {
                let shading = shadings[k].as_ref().expect("a live path has a shading");
                let Some((contribution, ray, d)) = shading.light(light) else {
                    continue;
                };
                if opts.mode.shadows() {
                    (shadow[m], adds[m]) = (ray.within(0.0, d), (k, contribution));
                    m += 1;
                } else {
                    paths[k].lit(shading, contribution);
                }
            }
            if m == 0 {
                continue;
            }
            rays.shadow += m as u64;
            let mut counted: [C; PACKET] = std::array::from_fn(|_| C::default());
            let occluded = if opts.ablation.shadow_closest_hit {
                // The ablation traces shadow rays as closest-hit queries, one by one.
                std::array::from_fn(|j| j < m && shadow_query(scene, opts, &shadow[j], &mut counted[j]))
            } else {
                scene.accel.occluded_packet(&shadow[..m], &mut counted[..m])
            };
            for (j, counted) in counted.into_iter().take(m).enumerate() {
                let (k, contribution) = adds[j];
                counters[k].absorb(counted);
                if !occluded[j] {
                    paths[k].lit(shadings[k].as_ref().expect("a live path has a shading"), contribution);
                }
            }
        }
        for k in set_bits(live) {
            if paths[k].reflect(opts, shadings[k].as_ref().expect("a live path has a shading")) {
                rays.reflection += 1;
            } else {
                live &= !(1 << k);
            }
        }
    }
}
