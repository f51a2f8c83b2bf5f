//! Lattice basics that every grid walk shares (the uniform grid's DDA, the irregular grid's
//! point lookups): which axis a ray leaves a cell by, and which way it steps.

/// Index of the smallest element, the first on ties (glam's `min_position`; the WGSL
/// `min_position` in common.wgsl is the same).
#[inline(always)]
pub(crate) fn min_position(v: [f32; 3]) -> usize {
    let mut m = v[0];
    let mut i = 0;
    if v[1] < m {
        m = v[1];
        i = 1;
    }
    if v[2] < m {
        i = 2;
    }
    i
}

#[inline(always)]
pub(crate) fn sign(x: f32) -> i32 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}
