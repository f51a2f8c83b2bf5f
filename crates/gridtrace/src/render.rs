//! What a render is, independent of the backend: modes, options, images, statistics, and the
//! shading rules both backends follow (so their images agree).

use glam::Vec3;
use rayon::prelude::*;

use crate::accel::TraversalCounters;

/// The paper's three workloads plus a traversal-cost view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// Eye rays, diffuse N.L shading, no shadows (Table 1).
    Cast,
    /// Plus one shadow ray per light per hit (Table 2).
    Shadow,
    /// Plus mirror reflection rays, two levels; every hit shaded with shadows (Table 3).
    Trace,
    /// Eye rays coloured by traversal cost (cells visited + triangle tests).
    Heat,
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "cast" => Ok(Mode::Cast),
            "shadow" => Ok(Mode::Shadow),
            "trace" => Ok(Mode::Trace),
            "heat" => Ok(Mode::Heat),
            _ => Err(format!("mode must be cast, shadow, trace or heat; got '{s}'")),
        }
    }
}

impl Mode {
    pub const ALL: [Mode; 4] = [Mode::Cast, Mode::Shadow, Mode::Trace, Mode::Heat];
    pub fn name(self) -> &'static str {
        match self {
            Mode::Cast => "cast",
            Mode::Shadow => "shadow",
            Mode::Trace => "trace",
            Mode::Heat => "heat",
        }
    }
    /// Reflection levels traced after the eye ray.
    pub fn reflection_depth(self) -> u32 {
        if self == Mode::Trace { MAX_REFLECTION_DEPTH } else { 0 }
    }
    pub fn shadows(self) -> bool {
        matches!(self, Mode::Shadow | Mode::Trace)
    }
}

/// Two levels of reflection: at most three path segments per pixel, as in the paper.
pub const MAX_REFLECTION_DEPTH: u32 = 2;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub mode: Mode,
    /// Optimisations turned off, to measure what they buy (`bench --ablate`); none by default.
    pub ablation: Ablation,
    /// Trace only image rows `first..end` of the `width` x `height` frame (the camera still
    /// frames the whole image); the returned image is `width` x `end - first`. `None`: every
    /// row. The interactive viewer traces a frame band by band within a time budget, so a slow
    /// frame never holds up input; a band's pixels equal the same rows of the whole frame.
    pub rows: Option<(u32, u32)>,
    /// What the caller will do with the pixels (`PixelFormat`): `Linear` keeps every float bit,
    /// `Srgb8` lets the GPU convert on the device and read back 4 bytes a pixel instead of 16.
    pub pixels: PixelFormat,
}

/// How much of a frame's pixels the caller needs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum PixelFormat {
    /// Linear floats, every bit (tests, heat maps, further computation).
    #[default]
    Linear,
    /// Only their 8-bit sRGB levels (a PNG, a window). The GPU converts on the device, with the
    /// host's rounding (`linear_to_srgb8`), and reads back 4 bytes a pixel; the image it returns
    /// holds each level's linear value (`srgb8_to_linear`), so `to_rgb8` gives exactly the
    /// device's bytes. The CPU's image is already in host memory and is left as it is (the
    /// same `to_rgb8`, up to the device's `pow`: within one level). Heat frames stay linear
    /// (their raw costs are normalised by the frame's maximum afterwards).
    Srgb8,
}

/// Switches that each turn off one optimisation the paper credits (its any-hit shadow rays, its
/// early removal of finished rays), for `bench --ablate`. Images do not change; time does.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ablation {
    /// Shadow rays find the closest hit before the light instead of stopping at the first hit.
    pub shadow_closest_hit: bool,
    /// GPU: no compacted queues. Every ray keeps its slot through the bounces, a finished one
    /// idles there, and every kernel runs over the whole tile. The CPU has nothing to compact:
    /// it walks each pixel's rays to their end.
    pub no_compaction: bool,
}

impl Ablation {
    /// The ablations by name, as `bench --ablate` takes them.
    pub const NAMES: [&'static str; 2] = ["shadow-any-hit", "compaction"];

    /// The ablation that turns off the optimisation `name` (one of `NAMES`).
    pub fn named(name: &str) -> Option<Ablation> {
        match name {
            "shadow-any-hit" => Some(Ablation {
                shadow_closest_hit: true,
                ..Ablation::default()
            }),
            "compaction" => Some(Ablation {
                no_compaction: true,
                ..Ablation::default()
            }),
            _ => None,
        }
    }
}

/// The largest image side, in pixels, the tracers take (`RenderOptions::validate`); front ends
/// refuse larger sizes before any work with it (`gridtrace render --res`).
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// An image size as `WxH` or `N` (N x N): `render --res`, the viewer's and the web page's
/// `res`. Each side from 1 to `MAX_IMAGE_SIDE`, refused when read rather than after the scene
/// is built.
pub fn parse_res(s: &str) -> Result<(u32, u32), String> {
    let parts: Vec<&str> = s.split(['x', 'X']).collect();
    let nums: Result<Vec<u32>, _> = parts.iter().map(|p| p.trim().parse::<u32>()).collect();
    let (w, h) = match nums.as_deref() {
        Ok([n]) if *n > 0 => (*n, *n),
        Ok([w, h]) if *w > 0 && *h > 0 => (*w, *h),
        Ok([_] | [_, _]) => return Err(format!("image size must be positive in both directions, got '{s}'")),
        _ => return Err(format!("expected WxH or N (N x N) in pixels, got '{s}'")),
    };
    if w.max(h) > MAX_IMAGE_SIDE {
        return Err(format!(
            "image size {w}x{h} is too large: at most {MAX_IMAGE_SIDE} pixels a side ({MAX_IMAGE_SIDE}x{MAX_IMAGE_SIDE})"
        ));
    }
    Ok((w, h))
}

impl RenderOptions {
    pub fn new(width: u32, height: u32, mode: Mode) -> Self {
        RenderOptions {
            width,
            height,
            mode,
            ablation: Ablation::default(),
            rows: None,
            pixels: PixelFormat::Linear,
        }
    }

    /// These options with the pixels wanted as `pixels`.
    pub fn with_pixels(self, pixels: PixelFormat) -> Self {
        RenderOptions { pixels, ..self }
    }

    /// These options for rows `first..end` only (see `rows`).
    pub fn band(self, first: u32, end: u32) -> Self {
        RenderOptions {
            rows: Some((first, end)),
            ..self
        }
    }

    /// The rows traced: `first..end`, the whole image when `rows` is `None`.
    pub fn row_range(&self) -> std::ops::Range<u32> {
        match self.rows {
            Some((first, end)) => first..end,
            None => 0..self.height,
        }
    }

    pub fn validate(&self) -> crate::Result<()> {
        if self.width == 0 || self.height == 0 || self.width > MAX_IMAGE_SIDE || self.height > MAX_IMAGE_SIDE {
            return Err(crate::Error::InvalidInput(format!(
                "image size {}x{} must be between 1x1 and {MAX_IMAGE_SIDE}x{MAX_IMAGE_SIDE}",
                self.width, self.height
            )));
        }
        if let Some((first, end)) = self.rows
            && (first >= end || end > self.height)
        {
            return Err(crate::Error::InvalidInput(format!(
                "rows {first}..{end} must be a non-empty range within the image's {} rows",
                self.height
            )));
        }
        Ok(())
    }
}

/// Rays traced, by kind.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct RayCounts {
    pub eye: u64,
    pub shadow: u64,
    pub reflection: u64,
}

impl RayCounts {
    pub fn total(&self) -> u64 {
        self.eye + self.shadow + self.reflection
    }
}

impl std::ops::AddAssign for RayCounts {
    fn add_assign(&mut self, o: Self) {
        self.eye += o.eye;
        self.shadow += o.shadow;
        self.reflection += o.reflection;
    }
}

/// A linear-RGB float image, row 0 at the top. In heat mode each pixel holds the raw cost
/// (cells + triangle tests) in all three channels until `heat_to_color`.
///
/// A frame the GPU packed as 8-bit sRGB (`PixelFormat::Srgb8`) keeps the device's levels as
/// they came over the bus: `to_rgb8` and `save_png` use them as they are, and `pixels` turns
/// them into linear values the first time it is asked. Why: the float round trip (each level
/// to its linear value, then back through the sRGB curve for the PNG) was the readout of
/// every GPU frame, 26 ms of a 1920x1080 frame on a loaded 2-core machine, for a caller that
/// only wanted the bytes.
#[derive(Debug, Clone)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// The linear pixels: made at once, or from `srgb8` on first use.
    linear: std::sync::OnceLock<Vec<Vec3>>,
    /// The device's levels (red, green, blue, alpha 255), when the image came packed; dropped
    /// when the pixels are written (`pixels_mut`).
    srgb8: Option<Vec<[u8; 4]>>,
}

impl PartialEq for Image {
    fn eq(&self, other: &Image) -> bool {
        (self.width, self.height) == (other.width, other.height) && self.pixels() == other.pixels()
    }
}

impl Image {
    /// A black image. Its memory comes zeroed from the allocator (`calloc`: fresh pages need no
    /// writing), where `vec![Vec3::ZERO; n]` wrote every pixel: 17-22 ms of a 1920x1080 GPU
    /// frame's host time on this project's 2-core machine, before a pixel was traced.
    pub fn new(width: u32, height: u32) -> Self {
        Image::from_pixels(width, height, bytemuck::zeroed_vec((width * height) as usize))
    }

    /// An image of these linear pixels (`width * height` of them, row by row).
    pub fn from_pixels(width: u32, height: u32, pixels: Vec<Vec3>) -> Self {
        debug_assert_eq!(pixels.len(), (width * height) as usize);
        Image {
            width,
            height,
            linear: std::sync::OnceLock::from(pixels),
            srgb8: None,
        }
    }

    /// An image of 8-bit sRGB levels (red, green, blue, alpha; `width * height`, row by row),
    /// as the GPU packs them.
    pub fn from_srgb8(width: u32, height: u32, levels: Vec<[u8; 4]>) -> Self {
        debug_assert_eq!(levels.len(), (width * height) as usize);
        Image {
            width,
            height,
            linear: std::sync::OnceLock::new(),
            srgb8: Some(levels),
        }
    }

    /// The linear pixels (from the 8-bit levels, on every core, the first time for a packed
    /// image: each level's linear value, so that `to_rgb8` of them gives the levels back).
    pub fn pixels(&self) -> &[Vec3] {
        self.linear.get_or_init(|| {
            let levels = self.srgb8.as_deref().unwrap_or(&[]);
            let mut px: Vec<Vec3> = bytemuck::zeroed_vec(levels.len());
            px.par_iter_mut().zip(levels.par_iter()).for_each(|(p, l)| {
                *p = Vec3::new(srgb8_to_linear(l[0]), srgb8_to_linear(l[1]), srgb8_to_linear(l[2]));
            });
            px
        })
    }

    /// The linear pixels, to write (a packed image's levels are dropped: they would be stale).
    pub fn pixels_mut(&mut self) -> &mut [Vec3] {
        let _ = self.pixels();
        self.srgb8 = None;
        self.linear.get_mut().expect("made above")
    }

    /// The 8-bit levels to write, as the GPU's readout fills them: the image becomes a packed
    /// one (black where nothing is written), its linear pixels made from the levels on use.
    pub fn srgb8_mut(&mut self) -> &mut [[u8; 4]] {
        if self.srgb8.is_none() {
            self.srgb8 = Some(bytemuck::zeroed_vec((self.width * self.height) as usize));
        }
        self.linear = std::sync::OnceLock::new();
        self.srgb8.as_mut().expect("set above")
    }

    /// 8-bit sRGB, clamped: the device's levels as they came for a packed image, else each
    /// linear pixel through the sRGB curve (`linear_to_srgb8`), on every core.
    pub fn to_rgb8(&self) -> Vec<u8> {
        let mut out: Vec<u8> = bytemuck::zeroed_vec(3 * (self.width * self.height) as usize);
        if let Some(levels) = &self.srgb8 {
            out.par_chunks_exact_mut(3)
                .zip(levels.par_iter())
                .for_each(|(o, l)| o.copy_from_slice(&l[..3]));
        } else {
            out.par_chunks_exact_mut(3)
                .zip(self.pixels().par_iter())
                .for_each(|(o, p)| o.copy_from_slice(&p.to_array().map(linear_to_srgb8)));
        }
        out
    }

    pub fn save_png(&self, path: &std::path::Path) -> crate::Result<()> {
        image::save_buffer(path, &self.to_rgb8(), self.width, self.height, image::ColorType::Rgb8)
            .map_err(|e| crate::Error::io(path, std::io::Error::other(e)))
    }

    /// Maps raw per-pixel traversal cost to a colour ramp, normalised by the image's maximum.
    pub fn heat_to_color(&self) -> Image {
        self.heat_to_color_scaled(self.heat_max())
    }

    /// The largest raw cost of a heat image (at least 1): what `heat_to_color` normalises by.
    pub fn heat_max(&self) -> f32 {
        self.pixels().iter().map(|p| p.x).fold(1.0f32, f32::max)
    }

    /// `heat_to_color` normalised by `max` instead of this image's own maximum: how the viewer
    /// colours a band of a frame before the whole frame's maximum is known.
    pub fn heat_to_color_scaled(&self, max: f32) -> Image {
        let max = max.max(1.0);
        let ramp = |v: f32| {
            // Black - blue - green - yellow - red - white, on a square-root scale so that low
            // costs remain distinguishable.
            let stops = [
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(0.05, 0.1, 0.6),
                Vec3::new(0.0, 0.6, 0.3),
                Vec3::new(0.95, 0.85, 0.1),
                Vec3::new(0.9, 0.15, 0.05),
                Vec3::new(1.0, 1.0, 1.0),
            ];
            let x = v.clamp(0.0, 1.0).sqrt() * (stops.len() - 1) as f32;
            let i = (x.floor() as usize).min(stops.len() - 2);
            stops[i].lerp(stops[i + 1], x - i as f32)
        };
        Image::from_pixels(
            self.width,
            self.height,
            self.pixels().iter().map(|p| ramp(p.x / max)).collect(),
        )
    }
}

/// Fraction of pixels (8-bit RGB, 3 bytes each) whose channels differ by more than `tol`
/// levels: the image tests' and the hardware suite's tolerance
/// measure.
pub fn differing_pixels(a: &[u8], b: &[u8], tol: u8) -> f64 {
    let n = a
        .chunks(3)
        .zip(b.chunks(3))
        .filter(|(p, q)| p.iter().zip(q.iter()).any(|(x, y)| x.abs_diff(*y) > tol))
        .count();
    n as f64 / (a.len() / 3).max(1) as f64
}

/// The linear value of the 8-bit sRGB level `v`: the level's own value, so that
/// `linear_to_srgb8(srgb8_to_linear(v)) == v` for every level (a test checks all 256: the
/// level's centre is half a level from either rounding boundary, far beyond float error).
pub fn srgb8_to_linear(v: u8) -> f32 {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|i| {
            let s = i as f64 / 255.0;
            let c = if s <= 0.040_45 {
                s / 12.92
            } else {
                ((s + 0.055) / 1.055).powf(2.4)
            };
            c as f32
        })
    })[v as usize]
}

pub fn linear_to_srgb8(c: f32) -> u8 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Per-render statistics.
#[derive(Debug, Default, Clone, Copy)]
pub struct RenderStats {
    pub rays: RayCounts,
    /// Filled only when counters were asked for (CPU) or in heat mode.
    pub counters: TraversalCounters,
    pub render_ms: f64,
}

impl RenderStats {
    pub fn mrays_per_s(&self) -> f64 {
        self.rays.total() as f64 / (self.render_ms * 1e3).max(1e-9)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every 8-bit level survives the trip to linear and back: what lets a GPU frame read back
    /// as `Srgb8` give the same PNG as its linear pixels.
    #[test]
    fn srgb8_levels_round_trip() {
        for v in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb8_to_linear(v)), v, "level {v}");
        }
        assert!((0..255u8).all(|v| srgb8_to_linear(v) < srgb8_to_linear(v + 1)));
    }
}
