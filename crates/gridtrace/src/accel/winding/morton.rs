//! The winding tree's Morton-order builder: the triangles sorted by the Morton code of their
//! centroids, then each node's run of codes cut where its codes' highest differing bit flips,
//! again in the children until a node has eight, as an octree cuts a cell into octants (the
//! tree libigl's fast winding numbers walk is such an octree). A run of eight triangles or
//! fewer is a leaf.
//!
//! Why not the SAH: the surface area heuristic prices a ray's visits, but the winding walk
//! stops at a node once the point is farther than `accuracy` times its radius, so compact,
//! cube-like clusters are what it wants, which spatial-median cuts give. And it is cheap: one
//! parallel sort of 64-bit keys and a binary search per cut (871,414 Dragon triangles: a few
//! tens of milliseconds against about a second for the SAH build), the moments then in
//! parallel (`shape.rs`).

use glam::Vec3;
use rayon::prelude::*;

use super::shape::Shape;
use super::wide::WIDTH;
use crate::accel::{Aabb, TriAccel};

/// Bits of the code per axis: 63 in all, in one `u64`.
const BITS: u32 = 21;

/// The Morton-order shape over `tris` (empty for no triangles).
pub(super) fn shape(tris: &[TriAccel]) -> Shape {
    if tris.is_empty() {
        return Shape::default();
    }
    let centroids: Vec<Vec3> = tris
        .par_iter()
        .map(|t| t.vertices().into_iter().sum::<Vec3>() / 3.0)
        .collect();
    let mut keyed: Vec<(u64, u32)> = {
        let codes = codes(&centroids);
        codes.into_iter().zip(0u32..).collect()
    };
    keyed.par_sort_unstable();
    let (codes, prims): (Vec<u64>, Vec<u32>) = keyed.into_iter().unzip();
    let open = |run: (u32, u32)| {
        let mut kids = vec![run];
        while kids.len() < WIDTH {
            // The run of the largest cell (highest differing bit; most triangles among equals)
            // that is not a leaf.
            let Some(pos) = (0..kids.len())
                .filter(|&k| kids[k].1 as usize > WIDTH)
                .max_by_key(|&k| (level(&codes, kids[k]), kids[k].1))
            else {
                break;
            };
            let (first, count) = kids.swap_remove(pos);
            let cut = cut(&codes, first as usize, count as usize) as u32;
            kids.extend([(first, cut - first), (cut, first + count - cut)]);
        }
        kids
    };
    let leaf = |run: (u32, u32)| (run.1 as usize <= WIDTH).then_some(run);
    Shape::breadth_first((0, tris.len() as u32), prims, open, leaf)
}

/// The highest bit where a run's codes differ (sorted: its first and last differ most), plus
/// one; 0 where they are all equal.
fn level(codes: &[u64], (first, count): (u32, u32)) -> u32 {
    let (a, b) = (codes[first as usize], codes[(first + count) as usize - 1]);
    64 - (a ^ b).leading_zeros()
}

/// Where a run of more than one code is cut: the first code with the highest differing bit
/// set (every code before has it clear: they share the bits above and are sorted). Codes all
/// equal (centroids in one cell, or repeated triangles): the middle, so that no run is left
/// that cannot be cut.
fn cut(codes: &[u64], first: usize, count: usize) -> usize {
    let run = &codes[first..first + count];
    match level(codes, (first as u32, count as u32)) {
        0 => first + count / 2,
        l => first + run.partition_point(|c| c & (1u64 << (l - 1)) == 0),
    }
}

/// Each point's Morton code over the cube around the finite points' box (so that a cut
/// halves a cube: cells stay cubes, not slabs); a point that is not finite has code 0.
fn codes(points: &[Vec3]) -> Vec<u64> {
    let bounds = points
        .par_iter()
        .filter(|p| p.is_finite())
        .fold(|| Aabb::EMPTY, |b, p| b.grow(*p))
        .reduce(|| Aabb::EMPTY, Aabb::union);
    let side = bounds.extent().max_element();
    let top = ((1u32 << BITS) - 1) as f32;
    // A single point (or none finite) has no extent: every code 0.
    let scale = if side > 0.0 && side.is_finite() {
        top / side
    } else {
        0.0
    };
    points
        .par_iter()
        .map(|&p| {
            if !p.is_finite() {
                return 0;
            }
            let c = ((p - bounds.min) * scale).clamp(Vec3::ZERO, Vec3::splat(top));
            spread(c.x as u32) | spread(c.y as u32) << 1 | spread(c.z as u32) << 2
        })
        .collect()
}

/// The low 21 bits of `x` moved to every third bit of a `u64`.
fn spread(x: u32) -> u64 {
    let mut x = u64::from(x) & 0x1f_ffff;
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    (x | x << 2) & 0x1249_2492_4924_9249
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::bvh::BvhAccel;
    use crate::accel::winding::test_soup::{open_soup, points_about, unit};
    use crate::accel::winding::{FastWinding, winding_number_brute};
    use crate::util::Rng;

    fn worst(a: &[f32], b: &[f32]) -> f32 {
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
    }

    /// The Morton tree over an open soup (its moments do not cancel: the expansion's worst
    /// case) with degenerate triangles (a point, a segment) and a stack of one repeated
    /// triangle, twelve copies (equal codes: cut in the middle), among them: within the bound of
    /// docs/robustness.md of the brute-force sum at accuracy 2, the same within 1e-5 at 64 (no
    /// node far: the exact leaves), and within twice the bound of the tree over the SAH BVH.
    #[test]
    fn morton_tree_follows_brute_force_and_the_sah_tree() {
        let mut rng = Rng::new(31);
        let mut tris = open_soup(&mut rng, 2500);
        let (p, q) = (unit(&mut rng), unit(&mut rng));
        tris.extend([TriAccel::new(p, p, p), TriAccel::new(p, q, p + (q - p) * 0.5)]);
        tris.extend(std::iter::repeat_n(TriAccel::new(p, q, unit(&mut rng)), 12));
        let points = points_about(&mut rng, 300, 20.0);
        let exact: Vec<f32> = points
            .iter()
            .map(|p| winding_number_brute(&tris, Vec3::from(*p)))
            .collect();
        let morton = FastWinding::build(&tris);
        let sah = FastWinding::from_bvh(&BvhAccel::build(&tris).bvh, &tris);
        let (m2, s2) = (
            morton.winding_numbers_at(&tris, &points, 2.0),
            sah.winding_numbers_at(&tris, &points, 2.0),
        );
        println!("morton {} sah {}", worst(&m2, &exact), worst(&s2, &exact));
        assert!(worst(&m2, &exact) < 5e-3, "morton at 2: {}", worst(&m2, &exact));
        assert!(worst(&m2, &s2) < 1e-2, "morton against sah: {}", worst(&m2, &s2));
        let m64 = morton.winding_numbers_at(&tris, &points, 64.0);
        assert!(worst(&m64, &exact) < 1e-5, "morton at 64: {}", worst(&m64, &exact));
    }

    /// No triangles: 0 everywhere (NaN off the finite points); one triangle: its exact angle
    /// (a leaf under the root); a triangle with a NaN vertex among others: no panic, and the
    /// finite answer of a point is NaN or finite, never a crash.
    #[test]
    fn morton_tree_edge_cases() {
        let empty = FastWinding::build(&[]);
        assert_eq!(empty.winding_number(&[], Vec3::ONE), 0.0);
        assert!(empty.winding_number(&[], Vec3::NAN).is_nan());
        let one = [TriAccel::new(Vec3::ZERO, Vec3::X, Vec3::Y)];
        let tree = FastWinding::build(&one);
        for p in [Vec3::new(0.2, 0.2, 0.5), Vec3::new(3.0, -1.0, -2.0), Vec3::splat(1e3)] {
            let (got, want) = (tree.winding_number(&one, p), winding_number_brute(&one, p));
            assert!((got - want).abs() < 1e-5, "{p}: {got} against {want}");
        }
        let bad = [one[0], TriAccel::new(Vec3::NAN, Vec3::X, Vec3::Z), one[0]];
        let tree = FastWinding::build(&bad);
        let _ = tree.winding_numbers(&bad, &[[0.2, 0.2, 0.5], [5.0, 5.0, 5.0]]);
    }

    /// `spread` puts bit `i` at bit `3 i`, for each of the 21 bits.
    #[test]
    fn spread_moves_each_bit_to_every_third() {
        for i in 0..BITS {
            assert_eq!(spread(1 << i), 1u64 << (3 * i), "bit {i}");
        }
        assert_eq!(spread(u32::MAX), 0x1249_2492_4924_9249);
    }
}
