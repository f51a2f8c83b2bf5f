//! What the user can do in the viewer, as `Action`s: window input and scripted input both become
//! these, so a script drives exactly the code a person does. And the orbit camera they move.

use gridtrace::{AccelKind, Mode};
// The orbit camera the mouse moves, and the projection the light gizmos use: the library's, so
// that the web page moves its camera as the viewer does.
pub use gridtrace::scene::orbit::{Orbit, project, unproject};

/// One user action.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Orbit about the target by a mouse drag of (dx, dy) pixels.
    Orbit(f32, f32),
    /// Pan by a (right-button) drag of (dx, dy) pixels: the target moves in the view plane so
    /// that the point under the pointer at the target's depth follows it.
    Pan(f32, f32),
    /// Zoom by wheel steps (positive: closer).
    Zoom(f32),
    /// Fly: move along the view (forward, right, up) in steps of 5% of the orbit distance.
    Fly(f32, f32, f32),
    /// Frame the scene: target its centre, at a distance that shows all of it.
    Frame,
    SetMode(Mode),
    /// The next structure (grid, pc, bvh, grid ...).
    NextAccel,
    /// Resize the window to (width, height) physical pixels.
    Resize(u32, u32),
    /// Save the frame on screen as a PNG and print its camera, lights, mode and structure.
    Screenshot(std::path::PathBuf),
    /// Save the window as it looks, overlay included, as a PNG.
    Capture(std::path::PathBuf),
    /// Write the overlay's text, one line each, to a file (what the overlay says, for tests).
    OverlayText(std::path::PathBuf),
    /// Select the next light (its gizmo turns yellow).
    NextLight,
    /// Drag the selected light's gizmo by (dx, dy) window pixels: the light moves in the plane
    /// through it parallel to the image, following the pointer.
    DragLight(f32, f32),
    /// Move the selected light along the view (forward, right, up) in fly steps.
    MoveLight(f32, f32, f32),
    /// Resolution scale: trace every pixel (0), every other pixel a side (1), ... (3 at most).
    ScaleStep(i32),
    /// Fly faster (positive) or slower, a factor of two a step.
    SpeedStep(i32),
    /// Load a mesh or scene file, as if dropped on the window (on a worker thread; a bad file
    /// keeps the scene on screen and shows its error).
    Drop(std::path::PathBuf),
    /// Show or hide the overlay.
    ToggleOverlay,
    /// Play or pause an animated scene.
    PlayPause,
    Quit,
}

/// Halvings of the resolution at most (`ScaleStep`): 1/8 of the window a side.
pub const MAX_SCALE_STEPS: u32 = 3;

/// The structure after `a` in the viewer's cycle: the registry's interactive kinds, in order,
/// round and round (from a kind outside the cycle, its first).
pub fn next_accel(a: AccelKind) -> AccelKind {
    let cycle: Vec<AccelKind> = AccelKind::interactive().collect();
    match cycle.iter().position(|&k| k == a) {
        Some(i) => cycle[(i + 1) % cycle.len()],
        None => cycle[0],
    }
}

/// The fly step a key makes, (forward, right, up): W/S forward and back, D/A right and left,
/// E/Q up and down.
pub fn fly_key(k: &str) -> Option<(f32, f32, f32)> {
    Some(match k.to_ascii_lowercase().as_str() {
        "w" => (1.0, 0.0, 0.0),
        "s" => (-1.0, 0.0, 0.0),
        "d" => (0.0, 1.0, 0.0),
        "a" => (0.0, -1.0, 0.0),
        "e" => (0.0, 0.0, 1.0),
        "q" => (0.0, 0.0, -1.0),
        _ => return None,
    })
}

/// The action of a key by name: characters as typed ("g", "1", "["), named keys in lower case
/// ("space", "left", "pageup", "escape"). `fast` multiplies fly steps (shift held). P (the
/// screenshot, which needs a file name) is the window's own.
pub fn key_action(name: &str, fast: f32) -> Option<Action> {
    Some(match name.to_ascii_lowercase().as_str() {
        "escape" => Action::Quit,
        "space" => Action::PlayPause,
        "left" => Action::MoveLight(0.0, -1.0, 0.0),
        "right" => Action::MoveLight(0.0, 1.0, 0.0),
        "up" => Action::MoveLight(0.0, 0.0, 1.0),
        "down" => Action::MoveLight(0.0, 0.0, -1.0),
        "pageup" => Action::MoveLight(1.0, 0.0, 0.0),
        "pagedown" => Action::MoveLight(-1.0, 0.0, 0.0),
        "g" => Action::NextAccel,
        "f" => Action::Frame,
        "l" => Action::NextLight,
        "h" => Action::ToggleOverlay,
        "[" => Action::ScaleStep(1),
        "]" => Action::ScaleStep(-1),
        "-" => Action::SpeedStep(-1),
        "=" | "+" => Action::SpeedStep(1),
        k => match mode_key(k) {
            Some(m) => Action::SetMode(m),
            None => {
                let (f, r, u) = fly_key(k)?;
                Action::Fly(f * fast, r * fast, u * fast)
            }
        },
    })
}

/// The mode a number key selects: 1 cast, 2 shadow, 3 trace, 4 heat.
pub fn mode_key(k: &str) -> Option<Mode> {
    Some(match k {
        "1" => Mode::Cast,
        "2" => Mode::Shadow,
        "3" => Mode::Trace,
        "4" => Mode::Heat,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys() {
        assert_eq!(mode_key("2"), Some(Mode::Shadow));
        assert_eq!(mode_key("9"), None);
        // G visits every interactive structure once and comes back.
        let mut seen = vec![AccelKind::Grid];
        while let a = next_accel(*seen.last().unwrap())
            && a != AccelKind::Grid
        {
            seen.push(a);
        }
        assert_eq!(seen, AccelKind::interactive().collect::<Vec<_>>());
        assert_eq!(
            seen.len(),
            AccelKind::ALL.len() - 2,
            "all but brute force and hwrt (which needs ray queries)"
        );
        assert_eq!(next_accel(AccelKind::Brute), AccelKind::Grid);
    }
}
