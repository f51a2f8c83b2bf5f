//! Golden images: built-in scenes in every mode on the CPU path, against PNGs in tests/golden/.
//!
//! Tolerance: an 8-bit sRGB channel may differ by at most 2 levels on 99.5% of pixels (rounding
//! differences between compilers and CPUs move a few pixels at shadow and silhouette edges
//! across a threshold), and the mean absolute difference must stay below 0.5 levels.
//! Regenerate after an intended change with `GRIDTRACE_BLESS=1 cargo test --test golden` and
//! look at the new images before committing them.

use gridtrace::AccelParams;
use std::path::PathBuf;

use gridtrace::scene::builtin;
use gridtrace::{AccelKind, Mode, RenderOptions, Resolution};

const SIZE: u32 = 96;

fn golden_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(format!("{name}.png"))
}

/// Compares two RGB8 buffers; returns a description of the failure, if any.
pub fn compare_rgb8(got: &[u8], want: &[u8]) -> Result<(), String> {
    if got.len() != want.len() {
        return Err(format!("size differs: {} vs {} bytes", got.len(), want.len()));
    }
    let pixels = got.len() / 3;
    let mut bad = 0;
    let mut sum = 0u64;
    for (g, w) in got.chunks(3).zip(want.chunks(3)) {
        let d = g.iter().zip(w).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        sum += g.iter().zip(w).map(|(a, b)| a.abs_diff(*b) as u64).sum::<u64>();
        if d > 2 {
            bad += 1;
        }
    }
    let mean = sum as f64 / got.len() as f64;
    if bad * 1000 > pixels * 5 || mean > 0.5 {
        return Err(format!(
            "{bad} of {pixels} pixels differ by more than 2 levels; mean difference {mean:.3}"
        ));
    }
    Ok(())
}

#[test]
fn golden_images() {
    let bless = std::env::var_os("GRIDTRACE_BLESS").is_some();
    let mut failures = Vec::new();
    for scene_name in ["knot-box", "mirror-spheres"] {
        let prepared = builtin::scene(scene_name)
            .unwrap()
            .prepare(Resolution::default())
            .unwrap();
        for mode in Mode::ALL {
            let name = format!("{scene_name}_{}", mode.name());
            let opts = RenderOptions::new(SIZE, SIZE, mode);
            let (img, stats) = gridtrace::cpu::render(&prepared, &opts, None).unwrap();
            let img = if mode == Mode::Heat { img.heat_to_color() } else { img };
            let rgb = img.to_rgb8();
            assert_eq!(stats.rays.eye, (SIZE * SIZE) as u64);
            // The picture is not blank: a scene that renders all background is a bug too.
            let distinct: std::collections::HashSet<&[u8]> = rgb.chunks(3).collect();
            assert!(distinct.len() > 50, "{name}: only {} distinct colours", distinct.len());
            let path = golden_path(&name);
            if bless {
                image::save_buffer(&path, &rgb, SIZE, SIZE, image::ColorType::Rgb8).unwrap();
                continue;
            }
            let want =
                image::open(&path).unwrap_or_else(|e| panic!("{}: {e} (bless with GRIDTRACE_BLESS=1)", path.display()));
            if let Err(e) = compare_rgb8(&rgb, want.to_rgb8().as_raw()) {
                image::save_buffer_with_format(
                    path.with_extension("png.new"),
                    &rgb,
                    SIZE,
                    SIZE,
                    image::ColorType::Rgb8,
                    image::ImageFormat::Png,
                )
                .unwrap();
                failures.push(format!("{name}: {e}"));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "golden images differ (new images saved as *.png.new):\n{}",
        failures.join("\n")
    );
}

/// The comparison itself must be able to fail.
#[test]
fn comparison_detects_differences() {
    let a = vec![100u8; 300];
    let mut b = a.clone();
    assert!(compare_rgb8(&a, &b).is_ok());
    b[0] = 110;
    assert!(compare_rgb8(&a, &b).is_err(), "1 of 100 pixels off by 10 exceeds 0.5%");
    let c: Vec<u8> = a.iter().map(|v| v + 1).collect();
    assert!(compare_rgb8(&a, &c).is_err(), "mean difference 1 exceeds 0.5");
}

/// Proximity clouds, the BVH and the irregular grid change speed, never pictures.
#[test]
fn every_structure_renders_the_same_image() {
    let scene = builtin::scene("mirror-spheres").unwrap();
    let render = |accel| {
        let prepared = scene.prepare_for(accel, &AccelParams::NONE).unwrap();
        let (img, stats) = gridtrace::cpu::render(&prepared, &RenderOptions::new(64, 64, Mode::Trace), None).unwrap();
        (img.to_rgb8(), stats.rays)
    };
    let (g, rg) = render(AccelKind::Grid);
    for accel in AccelKind::ALL.into_iter().filter(|&a| a != AccelKind::Grid) {
        let (p, rp) = render(accel);
        assert_eq!(rg, rp, "{}: ray counts", accel.name());
        compare_rgb8(&p, &g).unwrap_or_else(|e| panic!("{}: {e}", accel.name()));
    }
}
