//! `bench`'s studies beside the matrix (`--sweep-grid`, `--scaling`, `--build-scaling`,
//! `--pc-study`, `--query-study`, `--irregular-sweep`, `--ablate`, the ray export) and the
//! reports it writes: one method each over what a run shares.

use std::path::PathBuf;

use gridtrace::accel::dims_str;
use gridtrace::gpu::GpuContext;
use gridtrace::{Mode, RenderOptions, Resolution};
use gridtrace_bench::{self as bench, BenchConfig, BenchReport, scenes, studies};

use super::{BenchArgs, BenchBackendArg};

/// What every study of one `bench` run shares.
pub(super) struct Run<'a> {
    pub(super) a: &'a BenchArgs,
    pub(super) cfg: &'a BenchConfig,
    pub(super) data_dir: Option<PathBuf>,
    pub(super) gpu: Option<std::sync::Arc<GpuContext>>,
    pub(super) run_cpu: bool,
    pub(super) backend: BenchBackendArg,
}

impl Run<'_> {
    pub(super) fn first_res(&self) -> (u32, u32) {
        self.cfg.resolutions[0]
    }

    pub(super) fn sweep_grid(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (cfg, data_dir, first_res) = (self.cfg, &self.data_dir, self.first_res());
        let mut log = |s: &str| println!("{s}");
        println!(
            "grid sweep ({} {} {}x{}):",
            cfg.modes[0].name(),
            cfg.accels[0].name(),
            first_res.0,
            first_res.1
        );
        let opts = RenderOptions::new(first_res.0, first_res.1, cfg.modes[0]);
        for name in &cfg.scenes {
            match scenes::build_paper_scene(name, data_dir.as_deref()) {
                Ok(bs) => {
                    let sw = studies::grid_sweep(&bs, cfg.accels[0], &opts, cfg.warmup, cfg.reps, &mut log)?;
                    println!(
                        "  {}: best {} {} {:.2} ms; automatic {} {:.2} ms",
                        sw.scene,
                        sw.best,
                        dims_str(sw.best_dims),
                        sw.best_ms,
                        dims_str(sw.auto_dims),
                        sw.auto_ms
                    );
                    report.grid_sweep.push(sw);
                }
                Err(e) => println!("  sweep: skipping {name}: {e}"),
            }
        }
        Ok(())
    }

    pub(super) fn scaling(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, first_res, gpu, run_cpu) = (
            self.a,
            self.cfg,
            &self.data_dir,
            self.first_res(),
            &self.gpu,
            self.run_cpu,
        );
        let mut log = |s: &str| println!("{s}");
        let (max_tris, sides): (usize, &[u32]) = if a.quick {
            (100_000, &[64, 128, 256])
        } else {
            (2_000_000, &[128, 256, 512, 768, 1024])
        };
        println!(
            "scaling (cast {} {}x{}):",
            cfg.accels[0].name(),
            first_res.0,
            first_res.1
        );
        // The CPU series, then the GPU's on the same meshes (the paper's study was on its GPU).
        let mut on: Vec<Option<&std::sync::Arc<GpuContext>>> = Vec::new();
        if run_cpu {
            on.push(None);
        }
        if let Some(g) = gpu.as_ref() {
            on.push(Some(g));
        }
        for g in on {
            println!("  on the {}:", if g.is_some() { "gpu" } else { "cpu" });
            let meshes = studies::scaling_meshes(data_dir.as_deref(), max_tris, &mut log);
            let sc = studies::scaling(
                meshes,
                g,
                first_res,
                sides,
                Mode::Cast,
                cfg.accels[0],
                cfg.warmup,
                cfg.reps,
                &mut log,
            )?;
            for f in &sc.fits {
                println!("  exponent {:<32} {:.3} ({} points)", f.series, f.exponent, f.points);
            }
            report.scaling.push(sc);
        }
        Ok(())
    }

    pub(super) fn build_scaling(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, gpu, backend) = (self.a, self.cfg, &self.data_dir, &self.gpu, self.backend);
        let mut log = |s: &str| println!("{s}");
        let max = if a.quick {
            a.build_max_tris.min(100_000)
        } else {
            a.build_max_tris
        };
        println!("build scaling (up to {max} triangles):");
        let meshes = studies::build_scaling_meshes(data_dir.as_deref(), max, &mut log);
        if let Some(dir) = &a.export_meshes {
            bench::build_scaling::export(&meshes, dir)?;
            println!("  wrote the meshes to {}", dir.display());
        }
        let gpu_ctx = if backend == BenchBackendArg::Cpu {
            None
        } else {
            gpu.as_ref()
        };
        let mut points = bench::build_scaling::build_scaling(&meshes, gpu_ctx, cfg.reps, &mut log)?;
        if let Some(e) = &a.embree {
            bench::build_scaling::with_embree(&mut points, e)?;
        }
        report.build_scaling = points;
        Ok(())
    }

    pub(super) fn pc_study(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (cfg, data_dir, first_res) = (self.cfg, &self.data_dir, self.first_res());
        let mut log = |s: &str| println!("{s}");
        println!("proximity-cloud study ({}x{}):", first_res.0, first_res.1);
        let far_mesh = data_dir
            .as_ref()
            .and_then(|d| gridtrace::io::load_mesh(&d.join("bunny_lowpoly/bunny_1k.obj")).ok());
        let far_name = if far_mesh.is_some() { "far-bunny" } else { "far-knot" };
        let study_scenes = vec![
            ("sparse-room".to_string(), gridtrace::scene::builtin::sparse_room()),
            (far_name.to_string(), studies::far_mesh_scene(far_mesh)),
            ("torus-knot".to_string(), gridtrace::scene::builtin::knot_box()),
        ];
        report.pc_study = studies::pc_study(
            &study_scenes,
            &[Mode::Cast, Mode::Shadow],
            first_res,
            cfg.warmup,
            cfg.reps,
            &mut log,
        )?;
        Ok(())
    }

    pub(super) fn query_study(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, gpu, run_cpu) = (self.a, self.cfg, &self.data_dir, &self.gpu, self.run_cpu);
        let mut log = |s: &str| println!("{s}");
        println!("ray-query study ({} incoherent rays per mesh):", a.query_rays);
        let mut meshes = vec![(
            "torus-knot-hi".to_string(),
            gridtrace::scene::procedural::torus_knot(2, 3, 0.16, 1024, 32),
        )];
        if let Some(d) = &data_dir {
            for (name, file) in [
                ("stanford-bunny", "bunny/bun_zipper.ply"),
                ("dragon", "dragon/dragon_vrip_binary.ply"),
            ] {
                match gridtrace::io::load_mesh(&d.join(file)) {
                    Ok(m) => meshes.push((name.to_string(), m)),
                    Err(e) => println!("  {name}: skipped ({e})"),
                }
            }
        }
        report.query_study = studies::query_study(
            &meshes,
            a.query_rays,
            run_cpu,
            gpu.as_ref(),
            cfg.warmup,
            cfg.reps,
            &mut log,
        )?;
        Ok(())
    }

    pub(super) fn irregular_sweep(&self, sets: &str, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir) = (self.a, self.cfg, &self.data_dir);
        let mut log = |s: &str| println!("{s}");
        let sweep = if sets.trim() == "default" {
            bench::irregular::default_sweep()
        } else {
            sets.split(';')
                .map(|s| s.parse::<gridtrace::accel::IrregularParams>())
                .collect::<Result<Vec<_>, _>>()
                .map_err(gridtrace::Error::InvalidInput)?
        };
        println!("irregular-grid sweep ({} incoherent rays per mesh):", a.query_rays);
        let mut meshes = Vec::new();
        for (name, scene) in bench::irregular::sweep_scenes(data_dir.as_deref()) {
            meshes.push((name, scene.prepare(Resolution::default())?.accel.tris));
        }
        report.irregular_sweep =
            bench::irregular::irregular_sweep(&meshes, a.query_rays, &sweep, cfg.warmup, cfg.reps, &mut log)?;
        Ok(())
    }

    pub(super) fn ablate(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, first_res, gpu, run_cpu) = (
            self.a,
            self.cfg,
            &self.data_dir,
            self.first_res(),
            &self.gpu,
            self.run_cpu,
        );
        let mut log = |s: &str| println!("{s}");
        println!("ablations ({}x{}):", first_res.0, first_res.1);
        let plan = bench::ablation::AblationPlan {
            scenes: &cfg.scenes,
            data_dir: data_dir.as_deref(),
            grid: cfg.grid,
            paper_grids: cfg.paper_grids,
            size: first_res,
            modes: &cfg.modes,
            accels: &cfg.accels,
            ablations: &a.ablate,
            cpu: run_cpu,
            gpu: gpu.as_ref(),
            warmup: cfg.warmup,
            reps: cfg.reps,
        };
        report.ablation = bench::ablation::ablation_study(&plan, &mut log)?;
        Ok(())
    }

    /// Writes the rays (and hits) of one frame of the first scene, for other tracers to run.
    pub(super) fn export_rays(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, first_res) = (self.a, self.cfg, &self.data_dir, self.first_res());
        let mode = [Mode::Trace, Mode::Shadow, Mode::Cast]
            .into_iter()
            .find(|m| cfg.modes.contains(m))
            .unwrap_or(Mode::Cast);
        let name = &cfg.scenes[0];
        let bs = scenes::build_paper_scene(name, data_dir.as_deref())?;
        let prepared = bs
            .scene
            .prepare_for(cfg.accels[0], &bs.params_for(cfg.accels[0], cfg.paper_grids, cfg.grid))?;
        let opts = RenderOptions::new(first_res.0, first_res.1, mode);
        let set = bench::rays::collect_rays(&prepared, &opts)?;
        let c = set.counts();
        if let Some(p) = &a.export_rays {
            set.write_rays(p)?;
        }
        if let Some(p) = &a.export_hits {
            set.write_hits(p)?;
        }
        let hits = set.records.iter().filter(|r| r.t.is_finite()).count() as u64;
        println!(
            "exported {} rays of {name} {} {} {}x{} (eye {}, shadow {}, reflection {}; {hits} with a hit)",
            c.total(),
            mode.name(),
            cfg.accels[0].name(),
            opts.width,
            opts.height,
            c.eye,
            c.shadow,
            c.reflection
        );
        report.ray_export = Some(studies::RayExport {
            scene: name.clone(),
            mode: mode.name().into(),
            accel: cfg.accels[0].name().into(),
            width: opts.width,
            height: opts.height,
            rays_file: a.export_rays.as_ref().map(|p| p.display().to_string()),
            hits_file: a.export_hits.as_ref().map(|p| p.display().to_string()),
            eye: c.eye,
            shadow: c.shadow,
            reflection: c.reflection,
            hits,
        });
        Ok(())
    }

    /// The reports, the charts, and one ray-traced picture per scene that ran.
    pub(super) fn write_out(&self, dir: &std::path::Path, report: &BenchReport) -> gridtrace::Result<()> {
        let (cfg, data_dir, first_res) = (self.cfg, &self.data_dir, self.first_res());
        let mut files = bench::report::write_reports(report, dir)?;
        files.extend(bench::charts::write_charts(report, dir)?);
        // One ray-traced picture per scene that ran, to see what was measured.
        for s in &report.matrix.scenes {
            let bs = scenes::build_paper_scene(&s.name, data_dir.as_deref())?;
            let prepared = bs.scene.prepare(bs.resolution(cfg.paper_grids, cfg.grid))?;
            let opts = RenderOptions::new(first_res.0, first_res.1, Mode::Trace);
            let (image, _) = gridtrace::cpu::render(&prepared, &opts, None)?;
            let path = dir.join(format!("scene_{}.png", s.name));
            image.save_png(&path)?;
            files.push(path);
        }
        for f in files {
            println!("wrote {}", f.display());
        }
        Ok(())
    }
}
