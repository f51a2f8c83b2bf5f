//! One pass of the viewer: trace within the budget, build the overlay, present; and whether
//! another pass is wanted without input.

use super::*;

impl App {
    /// Traces within the budget (all of the frame with `finish`), and puts what changed into
    /// the image texture.
    pub(super) fn trace(&mut self, finish: bool) -> gridtrace::Result<()> {
        let (w, h) = self.size;
        if w == 0 || h == 0 {
            // Minimised: nothing to trace until the window has an area again (`resized`).
            return Ok(());
        }
        if self.dirty {
            // The frame stays on the GPU where the tracer is on it and the presenter draws with
            // its device; heat frames are coloured on the host by their whole frame's maximum,
            // and a frame larger than one storage binding (8192x8192 on lavapipe) is read back
            // in tiles, as `render` does.
            let i = self.open_tracer()?;
            let opts = self.frame_opts();
            let on_device = self.mode != Mode::Heat
                && self.tracers[i].1.gpu().is_some()
                && self
                    .presenter
                    .as_mut()
                    .is_some_and(|p| p.frame_target((opts.width, opts.height)).is_ok_and(|t| t.is_some()));
            self.refiner.restart(opts, self.budget, on_device);
            self.dirty = false;
        }
        if !self.refiner.done() {
            let camera = self.orbit.camera();
            let budget = self.budget;
            let i = self.open_tracer()?;
            let lights = &self.lights;
            let tracer = &mut self.tracers[i].1;
            let o = self.refiner.opts();
            let target = match &mut self.presenter {
                Some(p) if self.refiner.on_device() => p.frame_target((o.width, o.height))?,
                _ => None,
            };
            let mut trace = |o: &RenderOptions, on_device: bool| match target {
                Some(t) if on_device => tracer.render_to_device(&camera, lights, o, t),
                _ => tracer.render(&camera, lights, o).map(Rendered::OnHost),
            };
            if finish {
                self.refiner.finish(&mut trace)?;
            } else {
                self.refiner.step(budget, &mut trace)?;
            }
            // A GPU given up for the CPU says so in the overlay's notes.
            self.notes.extend(tracer.take_notes());
            if self.refiner.done() {
                if self.history.len() == HISTORY {
                    self.history.pop_front();
                }
                self.history.push_back(self.refiner.summary().ms);
                self.last = Some(self.refiner.summary().clone());
                self.set_title();
            }
        }
        if let Some(p) = &mut self.presenter {
            let o = *self.refiner.opts();
            if self.refiner.take_changed() {
                p.upload(&self.refiner.display, (o.width, o.height));
            }
            p.set_texture_rows(self.refiner.texture_rows(), (o.width, o.height));
        }
        Ok(())
    }

    pub(super) fn set_title(&self) {
        let (Some(win), Some(s)) = (&self.window, &self.last) else {
            return;
        };
        let tracer = self.current_tracer().map_or(String::new(), |t| t.describe());
        let up = if s.uploaded_bytes > 0 {
            format!(", {} B uploaded", s.uploaded_bytes)
        } else {
            String::new()
        };
        win.set_title(&format!(
            "gridtrace: {} - {} {} - {:.1} ms{up} - {tracer}",
            self.name,
            self.mode.name(),
            self.accel.name(),
            s.ms
        ));
    }

    /// Window pixel positions of the lights' gizmos (`None`: behind the camera).
    pub(super) fn gizmos(&self) -> Vec<Option<(f32, f32)>> {
        let c = self.orbit.camera();
        let size = (self.size.0.max(1) as f32, self.size.1.max(1) as f32);
        self.lights
            .iter()
            .map(|l| project(&c, size, Vec3::from(l.position)).map(|(x, y, _)| (x, y)))
            .collect()
    }

    pub(super) fn hud(&self) -> Hud {
        let t = self.current_tracer();
        let (triangles, structure, memory_bytes, paper_model_bytes) = match t {
            Some(t) => (
                t.scene.accel.tris.len(),
                crate::common::describe_structure(&t.scene.accel),
                t.scene.memory().iter().map(|(_, b)| b).sum(),
                t.scene.paper_memory_model(),
            ),
            None => (0, "(not prepared)".into(), 0, None),
        };
        Hud {
            tracer: t.map_or("(none yet)".into(), |t| t.short()),
            notes: self.notes.clone(),
            presenter: self.presenter.as_ref().map_or(String::new(), |p| p.adapter.clone()),
            scene: std::path::Path::new(&self.name)
                .file_name()
                .map_or(self.name.clone(), |f| f.to_string_lossy().into_owned()),
            triangles,
            structure,
            memory_bytes,
            paper_model_bytes,
            mode: self.mode.name(),
            accel: self.accel.name(),
            traced: self.traced_size(),
            scale: self.scale(),
            pixels_per_point: self.egui_ctx.pixels_per_point(),
            last: self.last.clone(),
            progress: self.refiner.progress(),
            lights: self.lights.iter().map(|l| Vec3::from(l.position)).collect(),
            selected_light: self.selected_light,
            fly_speed: self.fly_speed,
            loading: self.loader.as_ref().map(|l| l.describe()),
            error: self.drop_error.clone(),
            animation: self.anim.as_ref().map(|p| {
                format!(
                    "t = {:.2} s, {}{}",
                    p.time,
                    if p.playing { "playing" } else { "paused" },
                    p.last_update.as_ref().map_or(String::new(), |u| format!("; {u}"))
                )
            }),
        }
    }

    /// Runs egui for this pass: the overlay's shapes, ready to draw.
    pub(super) fn overlay(&mut self) -> Option<present::Overlay> {
        let window = self.window.clone()?;
        let hud = self.hud();
        let gizmos = self.gizmos();
        let show = self.show_overlay;
        let state = self.egui.as_mut()?;
        let input = state.take_egui_input(&window);
        let history = &self.history;
        let out = self.egui_ctx.run_pass(input, |ctx| {
            if show {
                hud.show(ctx, history, &gizmos);
            }
        });
        state.handle_platform_output(&window, out.platform_output);
        self.egui_repaint = out
            .viewport_output
            .get(&egui::ViewportId::ROOT)
            .is_some_and(|v| v.repaint_delay.is_zero());
        let ppp = out.pixels_per_point;
        Some(present::Overlay {
            primitives: self.egui_ctx.tessellate(out.shapes, ppp),
            textures: out.textures_delta,
            pixels_per_point: ppp,
        })
    }

    /// One pass: move an animation on (`tick`) once the frame before is done, trace within
    /// the budget, draw the overlay, present.
    pub(super) fn redraw(&mut self, tick: bool) -> gridtrace::Result<()> {
        if tick && self.refiner.done() && !self.dirty {
            self.tick_animation();
        }
        self.trace(false)?;
        self.present()
    }

    /// Draws the overlay and presents; a frame the surface could not take is asked for again.
    pub(super) fn present(&mut self) -> gridtrace::Result<()> {
        let overlay = self.overlay();
        if let (Some(p), Some(o)) = (&mut self.presenter, overlay)
            && !p.present(o)?
            && let Some(w) = &self.window
        {
            w.request_redraw();
        }
        Ok(())
    }

    /// Whether more passes are wanted without input: a frame being refined, a file loading,
    /// an animation playing.
    pub(super) fn busy(&self) -> bool {
        if self.size.0 == 0 || self.size.1 == 0 {
            // Minimised: nothing to draw until the window has an area again.
            return false;
        }
        self.dirty
            || !self.refiner.done()
            || self.loader.is_some()
            || self.egui_repaint
            || self.anim.as_ref().is_some_and(|p| p.playing)
    }
}
