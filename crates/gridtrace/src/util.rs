//! Small shared utilities.

/// The host's monotonic clock for the timings the library reports: std's on native targets;
/// in a browser (wasm32-unknown-unknown, where `std::time::Instant::now` panics: the target
/// has no clock of its own) the page's `performance.now()`, through web-time, whose `Instant`
/// has std's API.
#[cfg(not(target_arch = "wasm32"))]
pub use std::time::Instant;
#[cfg(target_arch = "wasm32")]
pub use web_time::Instant;

/// The most CPU threads a caller may ask for (`--threads`, Python's `threads=` and
/// `nthreads=`): far above any machine's cores, so oversubscribing to measure stays possible,
/// while a slip such as 100000 is refused at once. Asked for 100,000, the thread pool starts
/// that many OS threads, each with its stack, and the call sat for minutes like a hang.
pub const MAX_THREADS: usize = 1024;

/// A point or direction written `x,y,z` with finite numbers: the CLI's `--eye`, `--target`,
/// `--up`, the web page's `eye=`, `target=`.
pub fn parse_vec3(s: &str) -> Result<glam::Vec3, String> {
    let v: Result<Vec<f32>, _> = s.split(',').map(|p| p.trim().parse::<f32>()).collect();
    match v.as_deref() {
        Ok([x, y, z]) if x.is_finite() && y.is_finite() && z.is_finite() => Ok(glam::Vec3::new(*x, *y, *z)),
        _ => Err(format!("expected x,y,z with finite numbers, got '{s}'")),
    }
}

/// xorshift64*, the stream the examples draw their scenes, rays and points from
/// (`crates/gridtrace/examples/`): one generator, so that the figures docs/benchmarks.md
/// records from them stay reproducible. Uniform `f32` in `[0, 1)` from the top 24 bits.
#[derive(Debug, Clone)]
pub struct Xorshift(u64);

impl Default for Xorshift {
    fn default() -> Self {
        Xorshift(0x9E37_79B9_7F4A_7C15)
    }
}

impl Xorshift {
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f32 {
        let s = &mut self.0;
        *s ^= *s >> 12;
        *s ^= *s << 25;
        *s ^= *s >> 27;
        (s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A random similarity: a uniformly spread rotation, a uniform scale in `0.5..1.5` and a
    /// translation in a cube of side `spread` about the origin (the instance benchmarks' scenes).
    pub fn similarity(&mut self, spread: f32) -> glam::Mat4 {
        use glam::{Quat, Vec3};
        let q = Quat::from_xyzw(
            self.unit() - 0.5,
            self.unit() - 0.5,
            self.unit() - 0.5,
            self.unit() - 0.5,
        )
        .normalize();
        let s = 0.5 + self.unit();
        let t = (Vec3::new(self.unit(), self.unit(), self.unit()) - 0.5) * spread;
        glam::Mat4::from_scale_rotation_translation(Vec3::splat(s), q, t)
    }

    /// `n` points uniform in the box `lo..hi` grown by `pad` times its size on each side (the
    /// point queries' benchmarks: a tenth).
    pub fn points_around(&mut self, (lo, hi): (glam::Vec3, glam::Vec3), pad: f32, n: usize) -> Vec<[f32; 3]> {
        let grow = (hi - lo) * pad;
        let (lo, size) = (lo - grow, hi - lo + 2.0 * grow);
        (0..n)
            .map(|_| (lo + glam::Vec3::new(self.unit(), self.unit(), self.unit()) * size).to_array())
            .collect()
    }
}

/// A tiny deterministic PRNG (SplitMix64) for tests, benchmarks and procedural scenes, so
/// results are reproducible without pulling a random-number crate into the library.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }

    pub fn below(&mut self, n: u32) -> u32 {
        (((self.next_u64() >> 32) * n as u64) >> 32) as u32
    }
}

/// The indices of the set bits of `mask`, lowest first (the lanes of a packet a mask selects).
#[inline(always)]
pub(crate) fn set_bits(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            i
        })
    })
}

/// Bytes as people read them: `B`, `KiB` with one decimal, `MiB` with two.
pub fn fmt_bytes(b: usize) -> String {
    if b >= 1 << 20 {
        format!("{:.2} MiB", b as f64 / (1 << 20) as f64)
    } else if b >= 1 << 10 {
        format!("{:.1} KiB", b as f64 / 1024.0)
    } else {
        format!("{b} B")
    }
}
