//! PNG charts of a benchmark report, drawn with `plotters` into a pixel buffer (the font is the
//! DejaVu Sans that the `dejavu` crate embeds: no system fonts needed) and saved with `image`.

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::prelude::*;

use super::BenchReport;
use gridtrace::{Error, Result};

const SIZE: (u32, u32) = (960, 640);

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid; if registration ever failed, text would be missing, not
        // the chart.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

/// One line of a chart.
#[derive(Debug, Clone)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Drawn thin with small markers (reference data such as the paper's figures).
    pub reference: bool,
}

/// A line chart; log axes plot log10 of the values and label ticks with the values.
pub struct LineChart<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub log_x: bool,
    pub log_y: bool,
    pub series: Vec<Series>,
}

fn chart_err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::io(path, std::io::Error::other(format!("drawing chart: {e}")))
}

impl LineChart<'_> {
    pub fn save(&self, path: &Path) -> Result<()> {
        register_font();
        let tx = |v: f64| if self.log_x { v.max(1e-12).log10() } else { v };
        let ty = |v: f64| if self.log_y { v.max(1e-12).log10() } else { v };
        let pts: Vec<Vec<(f64, f64)>> = self
            .series
            .iter()
            .map(|s| {
                s.points
                    .iter()
                    .filter(|(x, y)| {
                        x.is_finite() && y.is_finite() && (!self.log_x || *x > 0.0) && (!self.log_y || *y > 0.0)
                    })
                    .map(|&(x, y)| (tx(x), ty(y)))
                    .collect()
            })
            .collect();
        let all: Vec<&(f64, f64)> = pts.iter().flatten().collect();
        let range = |f: &dyn Fn(&(f64, f64)) -> f64, log: bool| {
            let lo = all.iter().map(|p| f(p)).fold(f64::INFINITY, f64::min);
            let hi = all.iter().map(|p| f(p)).fold(f64::NEG_INFINITY, f64::max);
            if !lo.is_finite() {
                return 0.0..1.0;
            }
            let span = if hi > lo { hi - lo } else { hi.abs().max(1.0) * 0.2 };
            let pad = span * 0.08;
            // Linear axes of non-negative data start at zero.
            let low = if !log && lo >= 0.0 { 0.0 } else { lo - pad };
            low..hi + pad
        };
        let xr = range(&|p| p.0, self.log_x);
        let yr = range(&|p| p.1, self.log_y);

        let mut buf = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
            root.fill(&WHITE).map_err(|e| chart_err(path, e))?;
            let mut chart = ChartBuilder::on(&root)
                .caption(self.title, ("sans-serif", 22))
                .margin(16)
                .x_label_area_size(48)
                .y_label_area_size(72)
                .build_cartesian_2d(xr, yr)
                .map_err(|e| chart_err(path, e))?;
            let fmt = |log: bool| {
                move |v: &f64| {
                    let x = if log { 10f64.powf(*v) } else { *v };
                    if x.abs() >= 1e5 {
                        format!("{x:.1e}")
                    } else if x.abs() >= 10.0 || x == 0.0 {
                        format!("{x:.0}")
                    } else if x.abs() >= 1.0 {
                        format!("{x:.1}")
                    } else {
                        format!("{x:.3}")
                    }
                }
            };
            let (fx, fy) = (fmt(self.log_x), fmt(self.log_y));
            chart
                .configure_mesh()
                .x_desc(self.x_label)
                .y_desc(self.y_label)
                .x_label_formatter(&fx)
                .y_label_formatter(&fy)
                .label_style(("sans-serif", 14))
                .axis_desc_style(("sans-serif", 16))
                .draw()
                .map_err(|e| chart_err(path, e))?;
            for (i, (s, p)) in self.series.iter().zip(&pts).enumerate() {
                let color = Palette99::pick(i).to_rgba();
                let style = if s.reference {
                    color.stroke_width(1)
                } else {
                    color.stroke_width(2)
                };
                chart
                    .draw_series(LineSeries::new(p.clone(), style).point_size(if s.reference { 2 } else { 4 }))
                    .map_err(|e| chart_err(path, e))?
                    .label(s.name.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 13))
                .position(SeriesLabelPosition::UpperLeft)
                .draw()
                .map_err(|e| chart_err(path, e))?;
            root.present().map_err(|e| chart_err(path, e))?;
        }
        image::save_buffer(path, &buf, SIZE.0, SIZE.1, image::ColorType::Rgb8)
            .map_err(|e| Error::io(path, std::io::Error::other(e)))
    }
}

/// Draws every chart the report has data for into `dir`; returns the files written.
pub fn write_charts(report: &BenchReport, dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    time_vs_resolution(report, dir, &mut out)?;
    grid_sweep(report, dir, &mut out)?;
    build_scaling(report, dir, &mut out)?;
    for sc in &report.scaling {
        scaling(sc, dir, &mut out)?;
    }
    pc_study(report, dir, &mut out)?;
    Ok(out)
}

/// Time against resolution, one chart per scene.
fn time_vs_resolution(report: &BenchReport, dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let rows = &report.matrix.rows;
    // Time against resolution, one chart per scene: each backend/mode/accel a line, the paper's
    // figures beside them.
    for s in &report.matrix.scenes {
        let mut series = Vec::new();
        let mut keys: Vec<(String, String, String)> = rows
            .iter()
            .filter(|r| r.scene == s.name)
            .map(|r| (r.backend.name().to_string(), r.mode.clone(), r.accel.clone()))
            .collect();
        keys.dedup();
        keys.sort();
        keys.dedup();
        for (b, m, a) in &keys {
            let sel: Vec<_> = rows
                .iter()
                .filter(|r| r.scene == s.name && r.backend.name() == b && &r.mode == m && &r.accel == a)
                .collect();
            series.push(Series {
                name: format!("{b} {m} {a}"),
                points: sel.iter().map(|r| (r.width as f64, r.summary.best_ms)).collect(),
                reference: false,
            });
            if b == "cpu" || !keys.iter().any(|k| k.0 == "cpu") {
                let paper: Vec<(f64, f64)> = sel
                    .iter()
                    .filter_map(|r| r.paper_ms.map(|p| (r.width as f64, p)))
                    .collect();
                if !paper.is_empty() {
                    series.push(Series {
                        name: format!("paper {m} {a}"),
                        points: paper,
                        reference: true,
                    });
                }
            }
        }
        if series.is_empty() {
            continue;
        }
        let path = dir.join(format!("time_vs_resolution_{}.png", s.name));
        LineChart {
            title: &format!("{}: best time vs resolution (grid vs pc)", s.title),
            x_label: "image width = height (pixels)",
            y_label: "ms (log)",
            log_x: false,
            log_y: true,
            series,
        }
        .save(&path)?;
        out.push(path);
    }
    Ok(())
}

/// Time against the grid's cells per triangle.
fn grid_sweep(report: &BenchReport, dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    if !report.grid_sweep.is_empty() {
        let series = report
            .grid_sweep
            .iter()
            .map(|sw| Series {
                name: format!("{} ({} {})", sw.scene, sw.mode, sw.accel),
                points: sw
                    .points
                    .iter()
                    .map(|p| (p.cells_per_triangle, p.summary.best_ms))
                    .collect(),
                reference: false,
            })
            .collect();
        let path = dir.join("grid_sweep.png");
        LineChart {
            title: "Grid resolution sweep: best time vs cells per triangle",
            x_label: "cells per triangle (log)",
            y_label: "ms (log)",
            log_x: true,
            log_y: true,
            series,
        }
        .save(&path)?;
        out.push(path);
    }
    Ok(())
}

/// Build time against triangle count, each builder a line.
fn build_scaling(report: &BenchReport, dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    if !report.build_scaling.is_empty() {
        let b = &report.build_scaling;
        let threads = b[0].cpu_threads;
        let mut series = vec![
            (
                "grid+pc, cpu 1 thread".to_string(),
                b.iter().map(|p| Some(p.cpu_1t_ms)).collect::<Vec<_>>(),
            ),
            (
                format!("grid+pc, cpu {threads} threads"),
                b.iter().map(|p| Some(p.cpu_ms)).collect(),
            ),
            ("grid+pc, gpu".to_string(), b.iter().map(|p| p.gpu_ms).collect()),
            (
                format!("bvh, cpu {threads} threads"),
                b.iter().map(|p| Some(p.bvh_ms)).collect(),
            ),
            ("embree bvh".to_string(), b.iter().map(|p| p.embree_ms).collect()),
        ];
        series.retain(|(_, v)| v.iter().any(Option::is_some));
        let path = dir.join("build_scaling.png");
        LineChart {
            title: "Build time vs triangle count",
            x_label: "triangles (log)",
            y_label: "ms (log)",
            log_x: true,
            log_y: true,
            series: series
                .into_iter()
                .map(|(name, v)| Series {
                    name,
                    points: b
                        .iter()
                        .zip(v)
                        .filter_map(|(p, ms)| ms.map(|ms| (p.triangles as f64, ms)))
                        .collect(),
                    reference: false,
                })
                .collect(),
        }
        .save(&path)?;
        out.push(path);
    }
    Ok(())
}

/// Time per ray against triangle count (with the fitted power law) and time against pixel
/// count, for one backend's scaling study.
fn scaling(sc: &crate::studies::Scaling, dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    // The CPU's charts keep their old names; the GPU's get a suffix.
    let suffix = if sc.backend == "cpu" {
        String::new()
    } else {
        format!("_{}", sc.backend)
    };
    let mut families: Vec<String> = sc.by_triangles.iter().map(|p| p.family.clone()).collect();
    families.dedup();
    let mut series: Vec<Series> = families
        .iter()
        .map(|f| Series {
            name: f.clone(),
            points: sc
                .by_triangles
                .iter()
                .filter(|p| &p.family == f)
                .map(|p| (p.triangles as f64, p.ns_per_ray))
                .collect(),
            reference: false,
        })
        .collect();
    if let Some(fit) = sc.fits.iter().find(|f| f.series == "ns/ray vs triangles: all") {
        let xs: Vec<f64> = sc.by_triangles.iter().map(|p| p.triangles as f64).collect();
        let (lo, hi) = (
            xs.iter().copied().fold(f64::INFINITY, f64::min),
            xs.iter().copied().fold(0.0, f64::max),
        );
        let f = |x: f64| (fit.intercept_ln + fit.exponent * x.ln()).exp();
        series.push(Series {
            name: format!("fit: n^{:.3}", fit.exponent),
            points: vec![(lo, f(lo)), (hi, f(hi))],
            reference: true,
        });
    }
    let path = dir.join(format!("scaling_triangles{suffix}.png"));
    LineChart {
        title: &format!(
            "Time per ray vs triangle count ({} {} {})",
            sc.backend, sc.mode, sc.accel
        ),
        x_label: "triangles (log)",
        y_label: "ns per ray (log)",
        log_x: true,
        log_y: true,
        series,
    }
    .save(&path)?;
    out.push(path);
    if !sc.by_pixels.is_empty() {
        let exp = sc.fits.iter().find(|f| f.series == "ms vs pixels").map(|f| f.exponent);
        let path = dir.join(format!("scaling_pixels{suffix}.png"));
        LineChart {
            title: &format!(
                "Time vs pixel count ({}){}",
                sc.by_pixels[0].mesh,
                exp.map_or(String::new(), |e| format!(", slope {e:.3}"))
            ),
            x_label: "pixels (log)",
            y_label: "ms (log)",
            log_x: true,
            log_y: true,
            series: vec![Series {
                name: format!("{} {}", sc.mode, sc.accel),
                points: sc
                    .by_pixels
                    .iter()
                    .map(|p| ((p.width * p.height) as f64, p.summary.best_ms))
                    .collect(),
                reference: false,
            }],
        }
        .save(&path)?;
        out.push(path);
    }
    Ok(())
}

/// Cells visited per ray for each study scene and mode, grid against pc.
fn pc_study(report: &BenchReport, dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    if !report.pc_study.is_empty() {
        // Cells visited per ray for each study scene and mode, grid vs pc.
        let mut series = Vec::new();
        for accel in ["grid", "pc"] {
            let pts: Vec<(f64, f64)> = report
                .pc_study
                .iter()
                .filter(|r| r.accel == accel)
                .enumerate()
                .map(|(i, r)| (i as f64 + 1.0, r.cells_per_ray))
                .collect();
            series.push(Series {
                name: format!("{accel}: cells per ray"),
                points: pts,
                reference: false,
            });
        }
        let path = dir.join("pc_study.png");
        LineChart {
            title: "Proximity clouds: cells visited per ray (x = study case, see bench.md)",
            x_label: "study case (scene/mode, in the order of the table)",
            y_label: "cells per ray",
            log_x: false,
            log_y: false,
            series,
        }
        .save(&path)?;
        out.push(path);
    }
    Ok(())
}
