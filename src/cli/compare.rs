//! `garmentbake compare`: caches of one clip against perturbed simulations of it, measured so
//! that dynamics show (library: src/pipeline/compare.rs, src/compare.rs).

use super::args::{
    output_set, short_help, ClipArgs, CollisionFixArgs, ComputeArgs, OutputArgs, NO_IDS,
};
use super::args::{PNG, SHORT_HELP_NOTE};
use super::Execute;
use crate::compare::{Report, Settings};
use crate::pipeline::compare::{run, Request};
use anyhow::{bail, Result};
use std::path::PathBuf;

/// The flags (ids) `-h` leaves out besides the Advanced ones (`--help` shows them).
pub(super) const SHORT_HIDES: [&str; 2] = ["up", "units"];

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
/// spectrum, and the correlation and amplitude per part of the swing (the hem's centroid
/// lateral, vertical, forward; its shape); and strain mean / p99, inside the body, jitter. See
/// docs/dynamic.md.
#[derive(clap::Args)]
#[command(after_help = SHORT_HELP_NOTE)]
#[command(mut_args(short_help(SHORT_HIDES, NO_IDS)))]
pub struct Args {
    /// Skinned body (glTF/glb) the caches were played on.
    #[arg(long, help_heading = "Inputs")]
    pub body: PathBuf,
    /// The garment (OBJ or USD) the caches play; its lowest boundary loop is the hem.
    #[arg(long, help_heading = "Inputs")]
    pub garment: PathBuf,
    /// The clip (one --motion), at the caches' rate (--fps).
    #[command(flatten)]
    pub clips: ClipArgs,
    /// A simulation of the clip (PC2); give two or more, three or more for a ceiling.
    #[arg(long = "sim", value_name = "SIM.pc2", help_heading = "Inputs")]
    pub sims: Vec<PathBuf>,
    /// A cache to compare, named: NAME=PATH.pc2 (repeat).
    #[arg(long = "cache", value_name = "NAME=CACHE.pc2", help_heading = "Inputs")]
    pub caches: Vec<String>,
    /// The dynamic model that played a cache, NAME=MODEL.safetensors: e(k) restarts it from each
    /// simulation's state instead of reading the cache.
    #[arg(long = "model", value_name = "NAME=MODEL", help_heading = "Inputs")]
    pub models: Vec<String>,
    /// The quasi-static cache (by NAME) the hem's swing is measured beyond; without it, the
    /// hem's motion in the waist frame as it is.
    #[arg(long, value_name = "NAME", help_heading = "Inputs")]
    pub baseline: Option<String>,
    /// Compare only the clip's first N frames (caches of the whole clip or of N frames).
    #[arg(long, help_heading = "Inputs")]
    pub frames: Option<usize>,
    /// e(k) for k = 1 … N frames.
    #[arg(long, default_value_t = 50, help_heading = "Advanced")]
    pub horizon: usize,
    /// Restarts at frames 0, N, 2N, … (each followed by --horizon frames).
    #[arg(long, default_value_t = 50, help_heading = "Advanced")]
    pub restart_every: usize,
    /// The hem's lag behind the pelvis is looked for within ± this many seconds.
    #[arg(long, default_value_t = 1.0, value_parser = super::args::positive::<f32>(), help_heading = "Advanced")]
    pub max_lag: f32,
    /// Also score the simulations' vertex-wise mean garment (as `runs-mean`): the blurred
    /// average that wins whole-clip distance without being a garment, for scale.
    #[arg(long, help_heading = "Advanced")]
    pub with_mean: bool,
    /// Draw e(k) beside the simulations' divergence (PNG).
    #[arg(long, value_name = "PNG", help_heading = "Outputs")]
    pub plot_horizon: Option<PathBuf>,
    /// Draw the hem's swing over time and its spectrum (PNG).
    #[arg(long, value_name = "PNG", help_heading = "Outputs")]
    pub plot_hem: Option<PathBuf>,
    /// Restarted models play without the per-frame collision fix.
    #[arg(long, help_heading = "Advanced")]
    pub no_collision_fix: bool,
    #[command(flatten)]
    pub collision: CollisionFixArgs,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// `NAME=PATH` of `flag`.
fn named(flag: &str, text: &str) -> Result<(String, PathBuf)> {
    match text.split_once('=') {
        Some((name, path)) if !name.is_empty() && !path.is_empty() => {
            Ok((name.to_string(), PathBuf::from(path)))
        }
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
        let c = &self.clips;
        let request = Request {
            body: self.body.clone(),
            garment: self.garment.clone(),
            clips: c.clips(),
            sims: self.sims.clone(),
            caches: self
                .caches
                .iter()
                .map(|c| named("--cache", c))
                .collect::<Result<_>>()?,
            models: self
                .models
                .iter()
                .map(|m| named("--model", m))
                .collect::<Result<_>>()?,
            baseline: self.baseline.clone(),
            frames: self.frames,
            compute: self.compute.compute(),
            settings: Settings {
                horizon: self.horizon,
                restart_every: self.restart_every,
                max_lag_s: self.max_lag,
                with_mean: self.with_mean,
                rollout: self.collision.settings(!self.no_collision_fix)?,
                horizon_png: self.plot_horizon.clone(),
                hem_png: self.plot_hem.clone(),
                hide_bar: self.output.json,
            },
        };
        run(&request)
    }

    fn print(r: &Report) {
        print!("{r}");
    }
}
