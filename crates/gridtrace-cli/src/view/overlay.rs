//! The viewer's overlay (egui): where it traces, how fast (frame time, rays per second by kind,
//! GPU time per stage from timestamp queries), what it traces (triangles, the structure, its
//! memory beside the paper's model), the bytes sent per frame, a frame-time graph, the light
//! gizmos and the controls. Its text is built once, as lines (`lines`), for the window and for
//! `overlay FILE` in scripts, so tests read exactly what a person sees.

use std::collections::VecDeque;

use egui::{Align2, Color32, FontId, RichText, Stroke, pos2, vec2};

use super::progressive::FrameSummary;
use crate::common::fmt_bytes;

/// Frames the graph shows.
pub const HISTORY: usize = 120;
/// Points of width per frame in the graph.
const GRAPH_STEP_PT: f32 = 2.0;

/// Everything the overlay shows, gathered by the app each pass.
pub struct Hud {
    /// Where frames are traced ("gpu: ..." or "cpu (N threads)"), and a note when that is not
    /// what was asked for.
    pub tracer: String,
    pub notes: Vec<String>,
    /// The adapter putting frames on the window.
    pub presenter: String,
    pub scene: String,
    pub triangles: usize,
    pub structure: String,
    /// The structure's arrays in bytes, and the paper's model for a grid.
    pub memory_bytes: usize,
    pub paper_model_bytes: Option<usize>,
    pub mode: &'static str,
    pub accel: &'static str,
    /// Traced image size (physical pixels) and the resolution scale.
    pub traced: (u32, u32),
    pub scale: f32,
    pub pixels_per_point: f32,
    /// The last finished frame.
    pub last: Option<FrameSummary>,
    /// Share of the frame being refined (1: finished).
    pub progress: f64,
    /// Lights: position, and which one is selected.
    pub lights: Vec<glam::Vec3>,
    pub selected_light: usize,
    pub fly_speed: f32,
    /// A file being loaded, in words.
    pub loading: Option<String>,
    /// The last failed drop's error.
    pub error: Option<String>,
    /// An animated scene: time, playing, its last update.
    pub animation: Option<String>,
}

/// The controls, as the overlay lists them.
pub const CONTROLS: &[(&str, &str)] = &[
    ("drag", "orbit (drag a light's circle to move it)"),
    ("right drag", "pan"),
    ("wheel", "zoom"),
    ("W A S D Q E", "fly (shift: x5)"),
    ("- / =", "fly slower / faster"),
    ("F", "frame the scene"),
    ("1 2 3 4", "cast, shadow, trace, heat"),
    ("G", "next structure"),
    ("L", "next light"),
    ("arrows, PgUp/PgDn", "move the light"),
    ("[ / ]", "resolution scale down / up"),
    ("space", "play / pause (animated scenes)"),
    ("P", "screenshot"),
    ("H", "hide / show this overlay"),
    ("drop a file", "load a mesh or scene"),
    ("Esc", "quit"),
];

impl Hud {
    /// The overlay's text, line by line.
    pub fn lines(&self) -> Vec<String> {
        let mut l = vec![
            format!("tracer    {}", self.tracer),
            format!("present   {}", self.presenter),
        ];
        l.extend(self.notes.iter().map(|n| format!("note      {n}")));
        l.push(format!("scene     {}: {} triangles", self.scene, self.triangles));
        l.push(format!("structure {}", self.structure));
        let mut mem = format!("memory    {}", fmt_bytes(self.memory_bytes));
        if let Some(m) = self.paper_model_bytes {
            mem += &format!(" (paper's model {})", fmt_bytes(m));
        }
        l.push(mem);
        l.push(format!(
            "view      {} {}, {}x{} traced, scale 1/{}, {:.2} px/pt",
            self.mode,
            self.accel,
            self.traced.0,
            self.traced.1,
            (1.0 / self.scale).round(),
            self.pixels_per_point
        ));
        if let Some(s) = &self.last {
            let r = s.rays;
            l.push(format!(
                "frame     {:.1} ms, {:.2} Mrays/s, {} band{}",
                s.ms,
                r.total() as f64 / (s.ms * 1e3).max(1e-9),
                s.bands,
                if s.bands == 1 { "" } else { "s" },
            ));
            if s.total_ms > s.ms * 1.05 + 1.0 {
                // Bands spread over several presented frames, or a preview came first.
                l.push(format!("          {:.1} ms from the change of view", s.total_ms));
            }
            l.push(format!(
                "rays      eye {}, shadow {}, reflection {}",
                r.eye, r.shadow, r.reflection
            ));
            // Rays per second by kind, from the stage that traces them, where there are GPU
            // timestamps (as `render` reports them).
            let stage = |n: &str| s.stages_ms.iter().find(|(k, _)| *k == n).map(|(_, v)| *v);
            if s.from_timestamps {
                let mut rates = Vec::new();
                if let Some(ms) = stage("traverse").filter(|v| *v > 0.0) {
                    rates.push(format!(
                        "eye+reflection {:.1} Mrays/s",
                        (r.eye + r.reflection) as f64 / (ms * 1e3)
                    ));
                }
                if let Some(ms) = stage("occlusion").filter(|v| *v > 0.0) {
                    rates.push(format!("shadow {:.1} Mrays/s", r.shadow as f64 / (ms * 1e3)));
                }
                if !rates.is_empty() {
                    l.push(format!("rates     {}", rates.join(", ")));
                }
                let stages: Vec<String> = ["raygen", "traverse", "shade", "occlusion", "resolve"]
                    .iter()
                    .filter_map(|n| stage(n).map(|v| format!("{n} {v:.2}")))
                    .collect();
                l.push(format!("gpu ms    {} (timestamps)", stages.join(", ")));
            } else if !s.stages_ms.is_empty() {
                l.push("gpu ms    no timestamp queries on this adapter".into());
            }
            if s.uploaded_bytes > 0 {
                l.push(format!(
                    "uploaded  {} B this frame (camera, lights, pass uniforms)",
                    s.uploaded_bytes
                ));
            }
            if s.downloaded_bytes > 0 {
                l.push(format!(
                    "readback  {} B this frame ({})",
                    s.downloaded_bytes,
                    if s.on_device {
                        "counters, timestamps: the image stayed on the GPU"
                    } else {
                        "the image, counters, timestamps"
                    }
                ));
            }
        }
        if self.progress < 1.0 {
            l.push(format!("refining  {:.0}%", self.progress * 100.0));
        }
        for (i, p) in self.lights.iter().enumerate() {
            l.push(format!(
                "light {}{}  {:.3},{:.3},{:.3}",
                i + 1,
                if i == self.selected_light { "*" } else { " " },
                p.x,
                p.y,
                p.z
            ));
        }
        l.push(format!("fly speed x{}", self.fly_speed));
        if let Some(a) = &self.animation {
            l.push(format!("animation {a}"));
        }
        if let Some(s) = &self.loading {
            l.push(format!("loading   {s}"));
        }
        if let Some(e) = &self.error {
            l.push(format!("error     {e}"));
        }
        l
    }

    /// Draws the overlay: a panel with the lines, the frame-time graph and the controls; the
    /// light gizmos (`gizmos`: window pixel positions) over the image.
    pub fn show(&self, ctx: &egui::Context, history: &VecDeque<f64>, gizmos: &[Option<(f32, f32)>]) {
        let ppp = ctx.pixels_per_point();
        let painter = ctx.layer_painter(egui::LayerId::background());
        for (i, g) in gizmos.iter().enumerate() {
            if let Some((x, y)) = g {
                let at = pos2(x / ppp, y / ppp);
                let selected = i == self.selected_light;
                let colour = if selected { Color32::YELLOW } else { Color32::WHITE };
                painter.circle_stroke(at, GIZMO_RADIUS_PT, Stroke::new(2.0, colour));
                painter.circle_filled(at, 2.0, colour);
                painter.text(
                    at + vec2(GIZMO_RADIUS_PT + 2.0, -GIZMO_RADIUS_PT),
                    Align2::LEFT_BOTTOM,
                    format!("L{}", i + 1),
                    FontId::monospace(12.0),
                    colour,
                );
            }
        }
        egui::Window::new("gridtrace")
            .default_pos(pos2(8.0, 8.0))
            .default_width(460.0)
            .resizable(false)
            .frame(egui::Frame::window(&ctx.global_style()).fill(Color32::from_black_alpha(190)))
            .show(ctx, |ui| {
                for line in self.lines() {
                    let colour = if line.starts_with("error") {
                        Color32::from_rgb(255, 110, 90)
                    } else if line.starts_with("note") || line.starts_with("loading") {
                        Color32::from_rgb(255, 210, 90)
                    } else {
                        Color32::from_gray(225)
                    };
                    ui.label(RichText::new(line).monospace().size(12.0).color(colour));
                }
                graph(ui, history);
                ui.collapsing("controls", |ui| {
                    egui::Grid::new("controls").show(ui, |ui| {
                        for (k, what) in CONTROLS {
                            ui.label(RichText::new(*k).monospace().size(12.0));
                            ui.label(RichText::new(*what).size(12.0));
                            ui.end_row();
                        }
                    });
                });
            });
    }
}

/// A light's gizmo: a circle of this radius (points); a press within it drags the light.
pub const GIZMO_RADIUS_PT: f32 = 9.0;

/// The last frames' times, newest on the right, with the slowest's figure and a 60 fps mark
/// when it is in range.
fn graph(ui: &mut egui::Ui, history: &VecDeque<f64>) {
    let width = HISTORY as f32 * GRAPH_STEP_PT;
    let (rect, _) = ui.allocate_exact_size(vec2(width, 60.0), egui::Sense::hover());
    let p = ui.painter_at(rect);
    p.rect_filled(rect, 2.0, Color32::from_black_alpha(120));
    let max = history.iter().copied().fold(1.0f64, f64::max) * 1.1;
    let y = |ms: f64| rect.bottom() - (ms / max) as f32 * rect.height();
    if 1000.0 / 60.0 < max {
        let at = y(1000.0 / 60.0);
        p.line_segment(
            [pos2(rect.left(), at), pos2(rect.right(), at)],
            Stroke::new(1.0, Color32::from_rgb(80, 160, 80)),
        );
    }
    let first_x = rect.right() - (history.len().max(1) - 1) as f32 * GRAPH_STEP_PT;
    let pts: Vec<egui::Pos2> = history
        .iter()
        .enumerate()
        .map(|(i, ms)| pos2(first_x + i as f32 * GRAPH_STEP_PT, y(*ms)))
        .collect();
    let colour = Color32::from_rgb(120, 190, 255);
    if pts.len() > 1 {
        p.add(egui::Shape::line(pts.clone(), Stroke::new(1.5, colour)));
    }
    if pts.len() < 30 {
        // Few frames: points, so each one shows.
        for q in &pts {
            p.circle_filled(*q, 2.0, colour);
        }
    }
    p.text(
        rect.left_bottom() + vec2(4.0, -2.0),
        Align2::LEFT_BOTTOM,
        format!(
            "frame ms: last {:.1}, max {:.1}",
            history.back().copied().unwrap_or(0.0),
            history.iter().copied().fold(0.0f64, f64::max)
        ),
        FontId::monospace(11.0),
        Color32::from_gray(200),
    );
}
