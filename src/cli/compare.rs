//! `garmentbake compare`: caches of one clip against perturbed simulations of it, measured so
//! that dynamics show (library: src/compare.rs).

use super::args::{output_set, ClipArgs, CollisionFixArgs, ComputeArgs, OutputArgs, PNG};
use super::Execute;
use crate::compare::{compare, Cache, Inputs, Report, Settings};
use crate::garment::Garment;
use crate::io::gltf_body::read_body;
use crate::io::point_cache::read_pc2;
use crate::models::file::check_skeleton;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// Compare garment caches of one clip (a dynamic roll-out, PBNS, plain LBS, another simulation)
/// against three or more perturbed simulations of it (`simulate --perturb 0/1/2`).
///
/// Whole-clip distance to one run of a chaotic simulation is won by a blurred average that no
/// run shows. This reports, per cache: the RMS error against the runs beside their spread σ
/// (half the mean squared distance between two runs) and the cache's own error
/// b = √(mean_i MSE(cache, run_i) − σ²) (a re-run of the simulator scores b ≈ σ, the runs' mean
/// garment 0); the error k = 1 … --horizon frames after a restart, e(k), beside the runs' own
/// divergence (a dynamic model given by --model is restarted from each run's state every
/// --restart-every frames; other caches' e(k) is their error at those frames); the hem (the
/// garment's lowest boundary loop) in the waist frame beyond the --baseline cache (PBNS: what
/// the pose alone gives), per-vertex time mean removed: correlation with the runs (their mutual
/// correlation is the ceiling), amplitude ratio, lag behind the pelvis' velocity, power
/// spectrum; and strain mean / p99, inside the body, jitter. See docs/dynamic.md.
#[derive(clap::Args)]
pub struct Args {
    /// Skinned body (glTF/glb) the caches were played on.
    #[arg(long)]
    pub body: PathBuf,
    /// The garment (OBJ or USD) the caches play; its lowest boundary loop is the hem.
    #[arg(long)]
    pub garment: PathBuf,
    /// The clip (one --motion), at the caches' rate (--fps).
    #[command(flatten)]
    pub clips: ClipArgs,
    /// A simulation of the clip (PC2); give two or more, three or more for a ceiling.
    #[arg(long = "sim", value_name = "SIM.pc2")]
    pub sims: Vec<PathBuf>,
    /// A cache to compare, named: NAME=PATH.pc2 (repeat).
    #[arg(long = "cache", value_name = "NAME=CACHE.pc2")]
    pub caches: Vec<String>,
    /// The dynamic model that played a cache, NAME=MODEL.safetensors: e(k) restarts it from each
    /// simulation's state instead of reading the cache.
    #[arg(long = "model", value_name = "NAME=MODEL")]
    pub models: Vec<String>,
    /// The quasi-static cache (by NAME) the hem's swing is measured beyond; without it, the
    /// hem's motion in the waist frame as it is.
    #[arg(long, value_name = "NAME")]
    pub baseline: Option<String>,
    /// Compare only the clip's first N frames (caches of the whole clip or of N frames).
    #[arg(long)]
    pub frames: Option<usize>,
    /// e(k) for k = 1 … N frames.
    #[arg(long, default_value_t = 50)]
    pub horizon: usize,
    /// Restarts at frames 0, N, 2N, … (each followed by --horizon frames).
    #[arg(long, default_value_t = 50)]
    pub restart_every: usize,
    /// The hem's lag behind the pelvis is looked for within ± this many seconds.
    #[arg(long, default_value_t = 1.0, value_parser = super::args::positive::<f32>())]
    pub max_lag: f32,
    /// Also score the simulations' vertex-wise mean garment (as `runs-mean`): the blurred
    /// average that wins whole-clip distance without being a garment, for scale.
    #[arg(long)]
    pub with_mean: bool,
    /// Draw e(k) beside the simulations' divergence (PNG).
    #[arg(long, value_name = "PNG")]
    pub plot_horizon: Option<PathBuf>,
    /// Draw the hem's swing over time and its spectrum (PNG).
    #[arg(long, value_name = "PNG")]
    pub plot_hem: Option<PathBuf>,
    /// Restarted models play without the per-frame collision fix.
    #[arg(long)]
    pub no_collision_fix: bool,
    #[command(flatten)]
    pub collision: CollisionFixArgs,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// `NAME=PATH` of `flag`.
fn named<'a>(flag: &str, text: &'a str) -> Result<(&'a str, &'a Path)> {
    match text.split_once('=') {
        Some((name, path)) if !name.is_empty() && !path.is_empty() => Ok((name, Path::new(path))),
        _ => bail!("{flag} {text}: give NAME=PATH"),
    }
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        // Checked before the work; each plot is written atomically as it is drawn.
        let _checked = output_set(&[
            ("--plot-horizon", self.plot_horizon.as_deref(), PNG),
            ("--plot-hem", self.plot_hem.as_deref(), PNG),
        ])?;
        if self.sims.len() < 2 {
            bail!(
                "--sim: give two or more simulations of the clip (got {}; e.g. simulate --perturb 0, 1, 2)",
                self.sims.len()
            );
        }
        if self.restart_every == 0 {
            bail!("--restart-every 0: give a number of frames of 1 or more");
        }
        if !(self.max_lag.is_finite() && self.max_lag >= 0.0) {
            bail!(
                "--max-lag {}: give a non-negative number of seconds",
                self.max_lag
            );
        }
        let names: Vec<(&str, &Path)> = self
            .caches
            .iter()
            .map(|c| named("--cache", c))
            .collect::<Result<_>>()?;
        for (i, (name, _)) in names.iter().enumerate() {
            if self.with_mean && *name == crate::compare::RUNS_MEAN {
                bail!("--cache {name}=…: the name --with-mean gives the runs' mean garment");
            }
            if names[..i].iter().any(|(n, _)| n == name) {
                bail!("--cache {name}=…: the name is given twice");
            }
        }
        let index_of = |flag: &str, name: &str| {
            names
                .iter()
                .position(|(n, _)| *n == name)
                .with_context(|| format!("{flag} {name}: no --cache of that name"))
        };
        let baseline = self
            .baseline
            .as_deref()
            .map(|b| index_of("--baseline", b))
            .transpose()?;
        let models: Vec<(usize, &Path)> = self
            .models
            .iter()
            .map(|m| {
                let (name, path) = named("--model", m)?;
                Ok((index_of("--model", name)?, path))
            })
            .collect::<Result<_>>()?;
        let body = read_body(&self.body)?;
        let garment = Garment::read(&self.garment)?;
        let n = garment.mesh.vertex_count();
        let (motion, clip) = self.clips.load_single(&body.skeleton)?;
        let fps = clip.animation.fps;
        let clip_frames = clip.animation.frame_count();
        let played = self.frames.unwrap_or(clip_frames);
        if played < 2 || played > clip_frames {
            bail!("--frames {played}: give 2 to {clip_frames} (the clip's frames at {fps} fps)");
        }
        let poses: Vec<_> = (0..played).map(|f| clip.animation.local_pose(f)).collect();
        let read = |path: &Path| {
            let mut frames = read_pc2(path, n)?;
            if frames.len() != clip_frames && frames.len() != played {
                bail!(
                    "{}: {} frames, {} has {clip_frames} at {fps} fps (another clip or rate?)",
                    path.display(),
                    frames.len(),
                    motion.display(),
                );
            }
            frames.truncate(played);
            Ok(frames)
        };
        let sims = self
            .sims
            .iter()
            .map(|p| read(p))
            .collect::<Result<Vec<_>>>()?;
        let mut caches = names
            .iter()
            .map(|&(name, path)| {
                Ok(Cache {
                    name: name.to_string(),
                    frames: read(path)?,
                    model: None,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        for (i, path) in models {
            let (file, _) = self.compute.load_model(path)?;
            file.dynamic()
                .and_then(|d| d.motion().map(|_| ()))
                .with_context(|| {
                    format!(
                        "{}: not a dynamic model with its motion stage",
                        path.display()
                    )
                })?;
            check_skeleton(
                file.skeleton(),
                &body.skeleton,
                &self.body.display().to_string(),
            )?;
            if file.garment.vertex_count() != n {
                bail!(
                    "{}: the model's garment has {} vertices, {} has {n}",
                    path.display(),
                    file.garment.vertex_count(),
                    self.garment.display()
                );
            }
            if (file.info.dynamic()?.fps - fps).abs() > 1e-3 {
                bail!(
                    "{}: the model plays at {} fps, the clip is at {fps} (give --fps {})",
                    path.display(),
                    file.info.dynamic()?.fps,
                    file.info.dynamic()?.fps
                );
            }
            caches[i].model = Some(file);
        }
        self.compute.apply()?;
        let settings = Settings {
            horizon: self.horizon,
            restart_every: self.restart_every,
            max_lag_s: self.max_lag,
            with_mean: self.with_mean,
            rollout: self.collision.settings(!self.no_collision_fix)?,
            horizon_png: self.plot_horizon.clone(),
            hem_png: self.plot_hem.clone(),
            quiet: self.output.json,
        };
        let inputs = Inputs {
            body: &body,
            garment: &garment.mesh,
            poses: &poses,
            fps,
            simulations: &sims,
            caches: &caches,
            baseline,
        };
        compare(&inputs, &settings)
    }

    fn print(r: &Report) {
        let s = &r.spread;
        println!(
            "{} simulations, {} frames at {} fps: σ {:.1} mm over the clip ({:.1} over the first 50 frames); two runs {:.1} mm RMS apart; a run from the others' mean {:.1} mm",
            s.runs, r.frames, r.fps, s.sigma_mm.clip, s.sigma_mm.first_50, s.pairwise_rms_mm.clip, s.from_the_others_rms_mm.clip
        );
        println!("RMS vertex error, mm (first 50 frames / whole clip); own = √(RMS² − σ²): a re-run scores σ, the runs' mean 0");
        println!(
            "  {:<12} {:>15} {:>15} {:>15}",
            "cache", "RMS", "own b", "vs mean garment"
        );
        let pair = |a: f64, b: f64| format!("{a:.1} / {b:.1}");
        for c in &r.caches {
            let sc = &c.score;
            println!(
                "  {:<12} {:>15} {:>15} {:>15}",
                c.name,
                pair(sc.rms_mm.first_50, sc.rms_mm.clip),
                pair(sc.own_mm.first_50, sc.own_mm.clip),
                pair(sc.versus_mean_rms_mm.first_50, sc.versus_mean_rms_mm.clip)
            );
        }
        let at = |v: &[f64]| {
            [1usize, 10, 25, 50]
                .iter()
                .filter(|&&k| k <= v.len())
                .map(|&k| format!("{:.1}", v[k - 1]))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        println!(
            "error k = 1 / 10 / 25 / 50 frames after a restart (RMS mm, {} starts × {} runs):",
            r.starts.len(),
            s.runs
        );
        let d = &r.divergence;
        println!(
            "  simulations from a common start (frame 0, {:.1} mm apart): {}",
            d.start_mm,
            at(&d.from_the_start_mm)
        );
        println!(
            "  two runs at the same frames (√2 σ): {}; σ: {}",
            at(&d.pairwise_mm),
            at(&d.sigma_mm)
        );
        for c in &r.caches {
            println!(
                "  {}{}: {}",
                c.name,
                if c.restarted { " (restarted)" } else { "" },
                at(&c.horizon_mm)
            );
        }
        let h = &r.hem;
        let opt = |v: Option<f64>| v.map_or("—".to_string(), |x| format!("{x:.2}"));
        let lag = |l: &Option<crate::metrics::hem::Lag>| {
            l.map_or("—".to_string(), |l| {
                format!("{:+.2} s ({:+.2})", l.seconds, l.correlation)
            })
        };
        println!(
            "hem ({} vertices) in the waist frame beyond {}: the runs' swing {:.1} mm RMS, mutual correlation {} (each against the others' mean {}), lag behind the pelvis {}",
            h.vertices,
            h.baseline.as_deref().unwrap_or("nothing (no --baseline)"),
            h.amplitude_mm,
            opt(h.mutual_correlation),
            opt(h.correlation_with_the_others),
            h.runs.iter().map(|s| lag(&s.lag)).collect::<Vec<_>>().join(", ")
        );
        let spectrum = |s: &crate::metrics::hem::SpectrumSummary| {
            format!(
                "peak {:.2} Hz, centroid {:.2} Hz, {:.0} % above 1 Hz",
                s.peak_hz, s.centroid_hz, s.above_1hz_pct
            )
        };
        if let Some(first) = h.runs.first() {
            println!(
                "  the runs' spectrum (run 0): {}",
                spectrum(&first.spectrum)
            );
        }
        for c in &r.caches {
            let m = &c.hem;
            println!(
                "  {:<12} correlation with the runs' mean {}, with each {}, amplitude ratio {:.2}, lag {}, {}",
                c.name,
                opt(m.correlation_with_mean),
                opt(m.correlation_with_each),
                m.amplitude_ratio,
                lag(&m.swing.lag),
                spectrum(&m.swing.spectrum)
            );
        }
        println!("plausibility: strain mean / p99 %, inside the body %, jitter mm");
        let p = &r.simulations;
        println!(
            "  {:<12} {:.2} / {:.2}, {:.3}, {:.2}",
            "simulations",
            p.strain_mean_pct,
            p.strain_p99_pct,
            r.simulations_inside_pct,
            p.jitter_mm
        );
        for c in &r.caches {
            let p = &c.plausibility;
            println!(
                "  {:<12} {:.2} / {:.2}, {:.3}, {:.2}",
                c.name, p.strain_mean_pct, p.strain_p99_pct, c.inside_pct, p.jitter_mm
            );
        }
        for path in [&r.horizon_png, &r.hem_png].into_iter().flatten() {
            println!("wrote {}", path.display());
        }
    }
}
