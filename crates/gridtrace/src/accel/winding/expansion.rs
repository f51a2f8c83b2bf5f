//! The far-field expansion of a cluster of triangles' solid angle, to second order (Barill et
//! al. 2018, section 3.2; libigl's fast winding numbers use the same order).
//!
//! A surface element at `y` with area vector `n dA` subtends `n . g(y - p) dA` at `p`, with
//! `g(r) = r / |r|^3`. Around the cluster's centre `c`, with `q = c - p` and `d = y - c`,
//! Taylor in `d`:
//!
//! `Omega = N_k g_k(q) + N_ik d_i g_k(q) + 1/2 N_ijk d_i d_j g_k(q) + O((r/|q|)^3 / |q|^2)`
//!
//! with the moments `N_k = int n_k`, `N_ik = int d_i n_k`, `N_ijk = int d_i d_j n_k` over the
//! cluster, and the derivatives of `g`: `d_i g_k = delta_ik / |q|^3 - 3 q_i q_k / |q|^5`,
//! `d_i d_j g_k = -3 (delta_ij q_k + delta_ik q_j + delta_jk q_i) / |q|^5 + 15 q_i q_j q_k
//! / |q|^7`. With `h = q / |q|` (unit: the powers stay in range in `f32`):
//!
//! - order 0 (the dipole): `N . h / |q|^2`;
//! - order 1: `(tr N_ik - 3 h^T N_ik h) / |q|^3`;
//! - order 2: `(-1.5 L . h + 7.5 C(h)) / |q|^4`, `L_m = sum_i N_iim + 2 N_mii` and `C` the
//!   cubic `N_ijk h_i h_j h_k` (ten monomials).
//!
//! A triangle about its own centroid has `N_ik = 0` and `N_ijk = N_k S_ij / 12`, `S` the sum of
//! its vertices' `d d^T` (the second moment of a triangle is `area / 12` times that sum).
//! A parent's moments are its children's moved to the parent's centre (`shift`). The
//! moments are summed in `f64` and stored for the queries in `f32` (`coefficients`): the
//! terms a far node contributes are small and need no more.

use glam::DVec3;

use crate::accel::TriAccel;

/// A cluster's moments about its centre.
#[derive(Debug, Clone, Copy)]
pub(super) struct Moment {
    /// Area-weighted centre of the cluster's triangles (their vertices' mean for a cluster of
    /// no area).
    pub center: DVec3,
    /// Every vertex of the cluster is within this distance of `center`.
    pub radius: f64,
    /// Total area (weights the centres when clusters merge).
    pub area: f64,
    /// `N_k`: the sum of the area vectors.
    n: [f64; 3],
    /// `N_ik = int d_i n_k`.
    nik: [[f64; 3]; 3],
    /// `N_ijk = int d_i d_j n_k` (symmetric in `i, j`).
    nijk: [[[f64; 3]; 3]; 3],
}

/// The coefficients a query reads per cluster, in this order: centre (3), radius squared,
/// `N` (3), order 1's quadratic form (`xx, yy, zz, xy + yx, yz + zy, zx + xz`), order 2's `L`
/// (3) and cubic (`xxx, yyy, zzz, xxy, xxz, yyx, yyz, zzx, zzy, xyz`).
pub(super) const FIELDS: usize = 26;

/// Monomial of the cubic `C(h)` for `h_i h_j h_k` (`coefficients`' order, from 0).
fn cubic_slot(i: usize, j: usize, k: usize) -> usize {
    let mut c = [0u8; 3];
    for a in [i, j, k] {
        c[a] += 1;
    }
    match c {
        [3, 0, 0] => 0,
        [0, 3, 0] => 1,
        [0, 0, 3] => 2,
        [2, 1, 0] => 3,
        [2, 0, 1] => 4,
        [1, 2, 0] => 5,
        [0, 2, 1] => 6,
        [1, 0, 2] => 7,
        [0, 1, 2] => 8,
        _ => 9,
    }
}

impl Moment {
    /// No triangles (a placeholder until a node's moments are known).
    pub const ZERO: Moment = Moment {
        center: DVec3::ZERO,
        radius: 0.0,
        area: 0.0,
        n: [0.0; 3],
        nik: [[0.0; 3]; 3],
        nijk: [[[0.0; 3]; 3]; 3],
    };

    /// One triangle about its centroid (the tests' reference for `leaf`).
    #[cfg(test)]
    pub fn triangle(t: &TriAccel) -> Moment {
        let v = t.vertices().map(|v| v.as_dvec3());
        let center = (v[0] + v[1] + v[2]) / 3.0;
        let n = (v[1] - v[0]).cross(v[2] - v[0]) * 0.5;
        let d = v.map(|v| v - center);
        let mut nijk = [[[0.0; 3]; 3]; 3];
        for (i, row) in nijk.iter_mut().enumerate() {
            for (j, col) in row.iter_mut().enumerate() {
                let s: f64 = d.iter().map(|d| d[i] * d[j]).sum();
                for (k, x) in col.iter_mut().enumerate() {
                    *x = n[k] * s / 12.0;
                }
            }
        }
        Moment {
            center,
            radius: d.iter().map(|d| d.length()).fold(0.0, f64::max),
            area: n.length(),
            n: n.to_array(),
            nik: [[0.0; 3]; 3],
            nijk,
        }
    }

    /// A few triangles' moments about their area-weighted centre, the radius through their
    /// vertices (a leaf's): what `triangle` of each, `merge` and `with_radius` give, in two
    /// passes over the vertices without each triangle's moments. (Built that way, the leaves
    /// took 0.25 s of CPU over the Dragon's 871,414 triangles, most of a tree's build: a
    /// 352-byte moment a triangle, made, copied and merged.)
    pub fn leaf<'a>(tris: impl Iterator<Item = &'a TriAccel> + Clone) -> Moment {
        let corners = |t: &TriAccel| t.vertices().map(|v| v.as_dvec3());
        let area_vector = |v: &[DVec3; 3]| (v[1] - v[0]).cross(v[2] - v[0]) * 0.5;
        let (mut area, mut weighted, mut plain, mut count) = (0.0, DVec3::ZERO, DVec3::ZERO, 0.0);
        for t in tris.clone() {
            let v = corners(t);
            let (a, c) = (area_vector(&v).length(), (v[0] + v[1] + v[2]) / 3.0);
            area += a;
            weighted += c * a;
            plain += c;
            count += 1.0;
        }
        let center = if area > 0.0 {
            weighted / area
        } else {
            plain / f64::max(count, 1.0)
        };
        let mut out = Moment {
            center,
            area,
            ..Moment::ZERO
        };
        for t in tris {
            let v = corners(t);
            let n = area_vector(&v).to_array();
            let c = (v[0] + v[1] + v[2]) / 3.0;
            let delta = (c - center).to_array();
            let d = v.map(|v| (v - c).to_array());
            for (k, &nk) in n.iter().enumerate() {
                out.n[k] += nk;
                for (row, di) in out.nik.iter_mut().zip(delta) {
                    row[k] += di * nk;
                }
            }
            for i in 0..3 {
                for j in 0..3 {
                    // `triangle`'s `N_ijk` about its centroid moved to `center` (`merge`).
                    let m = (d[0][i] * d[0][j] + d[1][i] * d[1][j] + d[2][i] * d[2][j]) / 12.0 + delta[i] * delta[j];
                    for (x, nk) in out.nijk[i][j].iter_mut().zip(n) {
                        *x += m * nk;
                    }
                }
            }
            for v in v {
                out.radius = out.radius.max((v - center).length());
            }
        }
        out
    }

    /// The union of clusters, its moments about its own centre; its radius holds the parts'
    /// spheres (a leaf's, `leaf`, is through its vertices; `shape.rs` tightens an inner
    /// node's by its box).
    pub fn merge(parts: &[Moment]) -> Moment {
        let area: f64 = parts.iter().map(|m| m.area).sum();
        let center = if area > 0.0 {
            parts.iter().map(|m| m.center * m.area).sum::<DVec3>() / area
        } else {
            parts.iter().map(|m| m.center).sum::<DVec3>() / parts.len().max(1) as f64
        };
        let mut out = Moment {
            center,
            radius: parts
                .iter()
                .map(|m| (m.center - center).length() + m.radius)
                .fold(0.0, f64::max),
            area,
            n: [0.0; 3],
            nik: [[0.0; 3]; 3],
            nijk: [[[0.0; 3]; 3]; 3],
        };
        for m in parts {
            // `d = d' + delta` with `d'` about the part's centre: the moments of `d` expand
            // into the part's moments of `d'` and lower ones times `delta`.
            let delta = (m.center - center).to_array();
            for k in 0..3 {
                out.n[k] += m.n[k];
                for i in 0..3 {
                    out.nik[i][k] += m.nik[i][k] + delta[i] * m.n[k];
                    for j in 0..3 {
                        out.nijk[i][j][k] += m.nijk[i][j][k]
                            + delta[i] * m.nik[j][k]
                            + delta[j] * m.nik[i][k]
                            + delta[i] * delta[j] * m.n[k];
                    }
                }
            }
        }
        out
    }

    /// The same moments with the radius of the vertices given (a leaf's: tighter than the
    /// merged spheres).
    #[cfg(test)]
    pub fn with_radius(mut self, vertices: impl Iterator<Item = DVec3>) -> Moment {
        self.radius = vertices.map(|v| (v - self.center).length()).fold(0.0, f64::max);
        self
    }

    /// The query's coefficients (`FIELDS`), in `f32`.
    pub fn coefficients(&self) -> [f32; FIELDS] {
        let mut out = [0.0f64; FIELDS];
        out[..3].copy_from_slice(&self.center.to_array());
        out[3] = self.radius * self.radius;
        out[4..7].copy_from_slice(&self.n);
        let q = &self.nik;
        out[7..13].copy_from_slice(&[
            q[0][0],
            q[1][1],
            q[2][2],
            q[0][1] + q[1][0],
            q[1][2] + q[2][1],
            q[2][0] + q[0][2],
        ]);
        for m in 0..3 {
            out[13 + m] = (0..3).map(|i| self.nijk[i][i][m] + 2.0 * self.nijk[m][i][i]).sum();
        }
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    out[16 + cubic_slot(i, j, k)] += self.nijk[i][j][k];
                }
            }
        }
        out.map(|x| x as f32)
    }

    /// The expansion's solid angle at `p`, in `f64` (the reference the lanes' evaluation is
    /// tested against; the queries evaluate `coefficients` in `f32` lanes).
    #[cfg(test)]
    pub fn solid_angle(&self, p: DVec3) -> f64 {
        let c = self.coefficients().map(f64::from);
        let q = self.center - p;
        let len = q.length();
        let h = q / len;
        let (x, y, z) = (h.x, h.y, h.z);
        let order0 = (c[4] * x + c[5] * y + c[6] * z) / (len * len);
        let quad = c[7] * x * x + c[8] * y * y + c[9] * z * z + c[10] * x * y + c[11] * y * z + c[12] * z * x;
        let order1 = (c[7] + c[8] + c[9] - 3.0 * quad) / len.powi(3);
        let lin = c[13] * x + c[14] * y + c[15] * z;
        let cubic = c[16] * x * x * x
            + c[17] * y * y * y
            + c[18] * z * z * z
            + c[19] * x * x * y
            + c[20] * x * x * z
            + c[21] * y * y * x
            + c[22] * y * y * z
            + c[23] * z * z * x
            + c[24] * z * z * y
            + c[25] * x * y * z;
        let order2 = (-1.5 * lin + 7.5 * cubic) / len.powi(4);
        order0 + order1 + order2
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::winding::solid_angle;

    /// `leaf` in one pass gives what each triangle's moments merged give (to rounding),
    /// degenerate triangles (a point, a segment) and a single triangle included.
    #[test]
    fn leaf_is_the_merge_of_its_triangles() {
        let mut rng = Rng::new(3);
        let mut corner = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let mut tris: Vec<TriAccel> = (0..7).map(|_| TriAccel::new(corner(), corner(), corner())).collect();
        let p = corner();
        tris.push(TriAccel::new(p, p, p));
        tris.push(TriAccel::new(p, p + Vec3::X, p + Vec3::X * 2.0));
        for part in [&tris[..], &tris[..1], &tris[7..]] {
            let parts: Vec<Moment> = part.iter().map(Moment::triangle).collect();
            let want = Moment::merge(&parts).with_radius(part.iter().flat_map(|t| t.vertices()).map(|v| v.as_dvec3()));
            let got = Moment::leaf(part.iter());
            assert!((got.center - want.center).length() < 1e-12 && (got.radius - want.radius).abs() < 1e-12);
            for (a, b) in got.coefficients().iter().zip(want.coefficients()) {
                assert!((a - b).abs() <= 1e-6 * b.abs().max(1e-6), "{a} against {b}");
            }
        }
    }
    use crate::util::Rng;
    use glam::Vec3;

    /// A patch of a sphere (open: its area vectors do not cancel), seen from farther and
    /// farther along a random direction: the second-order expansion's error against the exact
    /// sum falls as `(r / |q|)^3` relative to the dipole's size, so doubling the distance
    /// divides it by about 2^5 = 32 (the dipole itself falls as 2^2; the dipole alone's error
    /// would fall only by 2^3). Measured here: ratios above 20 each step.
    #[test]
    fn expansion_error_falls_as_the_third_order() {
        let mut rng = Rng::new(7);
        let mut tris = Vec::new();
        for _ in 0..60 {
            let mut corner = || {
                let (u, v) = (rng.range(0.0, 0.8), rng.range(0.0, 0.8));
                Vec3::new(u, v, 0.3 * (u * u - v * v))
            };
            let (a, b, c) = (corner(), corner(), corner());
            tris.push(TriAccel::new(a, b, c));
        }
        let parts: Vec<Moment> = tris.iter().map(Moment::triangle).collect();
        let m = Moment::merge(&parts).with_radius(tris.iter().flat_map(|t| t.vertices()).map(|v| v.as_dvec3()));
        let dir = DVec3::new(0.3, -0.5, 0.8).normalize();
        let mut last = f64::NAN;
        for step in 0..4 {
            let p = m.center + dir * m.radius * 2.0 * f64::from(1 << step);
            let exact: f64 = tris.iter().map(|t| solid_angle(t, p.as_vec3())).sum();
            let err = (m.solid_angle(p) - exact).abs();
            if step > 0 {
                assert!(last / err > 20.0, "step {step}: error {err} after {last}");
            }
            last = err;
        }
    }
}
