//! Fast winding numbers (Barill, Dickson, Schmidt, Levin, Jacobson 2018, "Fast Winding Numbers
//! for Soups and Clouds"), first order: a binary BVH over the triangles (the library's SAH
//! builder), and for each node the sum of its triangles' area vectors `A = sum (e1 x e2) / 2`,
//! their area-weighted centre `c` and a radius `r` around `c` that holds them all.
//!
//! Seen from a point `p` far from a node (`|c - p| > BETA * r`), the node's triangles subtend
//! about the solid angle of one small flat patch at `c`: `A . (c - p) / |c - p|^3` (the dipole
//! term of the expansion; its relative error falls as `(r / |c - p|)^2`). Nearer nodes are
//! opened, down to exact solid angles (`solid_angle`) at the leaves. A point in empty space
//! far from the mesh costs a handful of nodes instead of every triangle; a point near the
//! surface opens the nodes around it and is exact there.
//!
//! A closed piece of surface has `A = 0` (its area vectors cancel) and subtends 0 from outside:
//! the far-field term is right for it whatever its size. The error of an open piece is what the
//! tests bound (against brute force, well under the 0.5 the inside test needs away from the
//! surface).

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::solid_angle;
use crate::accel::{Aabb, Bvh, TriAccel};

/// A node is summed as a dipole when the point is farther than `BETA` times its radius (the
/// paper's accuracy parameter; 2 is its default, and the queries' default `accuracy`).
pub const BETA: f64 = 2.0;

/// Checks an `accuracy` (the paper's beta): a number above 0, `inf` for the exact sum. An error
/// naming the argument otherwise (0, negative or NaN would open no node, or every node by
/// accident of a comparison with NaN).
pub fn check_accuracy(accuracy: f64) -> crate::Result<f64> {
    if accuracy > 0.0 {
        Ok(accuracy)
    } else {
        Err(crate::Error::InvalidInput(format!(
            "accuracy must be above 0 (libigl's beta: 2 is the default, larger is more accurate, inf is exact); got {accuracy}"
        )))
    }
}

/// One node's far-field data.
#[derive(Debug, Clone, Copy)]
struct Moment {
    /// Area-weighted centre of the node's triangles.
    center: DVec3,
    /// Sum of the triangles' area vectors (`(e1 x e2) / 2`).
    area: DVec3,
    /// Every vertex of the node's triangles is within this distance of `center`.
    radius: f64,
    /// Total area of the node's triangles (weights the centres when nodes merge).
    total: f64,
}

/// A binary BVH with the far-field data of each node, over the triangles the queries are
/// given (`winding_number` takes the same slice `build` did).
#[derive(Debug, Clone)]
pub struct FastWinding {
    bvh: Bvh,
    moments: Vec<Moment>,
    triangles: usize,
}

impl FastWinding {
    /// Builds the tree and its moments over `tris`.
    pub fn build(tris: &[TriAccel]) -> FastWinding {
        let boxes: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(&t.vertices())).collect();
        let centers: Vec<Vec3> = boxes.iter().map(Aabb::center).collect();
        let bvh = Bvh::build(&boxes, &centers);
        let mut moments = vec![
            Moment {
                center: DVec3::ZERO,
                area: DVec3::ZERO,
                radius: 0.0,
                total: 0.0,
            };
            bvh.nodes.len()
        ];
        if !tris.is_empty() {
            // Children before parents: the reverse of a preorder (whatever the node numbering).
            let mut order = Vec::with_capacity(bvh.nodes.len());
            let mut stack = vec![0usize];
            while let Some(i) = stack.pop() {
                order.push(i);
                let n = &bvh.nodes[i];
                if !n.is_leaf() {
                    stack.extend([n.first as usize, n.first as usize + 1]);
                }
            }
            for &i in order.iter().rev() {
                let n = bvh.nodes[i];
                moments[i] = if n.is_leaf() {
                    leaf_moment(tris, &bvh.prims[n.first as usize..(n.first + n.count) as usize])
                } else {
                    merge(&moments[n.first as usize], &moments[n.first as usize + 1])
                };
            }
        }
        FastWinding {
            bvh,
            moments,
            triangles: tris.len(),
        }
    }

    /// The winding number of `p` with respect to `tris` (the triangles given to `build`), to
    /// the accuracy of the far-field terms (module notes); NaN for a point that is not finite.
    pub fn winding_number(&self, tris: &[TriAccel], p: Vec3) -> f32 {
        self.winding_number_with(tris, p, BETA, &mut Vec::new())
    }

    /// The winding numbers of a batch of points, on all cores, at the default accuracy
    /// (`BETA`): `winding_numbers_at`.
    pub fn winding_numbers(&self, tris: &[TriAccel], points: &[[f32; 3]]) -> Vec<f32> {
        self.winding_numbers_at(tris, points, BETA)
    }

    /// The winding numbers of a batch of points, on all cores, a node summed as a dipole where
    /// the point is farther than `accuracy` times its radius (`check_accuracy`; `inf`: never, the
    /// exact sum of every triangle's solid angle). Each worker keeps one stack
    /// (`winding_number_with`).
    pub fn winding_numbers_at(&self, tris: &[TriAccel], points: &[[f32; 3]], accuracy: f64) -> Vec<f32> {
        points
            .par_iter()
            .with_min_len(64)
            .map_init(Vec::new, |stack, p| {
                self.winding_number_with(tris, Vec3::from(*p), accuracy, stack)
            })
            .collect()
    }

    /// `winding_number` with the caller's stack, kept between points: a batch's worker reuses
    /// one (`winding_numbers`). A fresh stack per point cost three allocations and frees a point, and
    /// on two threads the allocator's locks held the batch to 1.1-1.6x its one-thread speed
    /// (perf, 200,000 points at the Stanford Bunny: 12% of samples in malloc, free and
    /// realloc, 11% in the kernel's futex wake-ups); with the stack kept, 1.8-2.0x.
    /// `accuracy` as `winding_numbers_at` takes it.
    pub fn winding_number_with(&self, tris: &[TriAccel], p: Vec3, accuracy: f64, stack: &mut Vec<usize>) -> f32 {
        assert_eq!(tris.len(), self.triangles, "the triangles the tree was built over");
        if !p.is_finite() {
            return f32::NAN;
        }
        if tris.is_empty() {
            return 0.0;
        }
        let pd = p.as_dvec3();
        let mut sum = 0.0f64;
        stack.clear();
        stack.push(0);
        while let Some(i) = stack.pop() {
            let m = &self.moments[i];
            let to = m.center - pd;
            let d2 = to.length_squared();
            // With `accuracy` infinite the bound is infinite (or NaN for a node of radius 0,
            // which compares false too): every node is opened and the sum is exact.
            if d2 > (accuracy * m.radius).powi(2) {
                sum += m.area.dot(to) / (d2 * d2.sqrt());
                continue;
            }
            let n = &self.bvh.nodes[i];
            if n.is_leaf() {
                for &t in &self.bvh.prims[n.first as usize..(n.first + n.count) as usize] {
                    sum += solid_angle(&tris[t as usize], p);
                }
            } else {
                stack.extend([n.first as usize, n.first as usize + 1]);
            }
        }
        (sum / (4.0 * std::f64::consts::PI)) as f32
    }
}

/// The moment of a leaf's triangles. A leaf of zero total area takes its vertices' mean as its
/// centre.
fn leaf_moment(tris: &[TriAccel], prims: &[u32]) -> Moment {
    let mut area = DVec3::ZERO;
    let mut weighted = DVec3::ZERO;
    let mut total = 0.0;
    let mut mean = DVec3::ZERO;
    for &t in prims {
        let tri = &tris[t as usize];
        let a = tri.normal().as_dvec3() * 0.5;
        let [v0, v1, v2] = tri.vertices().map(|v| v.as_dvec3());
        let centroid = (v0 + v1 + v2) / 3.0;
        area += a;
        weighted += centroid * a.length();
        total += a.length();
        mean += centroid;
    }
    let center = if total > 0.0 {
        weighted / total
    } else {
        mean / prims.len().max(1) as f64
    };
    let radius = prims
        .iter()
        .flat_map(|&t| tris[t as usize].vertices())
        .map(|v| (v.as_dvec3() - center).length())
        .fold(0.0, f64::max);
    Moment {
        center,
        area,
        radius,
        total,
    }
}

/// The moment of two children: centres weighted by area (halfway if neither has any), a
/// radius that holds both children's spheres.
fn merge(a: &Moment, b: &Moment) -> Moment {
    let total = a.total + b.total;
    let center = if total > 0.0 {
        (a.center * a.total + b.center * b.total) / total
    } else {
        (a.center + b.center) * 0.5
    };
    let radius = ((a.center - center).length() + a.radius).max((b.center - center).length() + b.radius);
    Moment {
        center,
        area: a.area + b.area,
        radius,
        total,
    }
}
