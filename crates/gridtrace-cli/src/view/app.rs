//! What the viewer's state does: actions (from the window or a script), the tracer of each
//! structure, dropped files, the animation's clock.

use super::*;

impl App {
    /// Camera and lights from the scene (at start, and when a new file is loaded).
    pub(super) fn reset_view(&mut self) {
        self.orbit = Orbit::from_camera(&self.src.camera);
        self.lights = self.src.lights.clone();
        self.selected_light = 0;
    }

    /// The traced image's size: the window's, halved `scale_steps` times.
    pub(super) fn traced_size(&self) -> (u32, u32) {
        let (w, h) = self.size;
        let d = 1u32 << self.scale_steps;
        (w.div_ceil(d).min(MAX_SIDE), h.div_ceil(d).min(MAX_SIDE))
    }

    pub(super) fn scale(&self) -> f32 {
        1.0 / (1u32 << self.scale_steps) as f32
    }

    /// The index in `tracers` of the structure on screen's tracer, prepared and uploaded when
    /// first asked for, its vertices at the animation's time.
    pub(super) fn open_tracer(&mut self) -> gridtrace::Result<usize> {
        let structure = self.accel.structure_name();
        let i = match self.tracers.iter().position(|(s, _, _)| *s == structure) {
            Some(i) => i,
            None => {
                let t0 = Instant::now();
                let spec = self.accel_args.spec()?;
                let (tracer, _) = self
                    .placement
                    .open_scene(&self.src, self.accel, &spec, &mut self.notes)
                    .map_err(|e| crate::common::named(&self.name, e))?;
                eprintln!(
                    "{} prepared in {:.0} ms; tracing on {}",
                    structure,
                    t0.elapsed().as_secs_f64() * 1e3,
                    tracer.describe()
                );
                self.tracers.push((structure, tracer, 0.0));
                self.tracers.len() - 1
            }
        };
        let (_, tracer, at) = &mut self.tracers[i];
        if let Some(p) = &mut self.anim
            && *at != p.time
        {
            let u = tracer.update_vertices(&p.animation.positions_at(p.time))?;
            p.last_update = Some(format!(
                "geometry {:.1} ms, build {:.1} ms, {}",
                u.geometry_ms, u.build_ms, u.how
            ));
            *at = p.time;
        }
        // The grid's two traversals share one tracer: G switches between them in place.
        tracer.set_traversal(self.accel)?;
        Ok(i)
    }

    /// The tracer of the structure on screen, if it is open.
    pub(super) fn current_tracer(&self) -> Option<&Tracer> {
        let structure = self.accel.structure_name();
        self.tracers.iter().find(|(s, _, _)| *s == structure).map(|(_, t, _)| t)
    }

    /// The options of the frame for the current view.
    pub(super) fn frame_opts(&self) -> RenderOptions {
        let (w, h) = self.traced_size();
        RenderOptions::new(w, h, self.mode).with_pixels(PixelFormat::Srgb8)
    }

    pub(super) fn apply(&mut self, action: Action, el: &ActiveEventLoop) -> gridtrace::Result<()> {
        match action {
            Action::Orbit(dx, dy) => {
                self.orbit.drag(dx, dy);
                self.dirty = true;
            }
            Action::Pan(dx, dy) => {
                self.orbit.pan(dx, dy, self.size.1 as f32);
                self.dirty = true;
            }
            Action::Zoom(s) => {
                self.orbit.zoom(s);
                self.dirty = true;
            }
            Action::Fly(f, r, u) => {
                let k = self.fly_speed;
                self.orbit.fly(f * k, r * k, u * k);
                self.dirty = true;
            }
            Action::Frame => {
                let b = self.src.bounds();
                self.orbit.frame(b.min, b.max);
                self.dirty = true;
            }
            Action::SetMode(m) => {
                self.dirty |= m != self.mode;
                self.mode = m;
            }
            Action::NextAccel => {
                self.accel = next_accel(self.accel);
                self.dirty = true;
            }
            Action::Resize(w, h) => {
                if let Some(win) = &self.window {
                    let _ = win.request_inner_size(winit::dpi::PhysicalSize::new(w.max(1), h.max(1)));
                }
                self.resized(w, h);
            }
            Action::NextLight => {
                if !self.lights.is_empty() {
                    self.selected_light = (self.selected_light + 1) % self.lights.len();
                }
            }
            Action::DragLight(dx, dy) => {
                let c = self.orbit.camera();
                let size = (self.size.0.max(1) as f32, self.size.1.max(1) as f32);
                if let Some(l) = self.lights.get_mut(self.selected_light)
                    && let Some((x, y, z)) = project(&c, size, Vec3::from(l.position))
                {
                    l.position = unproject(&c, size, (x + dx, y + dy), z).to_array();
                    self.dirty = true;
                }
            }
            Action::MoveLight(f, r, u) => {
                let offset = self.orbit.view_offset(f, r, u) * self.fly_speed;
                if let Some(l) = self.lights.get_mut(self.selected_light) {
                    l.position = (Vec3::from(l.position) + offset).to_array();
                    self.dirty = true;
                }
            }
            Action::ScaleStep(d) => {
                let s = (self.scale_steps as i32 + d).clamp(0, MAX_SCALE_STEPS as i32) as u32;
                self.dirty |= s != self.scale_steps;
                self.scale_steps = s;
            }
            Action::SpeedStep(d) => {
                self.fly_speed = (self.fly_speed * 2f32.powi(d)).clamp(1.0 / 64.0, 64.0);
            }
            Action::ToggleOverlay => self.show_overlay = !self.show_overlay,
            Action::PlayPause => {
                if let Some(p) = &mut self.anim {
                    p.playing = !p.playing;
                    p.last_tick = Instant::now();
                }
            }
            Action::Drop(path) => {
                if let Some(l) = &self.loader {
                    // One load at a time: a worker thread cannot be stopped half way.
                    let e = format!(
                        "{}: still loading {}; drop it again when that is in",
                        path.display(),
                        l.path.display()
                    );
                    eprintln!("drop {e}");
                    self.drop_error = Some(e);
                } else {
                    println!("drop {}: loading", path.display());
                    self.drop_error = None;
                    self.loader = Some(loader::Loader::start(path, self.accel, self.accel_args.clone()));
                }
            }
            Action::Screenshot(path) => {
                self.trace(true)?;
                // A frame left on the device is read back from there (the only time it is).
                let image = match self.refiner.image() {
                    None if self.refiner.done() && self.refiner.on_device() => self
                        .presenter
                        .as_ref()
                        .and_then(|p| p.frame())
                        .map(|f| f.read())
                        .transpose()?,
                    image => image,
                };
                let Some(image) = image else {
                    return Err(gridtrace::Error::InvalidInput(
                        "screenshot: no frame yet (the window has no area)".into(),
                    ));
                };
                image.save_png(&path)?;
                let c = self.orbit.camera();
                let v = |v: Vec3| format!("{:?},{:?},{:?}", v.x, v.y, v.z);
                let lights: Vec<String> = self.lights.iter().map(light_arg).collect();
                println!(
                    "screenshot {} eye={} target={} up={} vfov={:?} lights={} mode={} accel={} res={}x{} ms={:.1}",
                    path.display(),
                    v(c.eye),
                    v(c.target),
                    v(c.up),
                    c.vfov_deg,
                    lights.join(";"),
                    self.mode.name(),
                    self.accel.name(),
                    image.width,
                    image.height,
                    self.last.as_ref().map_or(0.0, |s| s.ms)
                );
            }
            Action::Capture(path) => {
                self.trace(true)?;
                // egui sizes a window from the pass before: one pass on screen first.
                self.present()?;
                let overlay = self.overlay();
                if let (Some(p), Some(o)) = (&mut self.presenter, overlay) {
                    p.capture(o)?
                        .save(&path)
                        .map_err(|e| gridtrace::Error::io(&path, std::io::Error::other(e)))?;
                    println!("capture {}", path.display());
                }
            }
            Action::OverlayText(path) => {
                self.trace(true)?;
                let text = self.hud().lines().join("\n") + "\n";
                std::fs::write(&path, text).map_err(|e| gridtrace::Error::io(&path, e))?;
            }
            Action::Quit => el.exit(),
        }
        Ok(())
    }

    /// A finished load: the new scene replaces the old one; a failed one leaves it and says why.
    pub(super) fn loaded(&mut self, path: PathBuf, result: gridtrace::Result<loader::Loaded>) -> gridtrace::Result<()> {
        match result {
            Ok(l) => {
                let mut notes = Vec::new();
                let tracer = match Tracer::open(l.prepared, &self.placement, &mut notes) {
                    Ok(t) => t,
                    Err(e) => return self.loaded(path, Err(e)),
                };
                println!(
                    "drop {}: loaded {} triangles",
                    path.display(),
                    tracer.scene.accel.tris.len()
                );
                self.notes.extend(notes);
                self.src = l.src;
                self.name = l.name;
                // Prepared for the structure on screen when the file was dropped (G may have
                // been pressed since): keyed by that one.
                self.tracers = vec![(l.accel.structure_name(), tracer, 0.0)];
                self.anim = None;
                self.drop_error = None;
                self.reset_view();
                self.dirty = true;
            }
            Err(e) => {
                // The scene on screen stays; the error is shown until the next drop.
                eprintln!("drop {}: error: {e}", path.display());
                self.drop_error = Some(e.to_string());
            }
        }
        Ok(())
    }

    /// Checks on a file being loaded; true while it is still loading.
    pub(super) fn poll_loader(&mut self) -> gridtrace::Result<bool> {
        let Some(l) = &mut self.loader else {
            return Ok(false);
        };
        match l.poll() {
            None => Ok(true),
            Some(result) => {
                let path = l.path.clone();
                self.loader = None;
                self.loaded(path, result)?;
                Ok(false)
            }
        }
    }

    /// Moves an animated scene on by the wall time since the last frame (a fixed step in
    /// scripts).
    pub(super) fn tick_animation(&mut self) {
        let scripted = self.script.is_some();
        if let Some(p) = &mut self.anim
            && p.playing
        {
            let now = Instant::now();
            let dt = if scripted {
                SCRIPT_FRAME_S
            } else {
                now.duration_since(p.last_tick).as_secs_f32().min(MAX_ANIM_STEP_S)
            };
            p.last_tick = now;
            p.time += dt;
            self.dirty = true;
        }
    }

    pub(super) fn resized(&mut self, w: u32, h: u32) {
        let max = self.presenter.as_ref().map_or(MAX_SIDE, |p| p.max_side()).min(MAX_SIDE);
        if w > max || h > max {
            eprintln!("note: window {w}x{h} is larger than the device allows; tracing {max} pixels a side at most");
        }
        let size = (w.min(max), h.min(max));
        if size != self.size {
            self.size = size;
            self.dirty = true;
            if let Some(p) = &mut self.presenter {
                p.resize(size.0, size.1);
            }
        }
    }

    pub(super) fn fail(&mut self, el: &ActiveEventLoop, e: gridtrace::Error) {
        self.error = Some(e);
        el.exit();
    }

    /// The action of a key press, if any.
    pub(super) fn key_action(&mut self, key: &Key) -> Option<Action> {
        let fast = if self.modifiers.shift_key() { 5.0 } else { 1.0 };
        let name = match key {
            Key::Character(c) if c.eq_ignore_ascii_case("p") => {
                self.shots += 1;
                return Some(Action::Screenshot(format!("gridtrace-view-{}.png", self.shots).into()));
            }
            Key::Character(c) => c.as_str(),
            Key::Named(NamedKey::Escape) => "escape",
            Key::Named(NamedKey::Space) => "space",
            Key::Named(NamedKey::ArrowLeft) => "left",
            Key::Named(NamedKey::ArrowRight) => "right",
            Key::Named(NamedKey::ArrowUp) => "up",
            Key::Named(NamedKey::ArrowDown) => "down",
            Key::Named(NamedKey::PageUp) => "pageup",
            Key::Named(NamedKey::PageDown) => "pagedown",
            _ => return None,
        };
        key_action(name, fast)
    }
}
