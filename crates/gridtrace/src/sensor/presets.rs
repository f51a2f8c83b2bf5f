//! Published beam tables of real spinning LiDARs. Each preset states the datasheet figures it
//! uses; per-unit calibration (per-beam azimuth offsets, beam origins) differs from unit to
//! unit and is left to the caller (`Lidar::with_azimuth_offsets`, `with_origin_offsets`).

use super::Lidar;
use crate::{Error, Result};

/// The names `preset` takes.
pub const PRESET_NAMES: [&str; 3] = ["vlp16", "hdl64", "os1-128"];

/// A real sensor's beam table by name (`vlp16`, `hdl64`, `os1-128`; case and `-`/`_`
/// ignored), with `azimuth_steps` columns (`None`: the sensor's own at 10 Hz). Rows run from
/// the highest beam down.
pub fn preset(name: &str, azimuth_steps: Option<u32>) -> Result<Lidar> {
    let key: String = name
        .to_ascii_lowercase()
        .chars()
        .filter(|c| *c != '-' && *c != '_')
        .collect();
    let (elevations, steps, max_range): (Vec<f32>, u32, f32) = match key.as_str() {
        // Velodyne VLP-16 datasheet (Velodyne LiDAR, "VLP-16", 63-9229): 16 channels, vertical
        // FOV 30° (+15° to -15°), vertical resolution 2°, horizontal resolution 0.1°-0.4°
        // (0.2° at 10 Hz: 1800 steps), range up to 100 m.
        "vlp16" | "velodynevlp16" => ((0..16).map(|i| 15.0 - 2.0 * i as f32).collect(), 1800, 100.0),
        // Velodyne HDL-64E S2 datasheet and user's manual (Velodyne, 63-HDL64ES2): vertical FOV
        // +2° to -24.8°, 64 lasers in two blocks of 32: the upper block from +2° to -8.33° at
        // 1/3° spacing, the lower block from -8.83° to -24.33° at 1/2° spacing; horizontal
        // resolution about 0.17° at 10 Hz (360 / 0.1728 ≈ 2083 steps); range 120 m.
        "hdl64" | "hdl64e" | "velodynehdl64e" => (
            (0..32)
                .map(|i| 2.0 - i as f32 / 3.0)
                .chain((0..32).map(|i| -8.83 - 0.5 * i as f32))
                .collect(),
            2083,
            120.0,
        ),
        // Ouster OS1 datasheet (Ouster, "OS1 Mid-Range High-Resolution Imaging Lidar", rev. 06
        // and later): 128 channels uniformly spread over a 45° vertical FOV (+22.5° to -22.5°),
        // horizontal resolution 512, 1024 or 2048 (2048 at 10 Hz here), range 120 m. Ouster's
        // per-unit `beam_altitude_angles` differ from the uniform table by a fraction of a
        // degree; pass the unit's own through `Lidar::new` where it matters.
        "os1128" | "ousteros1128" => ((0..128).map(|i| 22.5 - 45.0 * i as f32 / 127.0).collect(), 2048, 120.0),
        _ => {
            return Err(Error::InvalidInput(format!(
                "unknown LiDAR preset {name:?}; known: {}",
                PRESET_NAMES.join(", ")
            )));
        }
    };
    Lidar::new(
        elevations,
        azimuth_steps.unwrap_or(steps),
        (-180.0, 180.0),
        0.0,
        max_range,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_have_their_datasheets_tables() {
        let v = preset("VLP-16", None).unwrap();
        assert_eq!((v.beams(), v.azimuth_steps), (16, 1800));
        assert_eq!((v.elevations_deg[0], v.elevations_deg[15]), (15.0, -15.0));

        let h = preset("hdl64", Some(100)).unwrap();
        assert_eq!((h.beams(), h.azimuth_steps), (64, 100));
        let e = &h.elevations_deg;
        assert!((e[0] - 2.0).abs() < 1e-6 && (e[31] + 8.333).abs() < 1e-3);
        assert!((e[32] + 8.83).abs() < 1e-6 && (e[63] + 24.33).abs() < 1e-4);
        assert!(e.windows(2).all(|w| w[0] > w[1]));

        let o = preset("os1-128", None).unwrap();
        assert_eq!((o.beams(), o.azimuth_steps), (128, 2048));
        assert!((o.elevations_deg[0] - 22.5).abs() < 1e-6 && (o.elevations_deg[127] + 22.5).abs() < 1e-5);

        let err = preset("hdl32", None).unwrap_err().to_string();
        assert!(err.contains("hdl32") && err.contains("vlp16"), "{err}");
        assert!(
            preset("vlp16", Some(0))
                .unwrap_err()
                .to_string()
                .contains("azimuth_steps")
        );
    }
}
