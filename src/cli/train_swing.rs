//! `garmentbake train-swing`: dynamics learnt from physics alone on top of a trained PBNS.

use super::args::{
    non_negative, output_set, positive, ClipArgs, ComputeArgs, OutputArgs, Writes, MODEL,
};
use super::Execute;
use crate::models::file::SwingEpoch;
use crate::models::swing::SwingIntegrator;
use crate::train::swing::{Inputs, Settings, SwingBasis, Trainer};
use crate::train::{fit_every, CheckpointEvery, FitOptions, Fitted};
use anyhow::Result;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Teach a trained PBNS garment to swing: lag behind the body, swing and settle after a stop,
/// learnt from physics alone (no simulation data).
///
/// The PBNS network stays as it is; a small network adds blend shapes whose weights follow the
/// motion (the root's velocity and turn, the garment joints' angular velocities over the last
/// ~0.3 s) and the garment's own last two frames. Training minimises, frame after frame, the
/// potential PBNS minimises (stretch, bending, body collision, gravity, pinning) plus inertia
/// Σ m/(2Δt²)·|x_t − 2x_{t−1} + x_{t−2}|²: an implicit Euler step of the cloth at --fps.
///
/// The result is a PBNS model file: `eval`, `bake`, `view` and `validate` take it as they take
/// PBNS, and play each clip in order from rest at the model's rate (clips are resampled to it).
/// `bake` writes the PSD and swing blend shapes with one weight track per clip.
///
///   garmentbake train-swing --from skirt.safetensors --motion a.bvh --motion b.bvh --fps 30 --out swing.safetensors
#[derive(clap::Args)]
pub struct Args {
    /// A trained PBNS model (garmentbake train); its network is kept as it is.
    #[arg(long, help_heading = "Inputs")]
    pub from: PathBuf,
    /// The training clips; played at --fps (the swing's time step).
    #[command(flatten)]
    pub clips: ClipArgs,
    /// Output model (.safetensors): the PBNS with its swing.
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    /// Append one JSON object per epoch (loss terms, inertia, swing size, seconds) to this file.
    #[arg(long, help_heading = "Outputs")]
    pub log: Option<PathBuf>,
    /// Epochs (each plays every clip in order, then one step per sequence on average).
    #[arg(long, default_value_t = Settings::recipe().epochs, help_heading = "Training")]
    pub epochs: usize,
    /// Sequences per step.
    #[arg(long, default_value_t = Settings::recipe().batch, help_heading = "Training")]
    pub batch: usize,
    /// Frames unrolled per sequence (each starts from the model's own earlier frames).
    #[arg(long, default_value_t = Settings::recipe().unroll, help_heading = "Training")]
    pub unroll: usize,
    /// Initial Adam learning rate (cosine decay).
    #[arg(long, default_value_t = Settings::recipe().learning_rate, value_parser = positive::<f64>(), help_heading = "Training")]
    pub lr: f64,
    /// Swing blend shapes (added to the PSD ones in a bake).
    #[arg(long, default_value_t = Settings::recipe().shapes, help_heading = "Training")]
    pub shapes: usize,
    /// Swing bones: the garment's copies of the N joints carrying most of its skin turn by a
    /// learnt rotation about each joint (a turn moves cloth without stretching it). `bake` cannot
    /// write them yet; eval to a point cache.
    #[arg(long, default_value_t = Settings::recipe().bones, help_heading = "Training")]
    pub bones: usize,
    /// Where the swing's blend shapes start: `turns` (a joint's share of the garment turned about
    /// it, and smooth per-axis fields) or `isometric` (the pinned garment's least-stretching
    /// smooth motions). Hidden: measured, not adopted (docs/lab/2026-12-06-isometric-swing.md).
    #[arg(long, value_enum, default_value_t = Settings::recipe().basis, hide = true)]
    pub basis: SwingBasis,
    /// How the swing's weights are stepped: `network` (the network maps the motion, the pose and
    /// the last two weights to the new ones) or `modal` (a learnt damped oscillator per blend
    /// shape, the network only drives it). Hidden: under test (docs/lab/).
    #[arg(long, value_enum, default_value_t = Settings::recipe().integrator, hide = true)]
    pub integrator: SwingIntegrator,
    /// Hidden width of the swing network.
    #[arg(long, default_value_t = Settings::recipe().width, help_heading = "Training")]
    pub width: usize,
    /// Seed: same seed and inputs → the same model.
    #[arg(long, default_value_t = 0, help_heading = "Training")]
    pub seed: u64,
    /// The garment's mass in the dynamics, times the fabric's density (1: the fabric as it is,
    /// which barely swings; 0 trains without dynamics, an ablation).
    #[arg(long, default_value_t = Settings::recipe().inertia, value_parser = non_negative::<f32>(), help_heading = "Training")]
    pub inertia: f32,
    /// Continue from OUT's checkpoint (same inputs and settings) up to --epochs.
    #[arg(long, help_heading = "Training")]
    pub resume: bool,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// What `train-swing` did.
#[derive(Serialize, Deserialize)]
pub struct Report {
    #[serde(flatten)]
    pub fitted: Fitted,
    pub frames: usize,
    pub fps: f32,
    pub last: Option<SwingEpoch>,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        let _checked = output_set(&[
            ("--out", Some(&self.out), MODEL),
            ("--log", self.log.as_deref(), Writes::Any),
        ])?;
        let (model, device) = crate::pipeline::load_model(&self.compute.compute(), &self.from)?;
        let settings = Settings {
            epochs: self.epochs,
            batch: self.batch,
            unroll: self.unroll,
            learning_rate: self.lr,
            shapes: self.shapes,
            bones: self.bones,
            basis: self.basis,
            integrator: self.integrator,
            width: self.width,
            seed: self.seed,
            inertia: self.inertia,
            fps: self.clips.fps.unwrap_or(Settings::recipe().fps),
            device,
            ..Settings::recipe()
        };
        let inputs = Inputs::read(
            model,
            &self.clips.motion.motions,
            &self.clips.clips().reader()?,
            settings.fps,
        )?;
        let mut trainer = Trainer::new(inputs, settings)?;
        if self.resume {
            crate::train::Training::resume(
                &mut trainer,
                &crate::train::checkpoint_path(&self.out),
            )?;
        }
        let (frames, starts) = trainer.frames();
        say(&format!(
            "{frames} frames at {} fps from {} clip(s); {starts} sequence starts, {} steps per epoch",
            trainer.settings.fps,
            self.clips.motion.motions.len(),
            trainer.steps_per_epoch()
        ));
        let opts = FitOptions {
            epochs: self.epochs,
            out: &self.out,
            hide_bar: self.output.json,
            log: self.log.as_deref(),
        };
        let fitted = fit_every(&mut trainer, &opts, CheckpointEvery::EPOCH)?;
        Ok(Report {
            fitted,
            frames,
            fps: trainer.settings.fps,
            last: trainer.info().history.last().cloned(),
        })
    }

    fn print(r: &Report) {
        if let Some(e) = &r.last {
            println!(
                "epoch {}: loss {:.5} (inertia {:.5}, edge {:.5}, collision {:.5}), collided {:.2} %, swing {:.1} mm RMS over {} frames at {} fps",
                e.epoch,
                e.loss,
                e.inertia,
                e.terms.edge,
                e.terms.collision,
                100.0 * e.collided,
                e.swing_rms_mm,
                r.frames,
                r.fps
            );
        }
        println!("{}", r.fitted.wall);
        println!(
            "wrote {} ({:.0} s); checkpoint {}",
            r.fitted.out.display(),
            r.fitted.seconds,
            r.fitted.checkpoint.display()
        );
    }
}
