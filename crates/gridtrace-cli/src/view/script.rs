//! `gridtrace view --script FILE`: timed input replayed from a file, one action a line, for tests
//! and demos. Each line becomes the `Action` the same input from a person would. The window
//! opens as without a script, so it needs a display (or `xvfb-run`). An example:
//! examples/view-script.txt; the format is also in the README ("The viewer").
//!
//! ```text
//! # comments and blank lines are ignored
//! key 2              # a key, as the window takes it: 1-4 modes, g next structure, f frame,
//!                    # w/s a/d e/q fly, l next light, left/right/up/down/pageup/pagedown move
//!                    # it, [ and ] resolution scale, - and = fly speed, h overlay, space play
//! drag 40 -20        # orbit by a mouse drag of (dx, dy) pixels
//! pan 10 5           # pan by a right-button drag of (dx, dy) pixels
//! light 30 10        # drag the selected light's gizmo by (dx, dy) pixels
//! zoom 2             # wheel steps, positive: closer
//! resize 320 240     # window size in physical pixels
//! drop mesh.ply      # load a file as if dropped on the window (the script waits for it)
//! screenshot a.png   # save the traced frame, print its camera, lights, mode and structure
//! capture w.png      # save the window as it looks, overlay included
//! overlay o.txt      # write the overlay's text to a file
//! quit               # (implied at the end of the file)
//! ```

use std::path::Path;

use super::controls::{Action, key_action};

/// The actions of a script file; errors name the file and line.
pub fn load(path: &Path) -> gridtrace::Result<Vec<Action>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| gridtrace::Error::InvalidInput(format!("{}: {e}", path.display())))?;
    parse(&text).map_err(|(line, m)| gridtrace::Error::InvalidInput(format!("{}:{line}: {m}", path.display())))
}

/// The actions of a script's text, or (line number, message) of the first bad line.
pub fn parse(text: &str) -> Result<Vec<Action>, (usize, String)> {
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let mut words = line.split_whitespace();
        let cmd = words.next().unwrap_or("");
        let args: Vec<&str> = words.collect();
        let num = |k: usize| -> Result<f32, (usize, String)> {
            args.get(k)
                .and_then(|a| a.parse::<f32>().ok().filter(|v| v.is_finite()))
                .ok_or((i + 1, format!("'{cmd}' needs a number as argument {}: '{line}'", k + 1)))
        };
        let want = |n: usize| -> Result<(), (usize, String)> {
            if args.len() == n {
                Ok(())
            } else {
                Err((i + 1, format!("'{cmd}' takes {n} argument(s): '{line}'")))
            }
        };
        let action = match cmd {
            "key" => {
                want(1)?;
                key_action(args[0], 1.0).ok_or((
                    i + 1,
                    format!(
                        "unknown key '{}' (1-4, g, f, w a s d q e, l, left right up down pageup pagedown, [ ], - =, h, space, escape)",
                        args[0]
                    ),
                ))?
            }
            "pan" => {
                want(2)?;
                Action::Pan(num(0)?, num(1)?)
            }
            "light" => {
                want(2)?;
                Action::DragLight(num(0)?, num(1)?)
            }
            "drop" => {
                want(1)?;
                Action::Drop(args[0].into())
            }
            "capture" => {
                want(1)?;
                Action::Capture(args[0].into())
            }
            "overlay" => {
                want(1)?;
                Action::OverlayText(args[0].into())
            }
            "drag" => {
                want(2)?;
                Action::Orbit(num(0)?, num(1)?)
            }
            "zoom" => {
                want(1)?;
                Action::Zoom(num(0)?)
            }
            "resize" => {
                want(2)?;
                let (w, h) = (num(0)?, num(1)?);
                if w < 0.0 || h < 0.0 || w.fract() != 0.0 || h.fract() != 0.0 {
                    return Err((i + 1, format!("resize takes whole pixel counts: '{line}'")));
                }
                Action::Resize(w as u32, h as u32)
            }
            "screenshot" => {
                want(1)?;
                Action::Screenshot(args[0].into())
            }
            "quit" => {
                want(0)?;
                Action::Quit
            }
            _ => {
                return Err((
                    i + 1,
                    format!(
                        "unknown command '{cmd}' (key, drag, pan, light, zoom, resize, drop, screenshot, capture, overlay, quit)"
                    ),
                ));
            }
        };
        out.push(action);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use gridtrace::Mode;

    /// The example script the README runs (examples/view-script.txt) parses, and shows what
    /// its comments say: two screenshots, a capture, the overlay's text, then quit.
    #[test]
    fn the_shipped_example_parses() {
        let actions = parse(include_str!("../../../../examples/view-script.txt")).unwrap();
        for want in [
            Action::SetMode(Mode::Shadow),
            Action::SetMode(Mode::Trace),
            Action::Screenshot("view-shadow.png".into()),
            Action::Screenshot("view-trace.png".into()),
            Action::Capture("view-window.png".into()),
            Action::OverlayText("view-overlay.txt".into()),
        ] {
            assert!(actions.contains(&want), "{want:?} missing from {actions:?}");
        }
        assert_eq!(actions.last(), Some(&Action::Quit));
    }

    #[test]
    fn parses_and_names_bad_lines() {
        let a = parse("# demo\nkey 2\ndrag 40 -20 # orbit\nzoom 1.5\n\nresize 0 0\nscreenshot a.png\nkey g\nquit\n")
            .unwrap();
        assert_eq!(
            a,
            vec![
                Action::SetMode(Mode::Shadow),
                Action::Orbit(40.0, -20.0),
                Action::Zoom(1.5),
                Action::Resize(0, 0),
                Action::Screenshot("a.png".into()),
                Action::NextAccel,
                Action::Quit
            ]
        );
        assert_eq!(parse("key 2\nfly 1").unwrap_err().0, 2);
        assert_eq!(parse("drag 1").unwrap_err().0, 1);
        assert_eq!(parse("zoom nan").unwrap_err().0, 1);
        assert_eq!(parse("resize -1 5").unwrap_err().0, 1);
        assert!(parse("key 7").unwrap_err().1.contains("unknown key"));
        assert_eq!(
            parse("key w\nkey q\nkey f").unwrap(),
            vec![Action::Fly(1.0, 0.0, 0.0), Action::Fly(0.0, 0.0, -1.0), Action::Frame]
        );
    }
}
