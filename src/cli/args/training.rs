//! The training flags `train` and `bench train` share, and their conversion into the trainer's
//! inputs and settings.

use super::{non_negative, positive, ClipArgs, ComputeArgs, FabricArgs};
use crate::train::pbns::{set_training_threads, InputFiles, Inputs, RefreshMode, Settings};
use anyhow::{bail, Result};
use std::path::PathBuf;

/// The documented training defaults, shared with the library (`Settings::DEFAULT`).
pub const TRAIN_DEFAULTS: Settings = Settings::DEFAULT;

/// The flags (ids) of [`TrainInputs`] that `-h` leaves out besides the Advanced ones, for
/// [`super::short_help`]: the clips' axis and unit (detected), and the finer training settings
/// (`--help` shows them).
pub const TRAIN_SHORT_HIDES: [&str; 11] = [
    "up",
    "units",
    "influences",
    "fixed_weights",
    "pose_threshold",
    "pose_budget",
    "recombine",
    "coverage",
    "weights_lr_scale",
    "inpaint_beyond",
    "no_inpaint",
];

/// Inputs and settings shared by `train` and `bench train`.
#[derive(clap::Args)]
pub struct TrainInputs {
    /// Skinned body (glTF/glb); metres, Y-up.
    #[arg(long, help_heading = "Inputs")]
    pub body: PathBuf,
    /// Garment mesh in the body's rest pose: OBJ, or USD with one Mesh prim (.usd/.usda/.usdc/.usdz,
    /// converted to metres, Y-up); sidecar NAME.toml: pinned vertices.
    #[arg(long, help_heading = "Inputs")]
    pub garment: PathBuf,
    /// The training clips (BVH): the poses come from them.
    #[command(flatten)]
    pub clips: ClipArgs,
    #[command(flatten)]
    pub fabric: FabricArgs,
    /// Seed: same seed and inputs → byte-identical model.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.seed, help_heading = "Training")]
    pub seed: u64,
    #[command(flatten)]
    pub compute: ComputeArgs,
    /// Poses per optimisation step.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.batch, help_heading = "Training")]
    pub batch: usize,
    /// Initial Adam learning rate (cosine decay to a tenth).
    #[arg(long, default_value_t = TRAIN_DEFAULTS.learning_rate, value_parser = positive::<f64>(), help_heading = "Training")]
    pub lr: f64,
    /// MLP width = number of PSD blend shapes.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.width, help_heading = "Training")]
    pub width: usize,
    /// Skin influences per vertex (4 or 8), fixed at initialisation.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.influences, help_heading = "Training")]
    pub influences: usize,
    /// Keep the proximity blend weights instead of optimising them.
    #[arg(long, help_heading = "Training")]
    pub fixed_weights: bool,
    /// Pose balancing threshold (radians, per rotation component of the garment's joints).
    #[arg(long, default_value_t = TRAIN_DEFAULTS.pose_threshold, value_parser = non_negative::<f32>(), help_heading = "Training")]
    pub pose_threshold: f32,
    /// At most this many balanced clip poses (train + validation). Many clips balance to
    /// thousands; beyond the budget the poses are thinned farthest first (each kept pose the one
    /// farthest from those already kept), which keeps rare poses and drops repeats of common ones.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.pose_budget, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(2..), help_heading = "Training")]
    pub pose_budget: usize,
    /// Extra training poses per balanced one, each taking every limb chain (legs, spine, neck and
    /// head, arms) from a different real frame: covers pose combinations the clips lack.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.recombine, help_heading = "Training")]
    pub recombine: usize,
    /// Pose coverage: generated training poses per balanced real one (0 turns it off). Half
    /// recombine limb chains of real frames (bent up to 30 % further), half draw about half of the
    /// garment's joints (hips, knees, spine, ...) uniformly across the rotation range the clips
    /// show, widened by 30 % of it on each side: wide stances, knee raises and deep bends the
    /// clips do not combine. The real poses stay in, so common poses keep their accuracy.
    #[arg(
        long,
        default_value_t = TRAIN_DEFAULTS.coverage,
        value_name = "PER_REAL_POSE",
        value_parser = non_negative::<f32>(),
        help_heading = "Training"
    )]
    pub coverage: f32,
    /// Epochs between refreshes of the nearest-body-vertex candidates.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.refresh_every, help_heading = "Advanced")]
    pub refresh_every: usize,
    /// How candidates are refreshed: trees (CPU k-d trees on a worker thread), device (brute
    /// force with cdist + topk on the training device), auto (device on CUDA, else trees).
    #[arg(long, value_enum, default_value = "auto", help_heading = "Advanced")]
    pub refresh: RefreshArg,
    /// Candidate body vertices kept per garment vertex.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.candidates, help_heading = "Advanced")]
    pub candidates: usize,
    /// Learning rate of the blend-weight logits relative to --lr.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.weights_lr_scale, value_parser = non_negative::<f64>(), help_heading = "Training")]
    pub weights_lr_scale: f64,
    /// Initial blend weights: copy the body's within this distance (metres) of it at rest and
    /// interpolate them smoothly over the garment beyond (a skirt's hanging part).
    #[arg(long, default_value_t = TRAIN_DEFAULTS.inpaint_beyond.unwrap(), value_parser = non_negative::<f32>(), help_heading = "Training")]
    pub inpaint_beyond: f32,
    /// Copy the body's weights by proximity everywhere (no inpainting).
    #[arg(long, help_heading = "Training")]
    pub no_inpaint: bool,
    /// Epochs between validation passes (exact metrics on the held-out poses).
    #[arg(long, default_value_t = TRAIN_DEFAULTS.validate_every, help_heading = "Advanced")]
    pub validate_every: usize,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum RefreshArg {
    Auto,
    Trees,
    Device,
}

impl TrainInputs {
    /// Reads everything and builds the settings; warnings (garment fit) come back as lines.
    pub fn load(&self, epochs: usize, strict: bool) -> Result<(Inputs, Settings, Vec<String>)> {
        set_training_threads(self.compute.threads);
        let reader = self.clips.clips().reader()?;
        let files = InputFiles {
            body: &self.body,
            garment: &self.garment,
            motions: &self.clips.motion.motions,
            reader: &reader,
            fps: self.clips.fps,
            fabric: &self.fabric.fabric,
        };
        if !(self.coverage.is_finite() && self.coverage >= 0.0) {
            bail!(
                "--coverage must be 0 or more generated poses per real one, not {}",
                self.coverage
            );
        }
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
            pose_budget: self.pose_budget,
            recombine: self.recombine,
            coverage: self.coverage,
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
