//! A LiDAR's beam table from a TOML file, for sensors the presets do not name (a unit's own
//! calibration, a research rig):
//!
//! ```toml
//! elevations_deg = [15, 13, 11, 9]     # one per beam, top first; required
//! azimuth_steps = 1800                 # columns a turn; required
//! azimuth_range_deg = [-180, 180]      # optional
//! min_range = 0.3                      # metres, optional (0)
//! max_range = 100                      # metres, optional (inf)
//! azimuth_offsets_deg = [0, 0, 0, 0]   # per beam, optional
//! origin_offsets = [[0, 0, 0.01], ...] # per beam, metres at azimuth 0, optional
//! ```
//!
//! Unknown keys are errors; every error names the file and, where TOML gives one, the line.

use std::path::Path;

use serde::Deserialize;

use super::Lidar;
use crate::error::Location;
use crate::{Error, Result};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BeamFile {
    elevations_deg: Vec<f32>,
    azimuth_steps: u32,
    azimuth_range_deg: Option<[f32; 2]>,
    min_range: Option<f32>,
    max_range: Option<f32>,
    azimuth_offsets_deg: Option<Vec<f32>>,
    origin_offsets: Option<Vec<[f32; 3]>>,
}

/// Reads a beam table file (the format above) into a `Lidar`; `Lidar::new`'s checks apply, and
/// their messages are prefixed with the file.
pub fn load_beam_table(path: &Path) -> Result<Lidar> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_beam_table(&text, path)
}

/// `load_beam_table` on text already read; `path` names it in errors.
pub fn parse_beam_table(text: &str, path: &Path) -> Result<Lidar> {
    let def: BeamFile = toml::from_str(text).map_err(|e| {
        let line = e
            .span()
            .map(|s| Location::Line(text[..s.start.min(text.len())].matches('\n').count() + 1))
            .unwrap_or(Location::Whole);
        Error::parse(path, line, e.message().to_string())
    })?;
    let in_file = |e: Error| match e {
        Error::InvalidInput(m) => Error::parse(path, Location::Whole, m),
        e => e,
    };
    let range = def.azimuth_range_deg.unwrap_or([-180.0, 180.0]);
    let mut lidar = Lidar::new(
        def.elevations_deg,
        def.azimuth_steps,
        (range[0], range[1]),
        def.min_range.unwrap_or(0.0),
        def.max_range.unwrap_or(f32::INFINITY),
    )
    .map_err(in_file)?;
    if let Some(offsets) = def.azimuth_offsets_deg {
        lidar = lidar.with_azimuth_offsets(offsets).map_err(in_file)?;
    }
    if let Some(origins) = def.origin_offsets {
        lidar = lidar.with_origin_offsets(origins).map_err(in_file)?;
    }
    Ok(lidar)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_file_makes_the_lidar_it_describes() {
        let text = "elevations_deg = [10, 0, -10]\nazimuth_steps = 8\nmax_range = 50\n\
                    azimuth_offsets_deg = [0.5, 0, -0.5]\n";
        let l = parse_beam_table(text, Path::new("beams.toml")).unwrap();
        let mut want = Lidar::new(vec![10.0, 0.0, -10.0], 8, (-180.0, 180.0), 0.0, 50.0).unwrap();
        want = want.with_azimuth_offsets(vec![0.5, 0.0, -0.5]).unwrap();
        assert_eq!(l, want);
    }

    #[test]
    fn bad_table_files_name_the_file_and_place() {
        let err = |text: &str| parse_beam_table(text, Path::new("beams.toml")).unwrap_err().to_string();
        let e = err("elevations_deg = [1]\nazimuth_steps = 4\nazimuth_stepz = 3\n");
        assert!(
            e.starts_with("beams.toml:line 3:") && e.contains("azimuth_stepz"),
            "{e}"
        );
        let e = err("elevations_deg = []\nazimuth_steps = 4\n");
        assert!(
            e.starts_with("beams.toml:") && e.contains("elevations_deg is empty"),
            "{e}"
        );
        let e = err("elevations_deg = [1, 2]\nazimuth_steps = 4\nazimuth_offsets_deg = [0]\n");
        assert!(e.starts_with("beams.toml:") && e.contains("azimuth_offsets_deg"), "{e}");
        let e = err("elevations_deg = [1]\n");
        assert!(e.contains("azimuth_steps"), "{e}");
    }
}
