//! Proximity clouds (Cohen & Sheffer 1994): for every cell, the Chebyshev distance in cells to
//! the nearest non-empty cell. A ray in a cell with distance `d` may jump over the cube of
//! `(2d-1)^3` cells around it, which is guaranteed empty.
//!
//! Computed with the linear-time separable algorithm of Meijster, Roerdink and Hesselink (2000)
//! for the chessboard metric: the L-infinity distance is a min over cells of a max over axes, so
//! it factors into three 1-D passes (x, then y over the x result, then z over the y result).

/// Distance of a cell with no non-empty cell anywhere in the grid.
pub const FAR: u32 = u32::MAX;

/// `occupied[x + dims[0]*(y + dims[1]*z)]` -> distance per cell (0 for occupied cells).
pub fn chebyshev_distance_transform(dims: [u32; 3], occupied: &[bool]) -> Vec<u32> {
    let [nx, ny, nz] = dims.map(|d| d as usize);
    assert_eq!(occupied.len(), nx * ny * nz);
    // Larger than any real distance, small enough that sums of two stay in i64 comfortably.
    let inf: i64 = (nx + ny + nz) as i64 + 1;
    let mut g: Vec<i64> = occupied.iter().map(|&o| if o { 0 } else { inf }).collect();

    let mut line_in = Vec::new();
    let mut line_out = Vec::new();
    let mut s = Vec::new();
    let mut t = Vec::new();
    // One pass along `axis`: for each line along it, replace g by min_i max(|x-i|, g(i)).
    for (len, stride, others) in [
        (nx, 1usize, lines(nx, ny, nz, 0)),
        (ny, nx, lines(nx, ny, nz, 1)),
        (nz, nx * ny, lines(nx, ny, nz, 2)),
    ] {
        for start in others {
            line_in.clear();
            line_in.extend((0..len).map(|i| g[start + i * stride]));
            line_out.resize(len, 0);
            chessboard_1d(&line_in, &mut line_out, inf, &mut s, &mut t);
            for i in 0..len {
                g[start + i * stride] = line_out[i];
            }
        }
    }
    g.into_iter().map(|d| if d >= inf { FAR } else { d as u32 }).collect()
}

/// Start indices of all lines along `axis`.
fn lines(nx: usize, ny: usize, nz: usize, axis: usize) -> Vec<usize> {
    match axis {
        0 => (0..ny * nz).map(|yz| yz * nx).collect(),
        1 => (0..nz).flat_map(|z| (0..nx).map(move |x| x + z * nx * ny)).collect(),
        _ => (0..nx * ny).collect(),
    }
}

/// 1-D lower envelope of `f_i(x) = max(|x - i|, g(i))` (Meijster et al., chessboard metric).
fn chessboard_1d(g: &[i64], out: &mut [i64], inf: i64, s: &mut Vec<i64>, t: &mut Vec<i64>) {
    let m = g.len() as i64;
    let f = |x: i64, i: i64| (x - i).abs().max(g[i as usize]);
    // Sep(i, u): first x at which f_u is no larger than f_i (for i < u).
    let sep = |i: i64, u: i64| {
        let (gi, gu) = (g[i as usize], g[u as usize]);
        if gi <= gu {
            (i + gu).max((i + u) / 2)
        } else {
            (u - gi).min((i + u) / 2)
        }
    };
    s.clear();
    t.clear();
    s.push(0);
    t.push(0);
    for u in 1..m {
        while let (Some(&sq), Some(&tq)) = (s.last(), t.last()) {
            if f(tq, sq) > f(tq, u) {
                s.pop();
                t.pop();
            } else {
                break;
            }
        }
        if s.is_empty() {
            s.push(u);
            t.push(0);
        } else {
            let w = 1 + sep(*s.last().unwrap(), u);
            if w < m {
                s.push(u);
                t.push(w);
            }
        }
    }
    for u in (0..m).rev() {
        let q = s.len() - 1;
        out[u as usize] = f(u, s[q]).min(inf);
        if u == t[q] {
            s.pop();
            t.pop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::Rng;

    fn brute(dims: [u32; 3], occ: &[bool]) -> Vec<u32> {
        let [nx, ny, nz] = dims.map(|d| d as i64);
        let mut out = vec![FAR; occ.len()];
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let mut best = FAR;
                    for (i, &o) in occ.iter().enumerate() {
                        if o {
                            let i = i as i64;
                            let (ox, oy, oz) = (i % nx, (i / nx) % ny, i / (nx * ny));
                            let d = (x - ox).abs().max((y - oy).abs()).max((z - oz).abs()) as u32;
                            best = best.min(d);
                        }
                    }
                    out[(x + nx * (y + ny * z)) as usize] = best;
                }
            }
        }
        out
    }

    #[test]
    fn equals_brute_force_on_random_grids() {
        let mut rng = Rng::new(42);
        for case in 0..300 {
            let dims = [1 + rng.below(12), 1 + rng.below(12), 1 + rng.below(12)];
            let n = dims.iter().product::<u32>() as usize;
            // From very sparse (often a single cell or none) to dense.
            let density = [0.0, 0.002, 0.01, 0.05, 0.2, 0.6][case % 6];
            let occ: Vec<bool> = (0..n).map(|_| rng.next_f32() < density).collect();
            let got = chebyshev_distance_transform(dims, &occ);
            assert_eq!(got, brute(dims, &occ), "dims {dims:?} case {case}");
        }
    }

    #[test]
    fn single_cell_and_empty() {
        let mut occ = vec![false; 5 * 4 * 3];
        assert!(chebyshev_distance_transform([5, 4, 3], &occ).iter().all(|&d| d == FAR));
        occ[0] = true;
        let d = chebyshev_distance_transform([5, 4, 3], &occ);
        assert_eq!(d[0], 0);
        assert_eq!(d[4 + 5 * (3 + 4 * 2)], 4);
        assert_eq!(d[1 + 5 * (3 + 4)], 3); // cell (1, 3, 1)
    }
}
