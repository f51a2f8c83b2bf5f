//! The scene's 32-bit masks on the driver's 8-bit instance masks (`hwrt` over the driver's
//! instances, `instances.rs`).
//!
//! The rule is the software walks': a ray sees an instance when `ray_mask & instance_mask != 0`,
//! over 32 bits. The driver culls an instance when `cull_mask & instance.mask == 0`, over 8.
//! Both sides go through one table of eight 32-bit `classes`: a ray's cull mask has bit `j`
//! exactly when `classes[j] & ray_mask != 0` (the shader computes it, `driver_cull_mask`), and
//! each instance gets an 8-bit mask chosen with the table:
//!
//! - **Exact** (at most eight distinct non-zero instance masks, the default all-ones among
//!   them): `classes[j]` is the `j`-th distinct mask and an instance of mask `m = classes[j]`
//!   gets bit `j` alone. Then the driver sees it exactly when `classes[j] & ray_mask != 0`,
//!   which is the 32-bit rule itself; an instance of mask 0 gets 0 (never seen, as the rule
//!   says). The geometry is traced opaque: the hardware commits its hits itself.
//! - **Folded** (more distinct masks): `classes[j]` is every bit `k` with `k % 8 == j`, and an
//!   instance gets bit `j` where its mask has one of those bits. A ray and an instance that
//!   share bit `k` both get bit `k % 8`, so nothing the 32-bit rule sees is culled (the cull is
//!   conservative); it may keep an instance the rule does not see, so the shader traces the
//!   geometry non-opaque and confirms a candidate only where the instance's own 32-bit mask
//!   (in the instance table) shares a bit with the ray's.

/// Entries of the class table (the driver's mask bits).
pub const CLASSES: usize = 8;

/// The class table and each instance's 8-bit mask.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HardwareMasks {
    /// A ray's cull mask has bit `j` when `classes[j] & ray_mask != 0`.
    pub classes: [u32; CLASSES],
    /// Each instance's driver mask, in the instances' order.
    pub instance: Vec<u8>,
    /// Whether the driver's cull is the 32-bit rule exactly (opaque: no candidate is checked).
    pub exact: bool,
}

/// The table and the instances' driver masks for the instances' 32-bit `masks`.
pub fn hardware_masks(masks: &[u32]) -> HardwareMasks {
    let mut distinct: Vec<u32> = masks.iter().copied().filter(|&m| m != 0).collect();
    distinct.sort_unstable();
    distinct.dedup();
    if distinct.len() <= CLASSES {
        let mut classes = [0u32; CLASSES];
        classes[..distinct.len()].copy_from_slice(&distinct);
        let instance = masks
            .iter()
            .map(|m| distinct.binary_search(m).map_or(0, |j| 1u8 << j))
            .collect();
        return HardwareMasks {
            classes,
            instance,
            exact: true,
        };
    }
    let classes: [u32; CLASSES] = std::array::from_fn(|j| 0x0101_0101u32 << j);
    HardwareMasks {
        instance: masks.iter().map(|&m| cull_mask(&classes, m)).collect(),
        classes,
        exact: false,
    }
}

/// The driver mask of a 32-bit `mask` under `classes`: bit `j` where `classes[j]` shares a bit
/// with it (the shader's `driver_cull_mask` for a ray; the folded instances' masks).
pub fn cull_mask(classes: &[u32; CLASSES], mask: u32) -> u8 {
    (0..CLASSES).fold(0u8, |hw, j| if classes[j] & mask != 0 { hw | (1 << j) } else { hw })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::Rng;

    /// Exact tables cull exactly by the 32-bit rule; folded ones never cull what it sees, for
    /// masks drawn from few and from many bits.
    #[test]
    fn the_cull_is_exact_or_conservative() {
        let mut rng = Rng::new(5);
        for (instances, pool, want_exact) in [(50, 3u32, true), (200, 32, false), (20, 1, true)] {
            let draw = |rng: &mut Rng| {
                let mut m = 0u32;
                for _ in 0..rng.below(3) + 1 {
                    m |= 1 << rng.below(pool);
                }
                if rng.below(10) == 0 {
                    [0, u32::MAX][rng.below(2) as usize]
                } else {
                    m
                }
            };
            let masks: Vec<u32> = (0..instances).map(|_| draw(&mut rng)).collect();
            let hw = hardware_masks(&masks);
            assert_eq!(hw.exact, want_exact, "{pool} bits");
            for _ in 0..2000 {
                let ray = draw(&mut rng);
                let cull = cull_mask(&hw.classes, ray);
                for (i, &m) in masks.iter().enumerate() {
                    let sees = m & ray != 0;
                    let kept = cull & hw.instance[i] != 0;
                    if hw.exact {
                        assert_eq!(kept, sees, "ray {ray:#x}, instance {m:#x}");
                    } else {
                        assert!(kept || !sees, "ray {ray:#x}, instance {m:#x} culled");
                    }
                }
            }
        }
    }

    /// The default (every mask all-ones) is one class: exact, the fast path.
    #[test]
    fn all_ones_is_exact() {
        let hw = hardware_masks(&[u32::MAX; 5]);
        assert!(hw.exact);
        assert_eq!(hw.instance, vec![1; 5]);
        assert_eq!(cull_mask(&hw.classes, u32::MAX), 1);
        assert_eq!(cull_mask(&hw.classes, 0), 0);
    }
}
