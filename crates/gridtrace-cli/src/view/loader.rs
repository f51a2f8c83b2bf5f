//! Files dropped on the viewer load on a worker thread: reading and preparing a large mesh takes
//! seconds, and the window keeps answering meanwhile (the overlay shows what the loader is
//! doing). A file that fails to load leaves the scene on screen as it was and says why.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use gridtrace::AccelKind;
use gridtrace::scene::{PreparedScene, Scene};

use crate::common::{AccelArgs, SceneArgs};

/// A loaded file: its scene, its name, and the scene prepared for the structure on screen.
pub struct Loaded {
    /// The structure it was prepared for.
    pub accel: AccelKind,
    pub src: Scene,
    pub name: String,
    pub prepared: PreparedScene,
}

pub struct Loader {
    pub path: PathBuf,
    /// What the worker is doing, in words.
    stage: Arc<Mutex<&'static str>>,
    started: Instant,
    handle: Option<JoinHandle<gridtrace::Result<Loaded>>>,
}

impl Loader {
    /// Starts loading `path` (a mesh in an auto-framed scene with a floor, or a TOML scene),
    /// prepared for `accel` with the parameters given for it.
    pub fn start(path: PathBuf, accel: AccelKind, accel_args: AccelArgs) -> Loader {
        let stage = Arc::new(Mutex::new("reading"));
        let s = stage.clone();
        let p = path.clone();
        let handle = std::thread::spawn(move || {
            let args = SceneArgs {
                file: Some(p),
                scene: None,
                mesh: None,
            };
            let (src, name) = args.load(true)?;
            *s.lock().unwrap_or_else(|e| e.into_inner()) = "building the structure";
            let prepared = crate::common::prepare(&src, &name, accel, &accel_args)?;
            Ok(Loaded {
                accel,
                src,
                name,
                prepared,
            })
        });
        Loader {
            path,
            stage,
            started: Instant::now(),
            handle: Some(handle),
        }
    }

    /// "NAME: STAGE (S s)", for the overlay.
    pub fn describe(&self) -> String {
        format!(
            "{}: {} ({:.1} s)",
            self.path.display(),
            self.stage.lock().map_or("?", |s| *s),
            self.started.elapsed().as_secs_f64()
        )
    }

    /// The result once the worker is done; `None` while it works.
    pub fn poll(&mut self) -> Option<gridtrace::Result<Loaded>> {
        if !self.handle.as_ref().is_some_and(|h| h.is_finished()) {
            return None;
        }
        let h = self.handle.take()?;
        Some(h.join().unwrap_or_else(|_| {
            Err(gridtrace::Error::InvalidInput(format!(
                "{}: the loader stopped unexpectedly",
                self.path.display()
            )))
        }))
    }
}
