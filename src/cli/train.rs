//! `garmentbake train`: unsupervised PBNS training of a garment on a body and motion clips.

use super::args::{ClipArgs, ComputeArgs, OutputArgs};
use super::Execute;
use crate::models::file::EpochRecord;
use crate::train::pbns::{
    set_training_threads, InputFiles, Inputs, PhaseSplit, RefreshMode, Settings, Trainer,
};
use crate::train::{fit, FitOptions, Fitted, Training};
use anyhow::Result;
use serde::Serialize;
use std::path::PathBuf;

/// The documented defaults, shared with the library (`Settings::DEFAULT`).
const D: Settings = Settings::DEFAULT;

/// Train a PBNS garment model: MLP over the pose → PSD blend shapes → linear blend skinning,
/// minimising a physical potential (stretch, bending, body collision, gravity, pinning), no
/// simulation data needed.
///
/// Poses are taken from the clips (retargeted onto the body), balanced (a frame is kept only if
/// it differs enough from every kept one in the joints that move the garment) and split 85/15
/// into train / validation (held-out frames of the training clips; judge the model on a clip it
/// never saw with `garmentbake eval`). The model file (.safetensors) is self-contained:
/// `garmentbake eval`, `bake` and `inspect` need nothing else. A checkpoint with the optimizer
/// state is written next to it every epoch (NAME.ckpt.safetensors); `--resume` continues from it.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub inputs: InputArgs,
    /// Epochs (passes over the training poses).
    #[arg(long, default_value_t = D.epochs)]
    pub epochs: usize,
    /// Output model (.safetensors).
    #[arg(long)]
    pub out: PathBuf,
    /// Continue from OUT's checkpoint (same inputs and settings) up to --epochs.
    #[arg(long)]
    pub resume: bool,
    /// Treat input warnings (garment inside the body, bad faces) as errors.
    #[arg(long)]
    pub strict: bool,
    /// Append one JSON object per epoch (loss terms, metrics, learning rate, seconds) to this file.
    #[arg(long)]
    pub log: Option<PathBuf>,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// Inputs and settings shared by `train` and `bench train`.
#[derive(clap::Args)]
pub struct InputArgs {
    /// Skinned body (glTF/glb); metres, Y-up.
    #[arg(long)]
    pub body: PathBuf,
    /// Garment mesh in the body's rest pose: OBJ, or USD with one Mesh prim (.usd/.usda/.usdc/.usdz,
    /// converted to metres, Y-up); sidecar NAME.toml: pinned vertices.
    #[arg(long)]
    pub garment: PathBuf,
    /// The training clips (BVH): the poses come from them.
    #[command(flatten)]
    pub clips: ClipArgs,
    /// Fabric: a FABRIC.toml or a preset name (cotton, silk, denim, jersey).
    #[arg(long, default_value = "cotton")]
    pub config: String,
    /// Seed: same seed and inputs → byte-identical model.
    #[arg(long, default_value_t = D.seed)]
    pub seed: u64,
    #[command(flatten)]
    pub compute: ComputeArgs,
    /// Poses per optimisation step.
    #[arg(long, default_value_t = D.batch)]
    pub batch: usize,
    /// Initial Adam learning rate (cosine decay to a tenth).
    #[arg(long, default_value_t = D.learning_rate)]
    pub lr: f64,
    /// MLP width = number of PSD blend shapes.
    #[arg(long, default_value_t = D.width)]
    pub width: usize,
    /// Skin influences per vertex (4 or 8), fixed at initialisation.
    #[arg(long, default_value_t = D.influences)]
    pub influences: usize,
    /// Keep the proximity blend weights instead of optimising them.
    #[arg(long)]
    pub fixed_weights: bool,
    /// Pose balancing threshold (radians, per rotation component of the garment's joints).
    #[arg(long, default_value_t = D.pose_threshold)]
    pub pose_threshold: f32,
    /// Extra training poses per balanced one, each taking every limb chain (legs, spine, neck and
    /// head, arms) from a different real frame: covers pose combinations the clips lack.
    #[arg(long, default_value_t = D.recombine)]
    pub recombine: usize,
    /// Epochs between refreshes of the nearest-body-vertex candidates.
    #[arg(long, default_value_t = D.refresh_every)]
    pub refresh_every: usize,
    /// How candidates are refreshed: trees (CPU k-d trees on a worker thread), device (brute
    /// force with cdist + topk on the training device), auto (device on CUDA, else trees).
    #[arg(long, value_enum, default_value = "auto")]
    pub refresh: RefreshArg,
    /// Candidate body vertices kept per garment vertex.
    #[arg(long, default_value_t = D.candidates)]
    pub candidates: usize,
    /// Learning rate of the blend-weight logits relative to --lr.
    #[arg(long, default_value_t = D.weights_lr_scale)]
    pub weights_lr_scale: f64,
    /// Initial blend weights: copy the body's within this distance (metres) of it at rest and
    /// interpolate them smoothly over the garment beyond (a skirt's hanging part).
    #[arg(long, default_value_t = D.inpaint_beyond.unwrap())]
    pub inpaint_beyond: f32,
    /// Copy the body's weights by proximity everywhere (no inpainting).
    #[arg(long)]
    pub no_inpaint: bool,
    /// Epochs between validation passes (exact metrics on the held-out poses).
    #[arg(long, default_value_t = D.validate_every)]
    pub validate_every: usize,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum RefreshArg {
    Auto,
    Trees,
    Device,
}

impl InputArgs {
    /// Reads everything and builds the settings; warnings (garment fit) come back as lines.
    pub fn load(&self, epochs: usize, strict: bool) -> Result<(Inputs, Settings, Vec<String>)> {
        set_training_threads(self.compute.threads);
        let files = InputFiles {
            body: &self.body,
            garment: &self.garment,
            motions: &self.clips.motions,
            maps: &self.clips.maps,
            fps: self.clips.fps,
            fabric: &self.config,
        };
        let (inputs, warnings) = Inputs::read(&files, strict)?;
        let settings = Settings {
            epochs,
            batch: self.batch,
            learning_rate: self.lr,
            width: self.width,
            influences: self.influences,
            train_weights: !self.fixed_weights,
            seed: self.seed,
            pose_threshold: self.pose_threshold,
            recombine: self.recombine,
            refresh_every: self.refresh_every,
            refresh: match self.refresh {
                RefreshArg::Auto => RefreshMode::Auto,
                RefreshArg::Trees => RefreshMode::Trees,
                RefreshArg::Device => RefreshMode::Device,
            },
            candidates: self.candidates.max(1),
            weights_lr_scale: self.weights_lr_scale,
            validate_every: self.validate_every,
            inpaint_beyond: (!self.no_inpaint).then_some(self.inpaint_beyond),
            device: crate::compute::parse_device(&self.compute.device)?,
            ..Settings::DEFAULT
        };
        Ok((inputs, settings, warnings))
    }
}

/// What `train` did.
#[derive(Serialize)]
pub struct Report {
    #[serde(flatten)]
    pub fitted: Fitted,
    /// Balanced real poses for training and validation, recombined extra ones, frames read.
    pub poses_train: usize,
    pub poses_recombined: usize,
    pub poses_validation: usize,
    pub frames_seen: usize,
    pub warnings: Vec<String>,
    pub last: Option<EpochRecord>,
    pub phases: PhaseSplit,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        let (inputs, settings, warnings) = self.inputs.load(self.epochs, self.strict)?;
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
            quiet: self.output.json,
            log: self.log.as_deref(),
        };
        let fitted = fit(&mut trainer, &opts)?;
        let p = &trainer.poses;
        let recombined = p.train.iter().filter(|x| x.recombined).count();
        Ok(Report {
            fitted,
            poses_train: p.train.len() - recombined,
            poses_recombined: recombined,
            poses_validation: p.validation.len(),
            frames_seen: p.frames_seen,
            warnings,
            last: trainer.info().history.last().cloned(),
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
        }
        println!("{}", r.phases);
        println!(
            "wrote {} ({:.0} s)",
            r.fitted.out.display(),
            r.fitted.seconds
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
    let recombined = p.train.iter().filter(|x| x.recombined).count();
    say(&format!(
        "poses: {} balanced of {} frames ({} train + {recombined} recombined, {} validation; threshold {} rad on {})",
        p.train.len() - recombined + p.validation.len(),
        p.frames_seen,
        p.train.len() - recombined,
        p.validation.len(),
        trainer.settings.pose_threshold,
        names.join(", ")
    ));
    let t = &trainer.info().training;
    if t.inpainted > 0 {
        say(&format!(
            "initial weights: {} of {} vertices hang farther than {} m from the body: inpainted",
            t.inpainted,
            trainer.model().shape.vertices,
            t.inpaint_beyond.unwrap_or_default()
        ));
    }
}
