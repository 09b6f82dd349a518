//! `garmentbake train`: unsupervised PBNS training of a garment on a body and motion clips.

use super::args::{output_set, short_help, OutputArgs, TrainInputs, Writes, MODEL, NO_IDS};
use super::args::{SHORT_HELP_NOTE, TRAIN_DEFAULTS, TRAIN_SHORT_HIDES};
use super::Execute;
use crate::models::file::EpochRecord;
use crate::train::pbns::{PhaseSplit, Trainer};
use crate::train::poses::{count, PoseKind};
use crate::train::{fit_every, CheckpointEvery, FitOptions, Fitted, Training};
use anyhow::Result;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Train a PBNS garment model: MLP over the pose → PSD blend shapes → linear blend skinning,
/// minimising a physical potential (stretch, bending, body collision, gravity, pinning), no
/// simulation data needed.
///
/// Poses are taken from the clips (retargeted onto the body), balanced (a frame is kept only if
/// it differs enough from every kept one in the joints that move the garment) and split 85/15
/// into train / validation (held-out frames of the training clips). Judge the model with
/// `garmentbake eval` on other clips: a clip used to choose settings (epochs, fabric, width) is a
/// validation clip; only a clip used for nothing is a test clip. The model file (.safetensors) is self-contained:
/// `garmentbake eval`, `bake` and `inspect` need nothing else. A checkpoint with the optimizer
/// state is written next to it (NAME.ckpt.safetensors) on `--checkpoint-every` and after the last
/// epoch; `--resume` continues from it exactly as if the run had not stopped (with the same
/// `--epochs`: the learning-rate schedule spans them).
///
/// The report ends with where the wall time went: optimisation steps (and their split into
/// forward, losses, nearest neighbour, backward), validation, candidate refresh, checkpoints,
/// logging; `--log` has the same per epoch.
#[derive(clap::Args)]
#[command(after_help = SHORT_HELP_NOTE)]
#[command(mut_args(short_help(TRAIN_SHORT_HIDES, NO_IDS)))]
pub struct Args {
    #[command(flatten)]
    pub inputs: TrainInputs,
    /// Epochs (passes over the training poses).
    #[arg(long, default_value_t = TRAIN_DEFAULTS.epochs, help_heading = "Training")]
    pub epochs: usize,
    /// Output model (.safetensors).
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    /// Continue from OUT's checkpoint (same inputs and settings) up to --epochs.
    #[arg(long, help_heading = "Training")]
    pub resume: bool,
    /// Write the checkpoint after this many epochs (50), this much wall time (300s, 5m) or
    /// whichever comes first (50,5m).
    ///
    /// Always after the last epoch too. A checkpoint of a wide model holds tens of MB of
    /// optimizer state, so writing one every epoch costs real time.
    #[arg(
        long,
        default_value = "5m",
        value_name = "EPOCHS|SECONDSs|MINUTESm",
        help_heading = "Training"
    )]
    pub checkpoint_every: CheckpointEvery,
    /// Treat input warnings (garment inside the body, bad faces) as errors.
    #[arg(long, help_heading = "Inputs")]
    pub strict: bool,
    /// Append one JSON object per epoch (loss terms, metrics, learning rate, seconds) to this file.
    #[arg(long, help_heading = "Outputs")]
    pub log: Option<PathBuf>,
    /// Early stopping: stop once this many epochs pass without a lower validation loss.
    ///
    /// The validation loss is the training potential on the held-out poses, computed every
    /// --validate-every epochs; the best validated epoch's weights are written as OUT. The
    /// learning-rate schedule still spans --epochs, so a run that stops early stops at a higher
    /// rate than the schedule's end.
    #[arg(long, value_name = "EPOCHS", value_parser = clap::value_parser!(u64).range(1..), help_heading = "Training")]
    pub patience: Option<u64>,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// What `train` did.
#[derive(Serialize, Deserialize)]
pub struct Report {
    #[serde(flatten)]
    pub fitted: Fitted,
    /// Balanced real poses for training and validation, recombined extra ones, frames read.
    pub poses_train: usize,
    pub poses_recombined: usize,
    /// Generated poses whose garment joints were drawn across their widened ranges.
    pub poses_sampled: usize,
    pub poses_validation: usize,
    /// The pose distance beyond which eval and bake report a frame as outside the trained range.
    pub coverage_threshold: f32,
    pub frames_seen: usize,
    pub warnings: Vec<String>,
    pub last: Option<EpochRecord>,
    /// The validated epoch with the lowest validation loss, and that loss; with --patience the
    /// model holds this epoch's weights.
    pub best_epoch: Option<usize>,
    pub best_validation_loss: Option<f64>,
    pub phases: PhaseSplit,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        // Checked before the training; the trainer writes the model (and its checkpoints)
        // atomically itself, as it goes.
        let _checked = output_set(&[
            ("--out", Some(&self.out), MODEL),
            ("--log", self.log.as_deref(), Writes::Any),
        ])?;
        let (inputs, mut settings, warnings) = self.inputs.load(self.epochs, self.strict)?;
        settings.patience = self.patience.map(|p| p as usize);
        for w in &warnings {
            if !self.output.json {
                eprintln!("warning: {w}");
            }
        }
        let mut trainer = Trainer::new(inputs, settings)?;
        if self.resume {
            trainer.resume(&crate::train::checkpoint_path(&self.out))?;
        }
        say_poses(&trainer, say);
        if trainer.epochs_done() > 0 {
            say(&format!("resuming after epoch {}", trainer.epochs_done()));
        }
        let opts = FitOptions {
            epochs: self.epochs,
            out: &self.out,
            hide_bar: self.output.json,
            log: self.log.as_deref(),
        };
        let fitted = fit_every(&mut trainer, &opts, self.checkpoint_every)?;
        let p = &trainer.poses;
        Ok(Report {
            fitted,
            poses_train: count(&p.train, PoseKind::Clip),
            poses_recombined: count(&p.train, PoseKind::Recombined),
            poses_sampled: count(&p.train, PoseKind::Sampled),
            poses_validation: p.validation.len(),
            coverage_threshold: trainer.info().training.beyond_range(),
            frames_seen: p.frames_seen,
            warnings,
            last: trainer.info().history.last().cloned(),
            best_epoch: trainer.best().map(|b| b.0),
            best_validation_loss: trainer.best().map(|b| b.1),
            phases: trainer.times().split(),
        })
    }

    fn print(r: &Report) {
        if let Some(e) = &r.last {
            let t = &e.train;
            println!(
                "epoch {}: train edge {:.3} mm, bend {:.4}, collided {:.2} %, gravity {:.4} J",
                e.epoch, t.edge_mm, t.bend, t.collided_pct, t.gravity_j
            );
            if let Some(v) = &e.validation {
                println!(
                    "validation ({} held-out poses of the training clips): edge {:.3} mm, bend {:.4}, collided {:.2} %, gravity {:.4} J",
                    r.poses_validation, v.edge_mm, v.bend, v.collided_pct, v.gravity_j
                );
            }
            if let Some(l) = e.validation_loss {
                println!("validation loss {l:.6} (training loss {:.6})", e.loss);
            }
        }
        if let Some(why) = &r.fitted.stopped_early {
            println!("stopped early after epoch {}: {why}", r.fitted.epochs);
        } else if let (Some(e), Some(l)) = (r.best_epoch, r.best_validation_loss) {
            println!("lowest validation loss {l:.6} at epoch {e}");
        }
        println!("{}", r.phases);
        println!("{}", r.fitted.wall);
        println!(
            "wrote {} ({:.0} s); {} checkpoint(s), the last after epoch {}: {}",
            r.fitted.out.display(),
            r.fitted.seconds,
            r.fitted.checkpoints,
            r.fitted.checkpoint_epoch,
            r.fitted.checkpoint.display()
        );
    }
}

/// The pose set and the weight initialisation, before the (long) training starts.
fn say_poses(trainer: &Trainer, say: &dyn Fn(&str)) {
    let p = &trainer.poses;
    let names: Vec<&str> = p
        .joints
        .iter()
        .map(|&j| trainer.file.body.skeleton.joint_names[j].as_str())
        .collect();
    let real = count(&p.train, PoseKind::Clip);
    let thinned = if p.balanced > real + p.validation.len() {
        format!(" (thinned from {} by --pose-budget)", p.balanced)
    } else {
        String::new()
    };
    say(&format!(
        "poses: {} balanced{thinned} of {} frames ({real} train + {} recombined + {} range-sampled, {} validation; threshold {} rad on {})",
        real + p.validation.len(),
        p.frames_seen,
        count(&p.train, PoseKind::Recombined),
        count(&p.train, PoseKind::Sampled),
        p.validation.len(),
        trainer.settings.pose_threshold,
        names.join(", ")
    ));
    let t = &trainer.info().training;
    say(&format!(
        "coverage threshold {:.3} rad: {:.0} % of the training clips' frames lie within it of the poses taken from the clips' other parts (eval and bake report frames beyond it)",
        t.beyond_range(),
        crate::train::poses::COVERAGE_PERCENTILE * 100.0
    ));
    if t.inpainted > 0 {
        say(&format!(
            "initial weights: {} of {} vertices hang farther than {} m from the body: inpainted",
            t.inpainted,
            trainer.model().shape.vertices,
            t.inpaint_beyond.unwrap_or_default()
        ));
    }
}
