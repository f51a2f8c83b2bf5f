//! `bench --ablate`: what the paper's optimisations buy, measured by turning each off. The paper
//! credits about 20% to shadow rays that stop at the first hit (any hit) rather than finding the
//! closest, and reports gains from removing finished rays early (its ray masks and early-Z; here
//! the compacted queues of the wavefront kernels). Each ablation renders the same frames with
//! the optimisation off (`RenderOptions::ablation`; the images are the same, tests/gpu.rs), the
//! two forms alternating run by run so that drift hits both alike.

use serde::Serialize;

use super::{Summary, build_paper_scene};
use gridtrace::Result;
use gridtrace::accel::{AccelKind, Resolution};
use gridtrace::gpu::{GpuContext, GpuRenderer};
use gridtrace::render::{Ablation, Mode, RenderOptions};
use gridtrace::scene::PreparedScene;

/// One ablation on one scene, structure, mode and backend.
#[derive(Debug, Clone, Serialize)]
pub struct AblationRow {
    pub scene: String,
    pub backend: String,
    pub accel: String,
    pub mode: String,
    /// The optimisation turned off (`Ablation::NAMES`).
    pub ablation: String,
    pub width: u32,
    pub height: u32,
    /// Median milliseconds per frame with the optimisation, and without it.
    pub with_ms: f64,
    pub without_ms: f64,
    /// `without_ms / with_ms`: how much slower the frame is without the optimisation.
    pub slowdown: f64,
    pub shadow_rays: u64,
}

/// A renderer the ablation study times: the CPU, or a scene uploaded to the GPU.
enum Target<'a> {
    Cpu,
    Gpu(&'a mut GpuRenderer),
}

impl Target<'_> {
    /// Milliseconds of one frame (the GPU's timestamps where it has them) and its shadow rays.
    fn frame(&mut self, scene: &PreparedScene, opts: &RenderOptions) -> Result<(f64, u64)> {
        match self {
            Target::Cpu => {
                let (_, s) = gridtrace::cpu::render(scene, opts, None)?;
                Ok((s.render_ms, s.rays.shadow))
            }
            Target::Gpu(g) => {
                let (_, s) = g.render(&scene.camera, &scene.lights, opts)?;
                Ok((s.frame_ms(), s.render.rays.shadow))
            }
        }
    }
}

/// What the study covers.
pub struct AblationPlan<'a> {
    pub scenes: &'a [String],
    pub data_dir: Option<&'a std::path::Path>,
    pub grid: Resolution,
    pub paper_grids: bool,
    pub size: (u32, u32),
    pub modes: &'a [Mode],
    pub accels: &'a [AccelKind],
    /// Ablation names (`Ablation::NAMES`).
    pub ablations: &'a [String],
    pub cpu: bool,
    pub gpu: Option<&'a std::sync::Arc<GpuContext>>,
    pub warmup: u32,
    pub reps: u32,
}

/// Runs every ablation of the plan on every backend it applies to (compaction: the GPU only;
/// the CPU walks each pixel's rays to their end and has no queues) and mode with shadow rays.
pub fn ablation_study(plan: &AblationPlan, log: &mut dyn FnMut(&str)) -> Result<Vec<AblationRow>> {
    let mut rows = Vec::new();
    for name in plan.scenes {
        let bs = match build_paper_scene(name, plan.data_dir) {
            Ok(s) => s,
            Err(e) => {
                log(&format!("  ablation: skipping {name}: {e}"));
                continue;
            }
        };
        for &accel in plan.accels {
            let scene = bs
                .scene
                .prepare_for(accel, &bs.params_for(accel, plan.paper_grids, plan.grid))?;
            let mut gpu = match plan.gpu {
                Some(ctx) => Some(GpuRenderer::new(
                    ctx.clone(),
                    &scene,
                    &gridtrace::gpu::GpuVariants::default(),
                )?),
                None => None,
            };
            let mut targets: Vec<(&str, Target)> = Vec::new();
            if plan.cpu {
                targets.push(("cpu", Target::Cpu));
            }
            if let Some(g) = gpu.as_mut() {
                targets.push(("gpu", Target::Gpu(g)));
            }
            for (backend, target) in &mut targets {
                for &mode in plan.modes.iter().filter(|m| m.shadows()) {
                    for ablation in plan.ablations {
                        let off = Ablation::named(ablation).ok_or_else(|| {
                            super::invalid(format!(
                                "--ablate takes {}; got '{ablation}'",
                                Ablation::NAMES.join(", ")
                            ))
                        })?;
                        if off.no_compaction && *backend == "cpu" {
                            continue;
                        }
                        let with = RenderOptions::new(plan.size.0, plan.size.1, mode);
                        let without = RenderOptions { ablation: off, ..with };
                        let (mut a, mut b) = (Vec::new(), Vec::new());
                        let mut shadow_rays = 0;
                        for rep in 0..plan.warmup + plan.reps.max(1) {
                            let (ta, s) = target.frame(&scene, &with)?;
                            let (tb, _) = target.frame(&scene, &without)?;
                            if rep >= plan.warmup {
                                a.push(ta);
                                b.push(tb);
                            }
                            shadow_rays = s;
                        }
                        let (with_ms, without_ms) = (Summary::of(&a).median_ms, Summary::of(&b).median_ms);
                        let row = AblationRow {
                            scene: bs.name.clone(),
                            backend: backend.to_string(),
                            accel: accel.name().into(),
                            mode: mode.name().into(),
                            ablation: ablation.clone(),
                            width: plan.size.0,
                            height: plan.size.1,
                            with_ms,
                            without_ms,
                            slowdown: without_ms / with_ms.max(1e-9),
                            shadow_rays,
                        };
                        log(&format!(
                            "  ablation {:<16} {} {:<4} {:<6} without {:<14} {:>9.2} ms -> {:>9.2} ms  x{:.3}",
                            row.scene,
                            row.backend,
                            row.accel,
                            row.mode,
                            row.ablation,
                            with_ms,
                            without_ms,
                            row.slowdown
                        ));
                        rows.push(row);
                    }
                }
            }
        }
    }
    Ok(rows)
}
