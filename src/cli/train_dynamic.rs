//! `garmentbake train-dynamic`: the motion-guided dynamic model, trained on simulated clips
//! (library: src/pipeline/train_dynamic.rs).

use super::args::{output_set, short_help, ClipArgs, CollisionFixArgs, ComputeArgs, FabricArgs};
use super::args::{OutputArgs, Writes, MODEL, SHORT_HELP_NOTE};
use super::Execute;
use crate::pipeline::train_dynamic::{run, Request, Stage};
use crate::pipeline::Feedback;
use anyhow::Result;
use std::path::PathBuf;

pub use crate::pipeline::train_dynamic::Report;

/// The flags (ids) `-h` leaves out besides the Advanced ones; the collision fix's, which only the
/// hidden --rollout-fix uses, are hidden from `--help` too (both in `#[command]` below).
pub(super) const SHORT_HIDES: [&str; 5] = ["maps", "up", "units", "latent", "dynamics_history"];

/// Train the dynamic garment model on cloth simulations (`garmentbake simulate`).
///
/// Two stages, one model file:
///
/// `--stage space` (first): the generative space of garment deformations. Each simulated frame
/// is measured against body seed points in the garment's UV layout and reduced to a latent: its
/// linear path (principal components) by default, the paper's networks beside it with
/// `--epochs N`. The garment needs UVs. Needs --body and --garment.
///
/// `--stage dynamic --from SPACE.safetensors` (second): the motion stage, the space frozen. From
/// the previous garment and the body's motion to the next frame's latent: a ridge-fitted
/// integrator settled towards the pose, then the learnt dynamics fitted through its own
/// roll-outs (--dynamics-epochs). Then `garmentbake rollout` plays it.
///
/// Give each --motion its --sim cache (same order, same --fps as simulated). Judge the model with
/// --eval-motion/--eval-sim on a clip it never saw. A checkpoint is written next to --out every
/// epoch; --resume continues from it.
#[derive(clap::Args)]
#[command(after_help = SHORT_HELP_NOTE)]
#[command(mut_args(short_help(SHORT_HIDES, CollisionFixArgs::ids())))]
pub struct Args {
    /// Skinned body (glTF/glb) the simulations used (stage space).
    #[arg(long, required_if_eq("stage", "space"), help_heading = "Inputs")]
    pub body: Option<PathBuf>,
    /// Garment mesh (OBJ with UVs) the simulations used (stage space).
    #[arg(long, required_if_eq("stage", "space"), help_heading = "Inputs")]
    pub garment: Option<PathBuf>,
    /// Stage dynamic: the model whose trained space the motion encoder builds on.
    #[arg(long, required_if_eq("stage", "dynamic"), help_heading = "Inputs")]
    pub from: Option<PathBuf>,
    #[command(flatten)]
    pub clips: ClipArgs,
    /// The simulated garment of each --motion (.pc2 from `garmentbake simulate`), in order.
    #[arg(long = "sim", required = true, help_heading = "Inputs")]
    pub sims: Vec<PathBuf>,
    /// Stage to train.
    #[arg(long, value_enum, default_value = "space", help_heading = "Training")]
    pub stage: Stage,
    /// Network size: cpu (64² map, 128 seeds, ≤ 256 channels) or paper (128², 581, 1024: a GPU).
    #[arg(long, default_value = "cpu", help_heading = "Training")]
    pub preset: String,
    /// Latent size (the preset's 64 when not given): the linear path starts as this many
    /// principal components of the training frames.
    #[arg(long, help_heading = "Training")]
    pub latent: Option<usize>,
    /// Stage space: initial kernel radius of the seed skinning (mm, every body part; learnt
    /// from there). Small: each garment vertex follows its nearest few seeds (a skirt's hem
    /// follows the thighs); large: it blends the seeds over a wider patch (the hem moves with
    /// the hips and both legs at once).
    #[arg(long, default_value_t = 50.0, value_parser = super::args::positive::<f64>(), help_heading = "Advanced")]
    pub kernel_radius_mm: f64,
    #[command(flatten)]
    pub fabric: FabricArgs,
    /// Epochs of the networks beside the linear paths; 0, the recipe: the linear paths alone.
    #[arg(long, default_value_t = 0, help_heading = "Training")]
    pub epochs: usize,
    /// Frames per optimisation step (space 4, dynamic 8).
    #[arg(long, help_heading = "Advanced")]
    pub batch: Option<usize>,
    /// Initial Adam learning rate, cosine decay to a tenth (space 3e-4, dynamic 1e-3).
    #[arg(long, value_parser = super::args::positive::<f64>(), help_heading = "Advanced")]
    pub lr: Option<f64>,
    /// Stage dynamic: pull of the fitted latent integrator towards keeping the previous latent,
    /// relative to each input's own spread (the garment going on at its own velocity, the body
    /// moving under it, the state itself); stronger is steadier over long roll-outs, weaker
    /// follows the simulation closer one step ahead.
    #[arg(long, default_value_t = 0.01, value_parser = super::args::non_negative::<f64>(), help_heading = "Advanced")]
    pub ridge: f64,
    /// Stage dynamic: rounds of roll-out-aware fitting. Each round rolls the model out over the
    /// training clips (no collision fix) and refits the latent integrator on those self-made
    /// histories too, with the simulation as the target, so that it learns to pull its own
    /// drift back (teacher forcing alone never shows it a drifted history). One round costs one
    /// roll-out of all training frames. 0: the teacher-forced fit alone (closest one step ahead).
    /// Default: 0 when settling towards the pose (it keeps roll-outs stable by itself), 3 with
    /// --no-pose-settle.
    #[arg(long, value_name = "N", help_heading = "Advanced")]
    pub rollout_rounds: Option<usize>,
    /// Stage dynamic: settling time towards the pose, in seconds (not in the paper).
    ///
    /// The integrator's prediction is blended with the garment the body's pose alone predicts (a
    /// ridge regression on the simulated frames), so whatever the history carries — a simulated
    /// start, a swing, a drift — fades to 1/e in this time: roll-outs follow a known start for
    /// the first frames and cannot run away over long shots. Longer: more of the history's
    /// motion kept, more room to drift; 0: the pose alone. The regression's ridge is chosen
    /// leaving one training clip out, and the output says how much of a left-out clip's latents
    /// it explains (0.3 % on the 26-take set: in practice the mean garment, the pose acting
    /// through the space's skinning). Implies --body-drive.
    #[arg(long, default_value_t = 1.0, value_name = "SECONDS", value_parser = super::args::non_negative::<f64>(), help_heading = "Training")]
    pub pose_settle: f64,
    /// Stage dynamic: no settling, the paper's integrator alone (with --rollout-rounds 3 by
    /// default to keep it stable).
    #[arg(long, conflicts_with = "pose_settle", help_heading = "Training")]
    pub no_pose_settle: bool,
    /// Stage dynamic, settling: the pose regression's ridge, relative to each pose input's mean
    /// square. Default: the one of 1e-3, 0.01, 0.1, 1, 10 whose fit on all training clips but
    /// one best predicts the clip left out (one clip: its halves).
    #[arg(long, value_name = "R", value_parser = super::args::non_negative::<f64>(), help_heading = "Advanced")]
    pub pose_ridge: Option<f64>,
    /// Stage dynamic: the rounds' roll-outs run the collision fix, as `rollout` plays the
    /// model, so the integrator is refitted on the histories it meets at play time (the fix
    /// makes a round ~3× slower).
    #[arg(long, hide = true)]
    pub rollout_fix: bool,
    /// Stage dynamic: the rounds' roll-outs restart every N frames from the simulation's
    /// moving state there, instead of running each whole clip from its first frame: the
    /// integrator is then refitted on histories that drifted for up to N frames (the states it
    /// meets near the simulation) rather than on ones far from any simulated state. 0: whole
    /// clips.
    #[arg(long, default_value_t = 0, value_name = "N", hide = true)]
    pub rollout_window: usize,
    /// With --rollout-fix: the fix as `rollout` runs it (hidden with it).
    #[command(flatten)]
    pub collision: CollisionFixArgs,
    /// Stage dynamic (not in the paper): feed the latent integrator the body drive too — the
    /// local rotations of the joints that move the garment, their speed, the root's velocity
    /// and turn. Without it the integrator sees the body only through the garment it carries,
    /// as in the paper. On whenever settling (the default); see docs/dynamic.md.
    #[arg(long, hide = true)]
    pub body_drive: bool,
    /// Stage dynamic, with --body-drive: ridge penalty on the drive's weights, relative to each
    /// drive input's own mean square (stronger: the drive nudges the integrator instead of
    /// steering it).
    #[arg(long, default_value_t = 1.0, value_parser = super::args::non_negative::<f64>(), hide = true)]
    pub drive_ridge: f64,
    /// Stage dynamic (not in the paper): epochs of the learnt latent dynamics.
    ///
    /// A small network beside the linear integrator, fitted through the model's own roll-outs of
    /// the training clips (windows growing from --unroll-frames' first to its last length, noise
    /// on each window's start; loss: decoded mm and velocity). 0: the linear integrator alone.
    /// Its last layer starts at zero, so it only adds what the roll-outs teach it. Default: 40
    /// (the recipe) with --epochs 0, else 0 (it needs the linear paths).
    #[arg(long, value_name = "N", help_heading = "Training")]
    pub dynamics_epochs: Option<usize>,
    /// Stage dynamic, with --dynamics-epochs: hidden layer widths of the learnt dynamics.
    #[arg(long, value_delimiter = ',', value_name = "W,W")]
    #[arg(default_value = "128,128", help_heading = "Advanced")]
    pub dynamics_widths: Vec<usize>,
    /// Stage dynamic, with --dynamics-epochs: window length of the roll-outs it is fitted
    /// through, at the first and the last epoch (frames).
    #[arg(long, value_delimiter = ',', value_name = "FIRST,LAST")]
    #[arg(default_value = "8,32", help_heading = "Advanced")]
    pub unroll_frames: Vec<usize>,
    /// Stage dynamic, with --dynamics-epochs: noise on each window's starting latent, in units
    /// of the training latents' spread.
    #[arg(long, default_value_t = 0.05, value_parser = super::args::non_negative::<f64>(), help_heading = "Advanced")]
    pub dynamics_noise: f64,
    /// Stage dynamic, with --dynamics-epochs: past frames of the body's motion (root and joint
    /// rotations and their speeds, as the body drive has them) the learnt dynamics also see,
    /// so a swing can answer the body's acceleration (8: 0.27 s at 30 fps, the measured recipe
    /// of docs/dynamic.md). 0: the current frame's alone.
    #[arg(long, default_value_t = 8, value_name = "FRAMES")]
    #[arg(help_heading = "Training")]
    pub dynamics_history: usize,
    /// Stage dynamic: channels of the motion features `E_t`.
    #[arg(long, default_value_t = 16, help_heading = "Advanced")]
    pub motion_features: usize,
    /// Seed: same seed and inputs → the same model.
    #[arg(long, default_value_t = 0, help_heading = "Training")]
    pub seed: u64,
    /// A clip held out from training and its simulation: reconstruction error reported on it.
    #[arg(long, requires = "eval_sim", help_heading = "Inputs")]
    pub eval_motion: Option<PathBuf>,
    /// The simulation of --eval-motion (.pc2).
    #[arg(long, requires = "eval_motion", help_heading = "Inputs")]
    pub eval_sim: Option<PathBuf>,
    /// Output model (.safetensors).
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    /// Continue from OUT's checkpoint up to --epochs.
    #[arg(long, help_heading = "Outputs")]
    pub resume: bool,
    /// Append one JSON object per epoch to this file.
    #[arg(long, help_heading = "Outputs")]
    pub log: Option<PathBuf>,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        // Checked first; the trainer writes the model and its checkpoints atomically itself.
        let _checked = output_set(&[
            ("--out", Some(&self.out), MODEL),
            ("--log", self.log.as_deref(), Writes::Any),
        ])?;
        let request = Request {
            stage: self.stage,
            body: self.body.clone(),
            garment: self.garment.clone(),
            from: self.from.clone(),
            clips: self.clips.clips(),
            sims: self.sims.clone(),
            preset: self.preset.clone(),
            latent: self.latent,
            kernel_radius_mm: self.kernel_radius_mm,
            fabric: self.fabric.fabric.clone(),
            epochs: self.epochs,
            batch: self.batch,
            lr: self.lr,
            ridge: self.ridge,
            rollout_rounds: self.rollout_rounds,
            pose_settle: (!self.no_pose_settle).then_some(self.pose_settle),
            pose_ridge: self.pose_ridge,
            rounds_fix: self.collision.settings(self.rollout_fix)?,
            rollout_window: self.rollout_window,
            body_drive: self.body_drive,
            drive_ridge: self.drive_ridge,
            dynamics_epochs: self.dynamics_epochs,
            dynamics_widths: self.dynamics_widths.clone(),
            unroll_frames: self.unroll_frames.clone(),
            dynamics_noise: self.dynamics_noise,
            dynamics_history: self.dynamics_history,
            motion_features: self.motion_features,
            seed: self.seed,
            eval: self.eval_motion.clone().zip(self.eval_sim.clone()),
            out: self.out.clone(),
            resume: self.resume,
            log: self.log.clone(),
            compute: self.compute.compute(),
        };
        let hide_bars = self.output.json;
        run(&request, &Feedback { say, hide_bars })
    }

    fn print(r: &Report) {
        print!("{r}");
    }
}
