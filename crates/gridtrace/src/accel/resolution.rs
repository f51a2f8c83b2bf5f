//! How many cells a lattice over the scene has: the uniform grid's resolution (`--accel grid:res=...`) and the
//! cube-root rule that the uniform grid and the irregular grid's top level share.

use glam::{UVec3, Vec3};

/// Default cells per triangle for the automatic resolution. Measured on the paper's scenes and
/// the Stanford bunny with `gridtrace bench --sweep-grid` (see docs/benchmarks.md): times are
/// flat within a few percent between 2 and 8; 4 is near the best for dense and sparse scenes.
pub const DEFAULT_LAMBDA: f32 = 4.0;

/// Upper bound on the number of cells; 2^26 cells are 768 MiB of cell data alone.
pub const MAX_CELLS: u64 = 1 << 26;

/// How the grid resolution is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Resolution {
    /// `dims = extent * cbrt(lambda * N / volume)`, with flat axes handled (see `auto_dims`).
    Auto { lambda: f32 },
    /// Given cell counts per axis, as the paper tuned per scene.
    Fixed([u32; 3]),
}

impl Default for Resolution {
    fn default() -> Self {
        Resolution::Auto { lambda: DEFAULT_LAMBDA }
    }
}

impl std::fmt::Display for Resolution {
    /// The form `FromStr` reads: `auto`, `auto:LAMBDA` or `AxBxC`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Resolution::Auto { lambda } if lambda == DEFAULT_LAMBDA => f.write_str("auto"),
            Resolution::Auto { lambda } => write!(f, "auto:{lambda}"),
            Resolution::Fixed([a, b, c]) => write!(f, "{a}x{b}x{c}"),
        }
    }
}

impl std::str::FromStr for Resolution {
    type Err = String;
    /// `auto`, `auto:LAMBDA`, `N` (NxNxN) or `AxBxC`.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let s = s.trim();
        if s == "auto" {
            return Ok(Resolution::default());
        }
        if let Some(l) = s.strip_prefix("auto:") {
            let lambda: f32 = l.parse().map_err(|_| format!("bad lambda '{l}'"))?;
            if !(lambda.is_finite() && lambda > 0.0) {
                return Err(format!("lambda must be positive, got {lambda}"));
            }
            return Ok(Resolution::Auto { lambda });
        }
        let parts: Vec<&str> = s.split(['x', 'X']).collect();
        let nums: std::result::Result<Vec<u32>, _> = parts.iter().map(|p| p.trim().parse::<u32>()).collect();
        match nums.as_deref() {
            Ok([n]) if *n > 0 => Ok(Resolution::Fixed([*n; 3])),
            Ok([a, b, c]) if *a > 0 && *b > 0 && *c > 0 => Ok(Resolution::Fixed([*a, *b, *c])),
            _ => Err(format!(
                "grid resolution must be 'auto', 'auto:LAMBDA', 'N' or 'AxBxC' with positive integers, got '{s}'"
            )),
        }
    }
}

/// Grid dimensions as everyone prints them: `AxBxC`.
pub fn dims_str(d: [u32; 3]) -> String {
    format!("{}x{}x{}", d[0], d[1], d[2])
}

/// Cube-root rule `dims = extent * cbrt(lambda * N / volume)`, generalised to flat scenes: an axis
/// whose share would be below one cell gets one cell, and the budget of `lambda * N` cells is
/// re-solved over the remaining axes (square root for a planar scene, linear for a line).
pub fn auto_dims(extent: Vec3, n_tris: usize, lambda: f32) -> UVec3 {
    let budget = (lambda as f64 * n_tris.max(1) as f64).min(MAX_CELLS as f64);
    let ext = extent.as_dvec3().to_array();
    let mut fixed = [false; 3];
    let mut dims = [1.0f64; 3];
    loop {
        let free: Vec<usize> = (0..3).filter(|&a| !fixed[a]).collect();
        if free.is_empty() {
            break;
        }
        let fixed_cells: f64 = (0..3).filter(|&a| fixed[a]).map(|a| dims[a]).product();
        let free_volume: f64 = free.iter().map(|&a| ext[a]).product();
        if free_volume <= 0.0 {
            // Some free axis has zero extent: it gets one cell.
            for &a in &free {
                if ext[a] <= 0.0 {
                    fixed[a] = true;
                    dims[a] = 1.0;
                }
            }
            continue;
        }
        let k = (budget / fixed_cells / free_volume).powf(1.0 / free.len() as f64);
        let mut changed = false;
        for &a in &free {
            dims[a] = ext[a] * k;
            if dims[a] < 1.0 {
                fixed[a] = true;
                dims[a] = 1.0;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    UVec3::new(dims[0].round() as u32, dims[1].round() as u32, dims[2].round() as u32)
        .clamp(UVec3::ONE, UVec3::splat(1024))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_dims_cube_and_flat() {
        let d = auto_dims(Vec3::ONE, 1000, 8.0);
        assert_eq!(d, UVec3::splat(20));
        // A planar scene gets a 2-D grid with about lambda*N cells.
        let d = auto_dims(Vec3::new(2.0, 0.0, 1.0), 1000, 2.0);
        assert_eq!(d.y, 1);
        assert!((d.x * d.z) as f32 > 1500.0 && ((d.x * d.z) as f32) < 2500.0, "{d}");
        // A nearly flat scene does too, rather than a budget wasted on the thin axis.
        let d = auto_dims(Vec3::new(1.0, 1e-4, 1.0), 1000, 4.0);
        assert_eq!(d.y, 1);
        assert!(d.x >= 60 && d.x <= 66, "{d}");
        // A line.
        let d = auto_dims(Vec3::new(0.0, 0.0, 5.0), 100, 4.0);
        assert_eq!(d, UVec3::new(1, 1, 400));
    }

    #[test]
    fn parse_resolution() {
        assert_eq!(
            "20x16x14".parse::<Resolution>().unwrap(),
            Resolution::Fixed([20, 16, 14])
        );
        assert_eq!("16".parse::<Resolution>().unwrap(), Resolution::Fixed([16; 3]));
        assert_eq!("auto".parse::<Resolution>().unwrap(), Resolution::default());
        assert!("0x1x1".parse::<Resolution>().is_err());
        assert!("1x2".parse::<Resolution>().is_err());
        assert!("auto:-1".parse::<Resolution>().is_err());
    }
}
