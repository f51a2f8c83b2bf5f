//! The page's URL parameters: `gridtrace render`'s options with the same names, values and
//! defaults (`?scene=knot-box&mode=shadow&accel=bvh&res=256x256&eye=X,Y,Z&target=X,Y,Z`), read
//! with the library's own parsers, so that a page and a command line given the same choices
//! trace the same image. Plain Rust: tested natively.

use glam::Vec3;
use gridtrace::render::parse_res;
use gridtrace::util::parse_vec3;
use gridtrace::{AccelParams, AccelSpec, Backend, Mode};

/// What the URL asks for; each field defaults as `gridtrace render`'s option of that name.
#[derive(Debug, Clone, PartialEq)]
pub struct PageParams {
    /// A built-in scene (`scene::builtin::SCENES`); `render` with no scene traces knot-box.
    pub scene: String,
    pub mode: Mode,
    /// `accel` with `accel-params` merged in (`AccelSpec::with_params`, as the CLI merges them).
    pub accel: AccelSpec,
    pub res: (u32, u32),
    pub eye: Option<Vec3>,
    pub target: Option<Vec3>,
    pub up: Option<Vec3>,
    pub vfov: Option<f32>,
    /// `auto` (WebGPU where the browser has it, else the CPU), `gpu` (WebGPU or an error),
    /// `cpu`.
    pub backend: Backend,
}

/// The parameters the page reads, as `render --help` lists the options.
pub const NAMES: [&str; 10] = [
    "scene",
    "mode",
    "accel",
    "accel-params",
    "res",
    "eye",
    "target",
    "up",
    "vfov",
    "backend",
];

impl Default for PageParams {
    fn default() -> Self {
        PageParams {
            scene: "knot-box".into(),
            mode: Mode::Trace,
            accel: AccelSpec::default(),
            res: (512, 512),
            eye: None,
            target: None,
            up: None,
            vfov: None,
            backend: Backend::Auto,
        }
    }
}

impl PageParams {
    /// Reads a URL's query (`location.search`, with or without its `?`). An unknown name, a
    /// value that does not parse or a repeated name is an error naming the parameter, as the
    /// CLI refuses a bad option before any work.
    pub fn from_query(query: &str) -> Result<PageParams, String> {
        let mut p = PageParams::default();
        let mut accel_params = AccelParams::NONE;
        let mut seen: Vec<String> = Vec::new();
        for pair in query.trim_start_matches('?').split('&').filter(|s| !s.is_empty()) {
            let (name, value) = pair.split_once('=').unwrap_or((pair, ""));
            let (name, value) = (decode(name)?, decode(value)?);
            if seen.contains(&name) {
                return Err(format!("parameter '{name}' is given twice"));
            }
            let bad = |e: String| format!("parameter '{name}': {e}");
            match name.as_str() {
                "scene" => {
                    if gridtrace::scene::builtin::scene(&value).is_none() {
                        return Err(bad(format!(
                            "unknown scene '{value}'; built-in scenes: {}",
                            scene_names()
                        )));
                    }
                    p.scene = value.clone();
                }
                "mode" => p.mode = value.parse().map_err(bad)?,
                "accel" => p.accel = value.parse().map_err(bad)?,
                "accel-params" => accel_params = value.parse().map_err(bad)?,
                "res" => p.res = parse_res(&value).map_err(bad)?,
                "eye" => p.eye = Some(parse_vec3(&value).map_err(bad)?),
                "target" => p.target = Some(parse_vec3(&value).map_err(bad)?),
                "up" => p.up = Some(parse_vec3(&value).map_err(bad)?),
                "vfov" => {
                    let v: f32 = value
                        .parse()
                        .map_err(|_| bad(format!("expected degrees, got '{value}'")))?;
                    p.vfov = Some(v);
                }
                "backend" => p.backend = value.parse().map_err(bad)?,
                _ => {
                    return Err(format!(
                        "unknown parameter '{name}'; the page reads {}",
                        NAMES.join(", ")
                    ));
                }
            }
            seen.push(name);
        }
        p.accel = p
            .accel
            .with_params(&accel_params)
            .map_err(|e| format!("parameter 'accel-params': {e}"))?;
        if let gridtrace::AccelChoice::Kind(kind) = p.accel.choice {
            gridtrace::accel::Structure::check_params(kind, &p.accel.params).map_err(|e| match e {
                gridtrace::Error::InvalidInput(m) => format!("parameter 'accel': {m}"),
                e => format!("parameter 'accel': {e}"),
            })?;
        }
        Ok(p)
    }

    /// The camera the scene's is replaced by: the scene's, with each of `eye`, `target`, `up`
    /// and `vfov` given in its place (`render`'s rule).
    pub fn camera(&self, scene: &gridtrace::scene::Camera) -> gridtrace::scene::Camera {
        gridtrace::scene::Camera {
            eye: self.eye.unwrap_or(scene.eye),
            target: self.target.unwrap_or(scene.target),
            up: self.up.unwrap_or(scene.up),
            vfov_deg: self.vfov.unwrap_or(scene.vfov_deg),
        }
    }
}

/// The built-in scenes' names, comma separated.
pub fn scene_names() -> String {
    gridtrace::scene::builtin::SCENES
        .iter()
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

/// A query component with its `%XX` escapes and `+` (a space in a form's query) decoded.
fn decode(s: &str) -> Result<String, String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'+' => out.push(b' '),
            b'%' => {
                let hex = s.get(i + 1..i + 3).and_then(|h| u8::from_str_radix(h, 16).ok());
                out.push(hex.ok_or_else(|| format!("bad escape in '{s}'"))?);
                i += 2;
            }
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8(out).map_err(|_| format!("'{s}' is not UTF-8 once decoded"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use gridtrace::{AccelChoice, AccelKind};

    #[test]
    fn defaults_are_renders() {
        assert_eq!(PageParams::from_query("").unwrap(), PageParams::default());
        assert_eq!(PageParams::from_query("?").unwrap(), PageParams::default());
        let d = PageParams::default();
        assert_eq!((d.scene.as_str(), d.mode, d.res), ("knot-box", Mode::Trace, (512, 512)));
        assert_eq!(d.accel.choice, AccelChoice::Auto);
    }

    #[test]
    fn reads_the_issue_example() {
        let p = PageParams::from_query(
            "?scene=mirror-spheres&mode=shadow&accel=bvh&res=256x128&eye=1,2,-3.5&target=0%2C0.5%2C0&backend=cpu",
        )
        .unwrap();
        assert_eq!(p.scene, "mirror-spheres");
        assert_eq!((p.mode, p.res, p.backend), (Mode::Shadow, (256, 128), Backend::Cpu));
        assert_eq!(p.accel.choice, AccelChoice::Kind(AccelKind::Bvh));
        assert_eq!(
            (p.eye, p.target),
            (Some(Vec3::new(1.0, 2.0, -3.5)), Some(Vec3::new(0.0, 0.5, 0.0)))
        );
        let scene_cam = gridtrace::scene::builtin::mirror_spheres().camera;
        let cam = p.camera(&scene_cam);
        assert_eq!(
            (cam.eye, cam.up, cam.vfov_deg),
            (Vec3::new(1.0, 2.0, -3.5), scene_cam.up, scene_cam.vfov_deg)
        );
        let g = PageParams::from_query("accel=grid:res=16&accel-params=res=32").unwrap();
        assert_eq!(g.accel, "grid:res=32".parse().unwrap());
    }

    #[test]
    fn bad_input_names_the_parameter() {
        let err = |q: &str| PageParams::from_query(q).unwrap_err();
        assert!(err("mode=fast").contains("'mode'") && err("mode=fast").contains("cast, shadow"));
        assert!(
            err("scene=teapot").contains("knot-box, mirror-spheres"),
            "{}",
            err("scene=teapot")
        );
        assert!(err("res=0x5").contains("'res'"));
        assert!(err("eye=1,nan,2").contains("'eye'"));
        assert!(err("colour=red").contains("unknown parameter 'colour'"));
        assert!(err("mode=cast&mode=heat").contains("twice"));
        assert!(err("target=%zz").contains("bad escape"));
        assert!(err("accel=warp").contains("'accel'"));
        assert!(
            err("accel=grid:size=3").contains("'accel'"),
            "{}",
            err("accel=grid:size=3")
        );
        assert!(err("backend=webgl").contains("auto, gpu or cpu"));
    }
}
