//! Window events (winit) to actions, and the passes the event loop runs.

use super::*;

impl ApplicationHandler for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let attrs = Window::default_attributes()
            .with_title(format!("gridtrace: {}", self.name))
            .with_inner_size(winit::dpi::PhysicalSize::new(self.size.0, self.size.1));
        let window = match el.create_window(attrs) {
            Ok(w) => Arc::new(w),
            Err(e) => return self.fail(el, window_error("opening a window", e)),
        };
        match present::Presenter::new(el, window.clone(), self.placement.device.as_ref()) {
            Ok(p) => {
                self.notes.extend(p.note.clone());
                self.egui = Some(egui_winit::State::new(
                    self.egui_ctx.clone(),
                    egui::ViewportId::ROOT,
                    &window,
                    Some(window.scale_factor() as f32),
                    None,
                    Some(p.max_side() as usize),
                ));
                self.presenter = Some(p);
            }
            Err(e) => return self.fail(el, e),
        }
        let s = window.inner_size();
        self.window = Some(window.clone());
        self.resized(s.width, s.height);
        window.request_redraw();
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        // The overlay sees every event first; a press on it, or a drag that started there, is
        // its own.
        let mut consumed = false;
        if let (Some(state), Some(win)) = (&mut self.egui, &self.window) {
            let r = state.on_window_event(win, &event);
            consumed = r.consumed;
            // egui asks to repaint after every redraw as well: following that would redraw
            // forever; what needs another pass is in `busy`.
            if r.repaint && !matches!(event, WindowEvent::RedrawRequested) {
                win.request_redraw();
            }
        }
        let result = match event {
            WindowEvent::CloseRequested => {
                el.exit();
                Ok(())
            }
            WindowEvent::Resized(s) => {
                self.resized(s.width, s.height);
                Ok(())
            }
            WindowEvent::ScaleFactorChanged { .. } => {
                // egui follows the new scale (its state saw the event); the window's physical
                // size arrives as a Resized event.
                self.dirty = true;
                Ok(())
            }
            // A script draws its own passes (about_to_wait), so its animation steps are its own.
            WindowEvent::RedrawRequested => self.redraw(self.script.is_none()),
            WindowEvent::ModifiersChanged(m) => {
                self.modifiers = m.state();
                Ok(())
            }
            WindowEvent::DroppedFile(path) => self.apply(Action::Drop(path), el),
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                if state == ElementState::Pressed && !consumed && !self.egui_ctx.is_pointer_over_egui() {
                    // A press on a light's gizmo (drawn with the overlay) drags the light;
                    // anywhere else it orbits.
                    let ppp = self.egui_ctx.pixels_per_point();
                    let (cx, cy) = (self.cursor.0 as f32, self.cursor.1 as f32);
                    let gizmos = if self.show_overlay { self.gizmos() } else { Vec::new() };
                    let hit = gizmos.iter().position(|g| {
                        g.is_some_and(|(x, y)| ((x - cx).powi(2) + (y - cy).powi(2)).sqrt() <= GIZMO_RADIUS_PT * ppp)
                    });
                    let kind = match hit {
                        Some(i) => {
                            self.selected_light = i;
                            Drag::Light
                        }
                        None => Drag::Orbit,
                    };
                    self.drag = Some((kind, self.cursor));
                } else if state == ElementState::Released {
                    self.drag = None;
                }
                Ok(())
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Right | MouseButton::Middle,
                ..
            } => {
                self.drag = (state == ElementState::Pressed && !consumed && !self.egui_ctx.is_pointer_over_egui())
                    .then_some((Drag::Pan, self.cursor));
                Ok(())
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = (position.x, position.y);
                match self.drag {
                    Some((kind, (x, y))) => {
                        self.drag = Some((kind, self.cursor));
                        let (dx, dy) = ((position.x - x) as f32, (position.y - y) as f32);
                        let action = match kind {
                            Drag::Orbit => Action::Orbit(dx, dy),
                            Drag::Pan => Action::Pan(dx, dy),
                            Drag::Light => Action::DragLight(dx, dy),
                        };
                        self.apply(action, el)
                    }
                    None => Ok(()),
                }
            }
            WindowEvent::MouseWheel { delta, .. } if !consumed => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => (p.y / 40.0) as f32,
                };
                self.apply(Action::Zoom(steps), el)
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed && !consumed => {
                match self.key_action(&event.logical_key) {
                    Some(a) => self.apply(a, el),
                    None => Ok(()),
                }
            }
            _ => Ok(()),
        };
        if let Err(e) = result {
            return self.fail(el, e);
        }
        if self.busy()
            && let Some(w) = &self.window
        {
            w.request_redraw();
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        let loading = match self.poll_loader() {
            Ok(l) => l,
            Err(e) => return self.fail(el, e),
        };
        if self.script.is_none() || self.window.is_none() {
            // Passes keep coming while there is work (`busy`, a file loading among it); when
            // idle, a loader is still polled ten times a second.
            if loading {
                el.set_control_flow(ControlFlow::WaitUntil(Instant::now() + Duration::from_millis(100)));
                if let Some(w) = &self.window {
                    w.request_redraw();
                }
            } else {
                el.set_control_flow(ControlFlow::Wait);
            }
            return;
        }
        // A script runs one action per pass of the event loop, after a pass of tracing (within
        // the budget, as for a person) and presenting; screenshots, captures and the overlay's
        // text finish the frame first, so they show the frame a person would have seen once it
        // was done. Trace and present here rather than wait for a redraw request: a script
        // must not depend on the window system's timing. A file being loaded holds the script
        // until it is in (or has failed).
        if let Err(e) = self.redraw(true) {
            return self.fail(el, e);
        }
        el.set_control_flow(ControlFlow::Poll);
        if loading {
            std::thread::sleep(Duration::from_millis(10));
            return;
        }
        let next = self.script.as_mut().and_then(|s| s.pop()).unwrap_or(Action::Quit);
        if let Err(e) = self.apply(next, el) {
            self.fail(el, e);
        }
    }
}
