//! Progressive frames: the viewer traces a frame in bands of rows, a few per pass of the event
//! loop within a time budget, so input is handled between bands however slow the frame is (a
//! huge mesh on a software adapter). When the last frame's pace says the whole frame will not
//! fit the budget, a coarse preview (one ray per block of pixels) is traced first, so something
//! of the new view shows at once; the full-resolution bands then replace it from the top.
//!
//! The bands of the full level are the same rows of the same frame (`RenderOptions::rows`), so
//! the finished image is the one `render` makes, bit for bit on the CPU.
//!
//! A frame traced on a GPU that presents (`restart` with `on_device`) leaves its full level's
//! bands in the presenter's device image (`Rendered::OnDevice`): they are not painted here, and
//! `texture_rows` tells the presenter which rows still come from the host's display (the
//! preview's). A band that comes back on the host instead (the GPU given up for the CPU) starts
//! the frame again on the host.

use std::ops::Range;
use std::time::{Duration, Instant};

use gridtrace::render::{RayCounts, linear_to_srgb8};
use gridtrace::{Image, Mode, RenderOptions, Rendered};

/// Traces a band (its options), into the device image when the flag says so and the tracer
/// can (`Tracer::render_to_device`), else on the host.
pub type TraceBand<'a> = dyn FnMut(&RenderOptions, bool) -> gridtrace::Result<Rendered> + 'a;

/// Pixels a side of the coarsest preview block.
const MAX_BLOCK: u32 = 16;
/// The preview takes at most this share of the budget (the rest starts the full level).
const PREVIEW_SHARE: f64 = 0.5;
/// The first band of a frame when nothing is known of the pace yet: small enough to come
/// back quickly even on a software adapter.
const FIRST_BAND_PIXELS: u64 = 16 * 1024;

/// What one finished frame took: the full-resolution level's bands, summed.
#[derive(Debug, Clone, Default)]
pub struct FrameSummary {
    /// Wall time of the full level's bands (tracing plus read-back).
    pub ms: f64,
    /// Wall time from the start of the frame to its last band, preview included.
    pub total_ms: f64,
    pub rays: RayCounts,
    /// GPU stage times summed over the bands (empty on the CPU).
    pub stages_ms: Vec<(&'static str, f64)>,
    pub from_timestamps: bool,
    /// Bytes written to the device for the frame, all bands (camera, lights, pass uniforms).
    pub uploaded_bytes: u64,
    /// Bands the full level took.
    pub bands: u32,
    /// Bytes read back for the full level (GPU): counters and timestamps, and the image unless
    /// it stayed on the device.
    pub downloaded_bytes: u64,
    /// The full level stayed on the device (the presenter drew it from there).
    pub on_device: bool,
}

pub struct Refiner {
    width: u32,
    height: u32,
    opts: RenderOptions,
    /// Block sizes still to trace, coarse to fine; the last is 1.
    levels: Vec<u32>,
    level: usize,
    /// The next row of the current level's image.
    next_row: u32,
    /// The frame on screen, RGBA8 (sRGB-encoded), `width` x `height`: finished rows of the full
    /// level, the preview's blocks below them.
    pub display: Vec<u8>,
    /// The full level's linear image, filled band by band (heat: raw costs); unused when the
    /// full level goes to the device image.
    full: Image,
    /// This frame's full level goes to the presenter's device image.
    on_device: bool,
    /// The display does not hold the last finished frame (that frame, or one since, went to
    /// the device image): a host frame after it shows only its own rows from the display.
    display_stale: bool,
    /// Largest raw cost seen in this frame (heat), to colour bands before the frame is done.
    heat_max: f32,
    /// Milliseconds per traced pixel, from the bands so far (kept across frames).
    ms_per_pixel: Option<f64>,
    started: Instant,
    summary: FrameSummary,
    /// The frame is finished; `summary` describes it.
    done: bool,
    /// `display` changed since `take_changed`.
    changed: bool,
}

impl Refiner {
    pub fn new() -> Refiner {
        Refiner {
            width: 0,
            height: 0,
            opts: RenderOptions::new(1, 1, Mode::Cast),
            levels: Vec::new(),
            level: 0,
            next_row: 0,
            display: Vec::new(),
            full: Image::new(0, 0),
            on_device: false,
            display_stale: false,
            heat_max: 1.0,
            ms_per_pixel: None,
            started: Instant::now(),
            summary: FrameSummary::default(),
            done: true,
            changed: false,
        }
    }

    /// Starts a new frame of `opts` (its size, mode and structure), its full level into the
    /// device image when `on_device`. A preview level is planned when the pace of the frames
    /// before says the whole frame would take over `budget`.
    pub fn restart(&mut self, opts: RenderOptions, budget: Duration, on_device: bool) {
        let (w, h) = (opts.width, opts.height);
        if (w, h) != (self.width, self.height) {
            self.display = vec![0; (w * h * 4) as usize];
            for px in self.display.chunks_exact_mut(4) {
                px[3] = 255;
            }
        }
        self.width = w;
        self.height = h;
        self.opts = RenderOptions { rows: None, ..opts };
        self.on_device = on_device;
        self.display_stale |= on_device;
        self.full = Image::new(if on_device { 0 } else { w }, if on_device { 0 } else { h });
        self.heat_max = 1.0;
        self.levels = vec![1];
        if let Some(pace) = self.ms_per_pixel {
            let budget_ms = budget.as_secs_f64() * 1e3;
            let full_ms = pace * (w as f64) * (h as f64);
            if full_ms > budget_ms {
                // The finest block whose preview fits its share of the budget (a block of b x b
                // pixels costs one ray's work).
                let mut b = 2;
                while b < MAX_BLOCK && full_ms / (b * b) as f64 > budget_ms * PREVIEW_SHARE {
                    b *= 2;
                }
                self.levels = vec![b, 1];
            }
        }
        self.level = 0;
        self.next_row = 0;
        self.started = Instant::now();
        self.summary = FrameSummary::default();
        self.done = false;
    }

    pub fn done(&self) -> bool {
        self.done
    }

    /// The finished frame's full image (heat: coloured), or `None` while it is being traced
    /// or when it is in the device image (`on_device`).
    pub fn image(&self) -> Option<Image> {
        (self.done && !self.on_device).then(|| {
            if self.opts.mode == Mode::Heat {
                self.full.heat_to_color()
            } else {
                self.full.clone()
            }
        })
    }

    /// The last finished frame's figures (valid once `done`).
    pub fn summary(&self) -> &FrameSummary {
        &self.summary
    }

    /// The options of the frame being traced (or last traced).
    pub fn opts(&self) -> &RenderOptions {
        &self.opts
    }

    /// Whether this frame's full level goes to (or went to) the device image.
    pub fn on_device(&self) -> bool {
        self.on_device
    }

    /// The rows of the frame the presenter draws from the host's display; the others from
    /// the device image. All of them for a frame made on the host; while a device frame is
    /// refined, the preview's rows (those it has traced) below the device's finished ones.
    ///
    /// A host frame after a device frame (heat, say) shows its own rows from the display and
    /// the rest from the device image, which holds the last frame, until it is done.
    pub fn texture_rows(&self) -> Range<u32> {
        if self.done {
            return if self.on_device { 0..0 } else { 0..u32::MAX };
        }
        if !self.on_device && !self.display_stale {
            return 0..u32::MAX;
        }
        let (h, next) = (self.height, self.next_row);
        let in_preview = self.level + 1 < self.levels.len();
        let previewed = self.levels.len() > 1;
        match (in_preview, previewed, self.on_device) {
            // The preview's rows traced so far.
            (true, _, _) => 0..(next * self.levels[self.level]).min(h),
            // The preview below the device's finished rows.
            (false, true, true) => next..h,
            // A host frame's finished rows above its preview: the display holds them all.
            (false, true, false) => 0..h,
            (false, false, true) => 0..0,
            (false, false, false) => 0..next,
        }
    }

    /// Whether the displayed image changed since the last call.
    pub fn take_changed(&mut self) -> bool {
        std::mem::take(&mut self.changed)
    }

    /// The share of the frame's full level traced, 0..=1.
    pub fn progress(&self) -> f64 {
        if self.done {
            return 1.0;
        }
        if self.level + 1 < self.levels.len() {
            return 0.0;
        }
        self.next_row as f64 / self.height.max(1) as f64
    }

    /// Traces bands with `trace` until `budget` is spent (at least one band, so every call
    /// makes progress) or the frame is finished.
    pub fn step(&mut self, budget: Duration, trace: &mut TraceBand) -> gridtrace::Result<()> {
        let t0 = Instant::now();
        while !self.done {
            let left_ms = (budget.saturating_sub(t0.elapsed())).as_secs_f64() * 1e3;
            self.band(left_ms, trace)?;
            if t0.elapsed() >= budget {
                break;
            }
        }
        Ok(())
    }

    /// Traces the rest of the frame, whatever it takes (a screenshot, a headless frame).
    pub fn finish(&mut self, trace: &mut TraceBand) -> gridtrace::Result<()> {
        while !self.done {
            self.band(f64::INFINITY, trace)?;
        }
        Ok(())
    }

    /// One band of the current level, sized to take about `left_ms` at the measured pace.
    fn band(&mut self, left_ms: f64, trace: &mut TraceBand) -> gridtrace::Result<()> {
        let block = self.levels[self.level];
        let (lw, lh) = (self.width.div_ceil(block), self.height.div_ceil(block));
        let rows_left = lh - self.next_row;
        let rows = match self.ms_per_pixel {
            _ if left_ms.is_infinite() => rows_left,
            Some(pace) if pace > 0.0 => (left_ms / (pace * lw as f64)).floor() as u32,
            _ => (FIRST_BAND_PIXELS / lw as u64) as u32,
        }
        .clamp(1, rows_left);
        let first = self.next_row;
        let opts = RenderOptions {
            width: lw,
            height: lh,
            ..self.opts
        }
        .band(first, first + rows);
        let to_device = self.on_device && block == 1;
        let t0 = Instant::now();
        let traced = trace(&opts, to_device)?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        if to_device && matches!(traced, Rendered::OnHost(_)) {
            // The GPU was given up mid-frame: the rows it left on the device are not on the
            // host's display. The frame again, on the host from the top.
            let opts = self.opts;
            self.restart(opts, Duration::MAX, false);
            return Ok(());
        }
        let frame = match &traced {
            Rendered::OnHost(f) => Some(f),
            Rendered::OnDevice(_) => None,
        };
        // The pace: a running mean that follows a change of view within a few bands.
        let pace = ms / (lw as f64 * rows as f64);
        self.ms_per_pixel = Some(match self.ms_per_pixel {
            Some(p) => 0.5 * p + 0.5 * pace,
            None => pace,
        });
        if let Some(frame) = frame {
            self.paint(block, first, &frame.image);
        }
        if block == 1 {
            if let Some(frame) = frame {
                let at = (first * self.width) as usize;
                self.full.pixels_mut()[at..at + frame.image.pixels().len()].copy_from_slice(frame.image.pixels());
            }
            let s = &mut self.summary;
            s.ms += ms;
            s.rays += traced.stats().rays;
            s.bands += 1;
            s.on_device = to_device;
            if let Some(g) = traced.gpu() {
                s.uploaded_bytes += g.uploaded_bytes;
                s.downloaded_bytes += g.downloaded_bytes;
                s.from_timestamps = g.timings.from_timestamps;
                for (k, v) in &g.timings.stages_ms {
                    match s.stages_ms.iter_mut().find(|(n, _)| n == k) {
                        Some((_, t)) => *t += v,
                        None => s.stages_ms.push((k, *v)),
                    }
                }
            }
        }
        self.next_row += rows;
        if self.next_row == lh {
            self.level += 1;
            self.next_row = 0;
            if self.level == self.levels.len() {
                self.done = true;
                // A host frame's display holds it all now.
                self.display_stale &= self.on_device;
                self.summary.total_ms = self.started.elapsed().as_secs_f64() * 1e3;
                if self.opts.mode == Mode::Heat && !self.on_device {
                    // Colour the whole frame by its own maximum, as `render` does.
                    let img = self.full.heat_to_color();
                    self.paint(1, 0, &img);
                }
            }
        }
        Ok(())
    }

    /// Writes a band of a level's image (rows from `first`, blocks of `block` pixels) into the
    /// display.
    fn paint(&mut self, block: u32, first: u32, band: &Image) {
        let heat;
        let band = if self.opts.mode == Mode::Heat && !self.done {
            self.heat_max = self.heat_max.max(band.heat_max());
            heat = band.heat_to_color_scaled(self.heat_max);
            &heat
        } else {
            band
        };
        let (w, h) = (self.width, self.height);
        for by in 0..band.height {
            let y0 = (first + by) * block;
            for y in y0..(y0 + block).min(h) {
                for x in 0..w {
                    let p = band.pixels()[(by * band.width + x / block) as usize];
                    let i = ((y * w + x) * 4) as usize;
                    self.display[i] = linear_to_srgb8(p.x);
                    self.display[i + 1] = linear_to_srgb8(p.y);
                    self.display[i + 2] = linear_to_srgb8(p.z);
                }
            }
        }
        self.changed = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gridtrace::gpu::GpuRenderStats;
    use gridtrace::scene::builtin;
    use gridtrace::{Frame, Resolution};

    /// Whatever the budget, bands and previews, the finished frame is `render`'s image bit for
    /// bit (CPU), and the display shows it; heat frames are coloured by the whole frame's
    /// maximum as `render` colours them.
    #[test]
    fn refined_frames_equal_render() {
        let scene = builtin::scene("mirror-spheres")
            .unwrap()
            .prepare(Resolution::default())
            .unwrap();
        let mut trace = |o: &RenderOptions, _: bool| -> gridtrace::Result<Rendered> {
            let (image, stats) = gridtrace::cpu::render_view(&scene, &scene.camera, &scene.lights, o, None)?;
            Ok(Rendered::OnHost(Frame {
                image,
                stats,
                gpu: None,
            }))
        };
        let mut r = Refiner::new();
        // The first frame (a long budget) measures the pace; the later ones, on a budget of
        // nothing or next to nothing, go band by band after a preview.
        for (mode, budget_us) in [
            (Mode::Cast, 1_000_000),
            (Mode::Shadow, 0),
            (Mode::Trace, 50),
            (Mode::Heat, 0),
        ] {
            let opts = RenderOptions::new(61, 47, mode);
            r.restart(opts, Duration::from_micros(budget_us), false);
            let mut steps = 0;
            while !r.done() {
                r.step(Duration::from_micros(budget_us), &mut trace).unwrap();
                steps += 1;
                assert!(steps < 10_000);
            }
            let (want, stats) = gridtrace::cpu::render(&scene, &opts, None).unwrap();
            let want = if mode == Mode::Heat { want.heat_to_color() } else { want };
            let got = r.image().unwrap();
            assert!(got == want, "{} differs from render", mode.name());
            let rgba: Vec<u8> = want.to_rgb8().chunks(3).flat_map(|c| [c[0], c[1], c[2], 255]).collect();
            assert!(r.display == rgba, "{}: the display is not the frame", mode.name());
            assert_eq!(r.summary().rays, stats.rays);
            if budget_us == 0 {
                // A zero budget traces one band a step: the frame took several.
                assert!(steps > 1, "{}", mode.name());
            }
        }
        // The pace is known now: a zero budget plans a preview before the full level.
        r.restart(RenderOptions::new(61, 47, Mode::Shadow), Duration::ZERO, false);
        assert_eq!(r.levels.len(), 2);
        r.step(Duration::ZERO, &mut trace).unwrap();
        assert_eq!(r.progress(), 0.0, "the preview's band comes first");
        r.finish(&mut trace).unwrap();
        assert!(r.done() && r.progress() == 1.0);
    }

    /// A frame whose full level goes to the device: its bands are not painted (the preview's
    /// are), `texture_rows` gives the presenter the preview's traced rows, then those below the
    /// device's finished ones, then none; the device (a CPU image stands in for it) holds
    /// `render`'s frame and the summary its rays and readback. A band that comes back on the
    /// host mid-frame (the GPU given up) starts the frame again on the host, which then equals
    /// `render` and shows every row from the display.
    #[test]
    fn device_frames_leave_the_display_to_the_preview() {
        let scene = builtin::scene("knot-box")
            .unwrap()
            .prepare(Resolution::default())
            .unwrap();
        let (w, h) = (61, 47);
        let opts = RenderOptions::new(w, h, Mode::Shadow);
        let (want, want_stats) = gridtrace::cpu::render(&scene, &opts, None).unwrap();
        let want_rgba: Vec<u8> = want.to_rgb8().chunks(3).flat_map(|c| [c[0], c[1], c[2], 255]).collect();
        let cpu = |o: &RenderOptions| gridtrace::cpu::render_view(&scene, &scene.camera, &scene.lights, o, None);
        let mut device = Image::new(w, h);
        let mut trace = |o: &RenderOptions, on_device: bool| -> gridtrace::Result<Rendered> {
            let (image, stats) = cpu(o)?;
            if on_device {
                let at = (o.row_range().start * w) as usize;
                device.pixels_mut()[at..at + image.pixels().len()].copy_from_slice(image.pixels());
                return Ok(Rendered::OnDevice(GpuRenderStats {
                    render: stats,
                    downloaded_bytes: 64,
                    ..Default::default()
                }));
            }
            Ok(Rendered::OnHost(Frame {
                image,
                stats,
                gpu: None,
            }))
        };
        let mut r = Refiner::new();
        // A host frame first, to measure the pace; then on a zero budget a preview comes
        // before the device's bands.
        r.restart(opts, Duration::from_secs(100), false);
        r.finish(&mut trace).unwrap();
        assert_eq!(r.texture_rows(), 0..u32::MAX);
        r.restart(opts, Duration::ZERO, true);
        assert_eq!(r.levels.len(), 2, "a preview is planned");
        let block = r.levels[0];
        let mut saw_split = false;
        while !r.done() {
            r.step(Duration::ZERO, &mut trace).unwrap();
            let rows = r.texture_rows();
            if r.done() {
                assert_eq!(rows, 0..0);
            } else if r.level == 0 {
                assert_eq!(rows, 0..(r.next_row * block).min(h));
            } else {
                assert_eq!(rows, r.next_row..h);
                saw_split |= r.next_row > 0;
            }
        }
        assert!(saw_split, "the device's rows and the preview's shared the screen");
        let s = r.summary().clone();
        assert!(s.on_device && s.bands > 1);
        assert_eq!(s.rays, want_stats.rays);
        assert_eq!(s.downloaded_bytes, 64 * s.bands as u64);
        assert!(r.image().is_none(), "the frame is in the device image");
        assert!(r.display != want_rgba, "the display holds the preview, not the frame");
        assert!(device.pixels() == want.pixels(), "the device image is not the frame");
        // A host frame next (heat, say): its own rows come from the display, the rest from the
        // device image (the last frame), until it is done; the one after shows all from the
        // display.
        let mut host_only = |o: &RenderOptions, _: bool| -> gridtrace::Result<Rendered> {
            let (image, stats) = cpu(o)?;
            Ok(Rendered::OnHost(Frame {
                image,
                stats,
                gpu: None,
            }))
        };
        let heat = RenderOptions::new(w, h, Mode::Heat);
        for (k, want_stale) in [(0, true), (1, false)] {
            r.restart(heat, Duration::from_secs(100), false);
            assert_eq!(r.levels, [1], "frame {k}");
            while !r.done() {
                let rows = r.texture_rows();
                if want_stale {
                    assert_eq!(rows, 0..r.next_row, "frame {k}");
                } else {
                    assert_eq!(rows, 0..u32::MAX, "frame {k}");
                }
                r.step(Duration::ZERO, &mut host_only).unwrap();
            }
            assert_eq!(r.texture_rows(), 0..u32::MAX);
        }
        // The GPU given up mid-frame: the frame again on the host.
        let mut device = Image::new(w, h);
        let mut bands = 0;
        let mut trace = |o: &RenderOptions, on_device: bool| -> gridtrace::Result<Rendered> {
            let (image, stats) = cpu(o)?;
            bands += 1;
            if on_device && bands < 3 {
                let at = (o.row_range().start * w) as usize;
                device.pixels_mut()[at..at + image.pixels().len()].copy_from_slice(image.pixels());
                return Ok(Rendered::OnDevice(GpuRenderStats {
                    render: stats,
                    ..Default::default()
                }));
            }
            Ok(Rendered::OnHost(Frame {
                image,
                stats,
                gpu: None,
            }))
        };
        r.restart(opts, Duration::from_secs(100), true);
        assert_eq!(r.levels, [1]);
        while !r.done() {
            r.step(Duration::ZERO, &mut trace).unwrap();
        }
        assert!(!r.on_device());
        assert_eq!(r.texture_rows(), 0..u32::MAX);
        assert!(r.image().unwrap() == want, "the host's frame after the GPU");
        assert!(r.display == want_rgba);
        assert_eq!(
            r.summary().rays,
            want_stats.rays,
            "rays of the abandoned bands not counted"
        );
    }
}
