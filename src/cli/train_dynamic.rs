//! `garmentbake train-dynamic`: the motion-guided dynamic model, trained on simulated clips.

use super::args::{
    output_set, ClipArgs, CollisionFixArgs, ComputeArgs, FabricArgs, OutputArgs, Writes, MODEL,
};
use super::Execute;
use crate::garment::Garment;
use crate::io::gltf_body::read_body;
use crate::models::dynamic::SpaceShape;
use crate::models::dynamic::{MotionShape, Seeds};
use crate::models::file::{DynamicEpoch, ModelFile, MotionEpoch, RolloutRound, Settled};
use crate::motion::read_maps;
use crate::rig::Skeleton;
use crate::rollout::{for_model, Init, Settings as RolloutSettings};
use crate::train::dynamic::{FrameData, Reconstruction, Sequence, Settings, SpaceTrainer};
use crate::train::motion::{
    drive_joints, one_step, MotionTrainer, Rolled, Settings as MotionSettings,
};
use crate::train::{fit, FitOptions, Fitted, Training};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Train the dynamic garment model on cloth simulations (`garmentbake simulate`).
///
/// Two stages, one model file:
///
/// `--stage space` (first): the generative space of garment deformations. Each simulated frame
/// is measured relative to body seed points, laid out in the garment's UV map, encoded to a
/// 64-number latent and decoded to per-vertex displacements in each vertex's rest frame, then
/// skinned by the seeds with distance weights whose kernel radius is learnt per body part. Loss:
/// reconstruction (positions and Laplacians, L1), edge lengths of garments decoded from random
/// latents, the exact signed distance to the rest body (hinge) and a latent regulariser. The
/// garment needs UVs. Needs --body and --garment.
///
/// `--stage dynamic --from SPACE.safetensors` (second): the motion encoder, the space frozen.
/// From the previous garment (its shape, velocity and acceleration) and the body's motion into
/// the next frame it predicts the next frame's latent; trained on the simulated frames with the
/// paper's virtual sample (no change in, no change out). Then `garmentbake rollout` plays it.
///
/// Give each --motion its --sim cache (same order, same --fps as simulated). Judge the model with
/// --eval-motion/--eval-sim on a clip it never saw. A checkpoint is written next to --out every
/// epoch; --resume continues from it.
#[derive(clap::Args)]
pub struct Args {
    /// Skinned body (glTF/glb) the simulations used (stage space).
    #[arg(long, required_if_eq("stage", "space"))]
    pub body: Option<PathBuf>,
    /// Garment mesh (OBJ with UVs) the simulations used (stage space).
    #[arg(long, required_if_eq("stage", "space"))]
    pub garment: Option<PathBuf>,
    /// Stage dynamic: the model whose trained space the motion encoder builds on.
    #[arg(long, required_if_eq("stage", "dynamic"))]
    pub from: Option<PathBuf>,
    #[command(flatten)]
    pub clips: ClipArgs,
    /// The simulated garment of each --motion (.pc2 from `garmentbake simulate`), in order.
    #[arg(long = "sim", required = true)]
    pub sims: Vec<PathBuf>,
    /// Stage to train.
    #[arg(long, value_enum, default_value = "space")]
    pub stage: StageArg,
    /// Network size: cpu (64² map, 128 seeds, ≤ 256 channels) or paper (128², 581, 1024: a GPU).
    #[arg(long, default_value = "cpu")]
    pub preset: String,
    /// Latent size (the preset's 64 when not given): the linear path starts as this many
    /// principal components of the training frames.
    #[arg(long)]
    pub latent: Option<usize>,
    /// Stage space: initial kernel radius of the seed skinning (mm, every body part; learnt
    /// from there). Small: each garment vertex follows its nearest few seeds (a skirt's hem
    /// follows the thighs); large: it blends the seeds over a wider patch (the hem moves with
    /// the hips and both legs at once).
    #[arg(long, default_value_t = 50.0, value_parser = super::args::positive::<f64>())]
    pub kernel_radius_mm: f64,
    #[command(flatten)]
    pub fabric: FabricArgs,
    #[arg(long, default_value_t = 30)]
    pub epochs: usize,
    /// Frames per optimisation step (space 4, dynamic 8).
    #[arg(long)]
    pub batch: Option<usize>,
    /// Initial Adam learning rate, cosine decay to a tenth (space 3e-4, dynamic 1e-3).
    #[arg(long, value_parser = super::args::positive::<f64>())]
    pub lr: Option<f64>,
    /// Stage dynamic: pull of the fitted latent integrator towards keeping the previous latent
    /// (relative ridge penalty); stronger is steadier over long roll-outs, weaker follows the
    /// simulation closer one step ahead.
    #[arg(long, default_value_t = 0.1, value_parser = super::args::non_negative::<f64>())]
    pub ridge: f64,
    /// Stage dynamic: rounds of roll-out-aware fitting. Each round rolls the model out over the
    /// training clips (no collision fix) and refits the latent integrator on those self-made
    /// histories too, with the simulation as the target, so that it learns to pull its own
    /// drift back (teacher forcing alone never shows it a drifted history). One round costs one
    /// roll-out of all training frames. 0: the teacher-forced fit alone (closest one step ahead).
    /// Default: 0 when settling towards the pose (it keeps roll-outs stable by itself), 3 with
    /// --no-pose-settle.
    #[arg(long, value_name = "N")]
    pub rollout_rounds: Option<usize>,
    /// Stage dynamic: settling time towards the pose, in seconds (not in the paper). The
    /// integrator's prediction is blended with the garment the body's pose alone predicts (a
    /// ridge regression on the simulated frames), so whatever the history carries — a
    /// simulated start, a swing, a drift — fades to 1/e in this time: roll-outs follow a known
    /// start for the first frames and cannot run away over long shots. Longer: more of the
    /// history's motion kept, more room to drift; 0: the pose alone. The regression's ridge is
    /// chosen leaving one training clip out. Implies --body-drive.
    #[arg(long, default_value_t = 0.3, value_name = "SECONDS", value_parser = super::args::non_negative::<f64>())]
    pub pose_settle: f64,
    /// Stage dynamic: no settling, the paper's integrator alone (with --rollout-rounds 3 by
    /// default to keep it stable).
    #[arg(long, conflicts_with = "pose_settle")]
    pub no_pose_settle: bool,
    /// Stage dynamic, settling: the pose regression's ridge, relative to each pose input's mean
    /// square. Default: the one of 1e-3, 0.01, 0.1, 1, 10 whose fit on all training clips but
    /// one best predicts the clip left out (one clip: its halves).
    #[arg(long, value_name = "R", value_parser = super::args::non_negative::<f64>())]
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
    /// With --rollout-fix: the fix as `rollout` runs it.
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
    /// Stage dynamic (not in the paper): epochs of the learnt latent dynamics, a small network
    /// beside the linear integrator fitted through the model's own roll-outs of the training
    /// clips (windows growing from --unroll-frames' first to its last length, noise on each
    /// window's start; loss: decoded mm and velocity). 0: the linear integrator alone. Its last
    /// layer starts at zero, so it only adds what the roll-outs teach it.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub dynamics_epochs: usize,
    /// Stage dynamic, with --dynamics-epochs: hidden layer widths of the learnt dynamics.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "128,128",
        value_name = "W,W"
    )]
    pub dynamics_widths: Vec<usize>,
    /// Stage dynamic, with --dynamics-epochs: window length of the roll-outs it is fitted
    /// through, at the first and the last epoch (frames).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "8,32",
        value_name = "FIRST,LAST"
    )]
    pub unroll_frames: Vec<usize>,
    /// Stage dynamic, with --dynamics-epochs: noise on each window's starting latent, in units
    /// of the training latents' spread.
    #[arg(long, default_value_t = 0.05, value_parser = super::args::non_negative::<f64>())]
    pub dynamics_noise: f64,
    /// Stage dynamic, with --dynamics-epochs: past frames of the body's motion (root and joint
    /// rotations and their speeds, as the body drive has them) the learnt dynamics also see,
    /// so a swing can answer the body's acceleration (8: 0.27 s at 30 fps, the measured recipe
    /// of docs/dynamic.md). 0: the current frame's alone.
    #[arg(long, default_value_t = 8, value_name = "FRAMES")]
    pub dynamics_history: usize,
    /// Stage dynamic: channels of the motion features `E_t`.
    #[arg(long, default_value_t = 16)]
    pub motion_features: usize,
    /// Seed: same seed and inputs → the same model.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A clip held out from training and its simulation: reconstruction error reported on it.
    #[arg(long, requires = "eval_sim")]
    pub eval_motion: Option<PathBuf>,
    #[arg(long, requires = "eval_motion")]
    pub eval_sim: Option<PathBuf>,
    /// Output model (.safetensors).
    #[arg(long)]
    pub out: PathBuf,
    /// Continue from OUT's checkpoint up to --epochs.
    #[arg(long)]
    pub resume: bool,
    /// Append one JSON object per epoch to this file.
    #[arg(long)]
    pub log: Option<PathBuf>,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum StageArg {
    Space,
    Dynamic,
}

#[derive(Serialize, Deserialize)]
pub struct Report {
    pub stage: String,
    #[serde(flatten)]
    pub fitted: Fitted,
    pub frames: usize,
    /// Training frames processed per second of wall time.
    pub frames_per_second: f64,
    /// Space: reconstructions; dynamic: one-step predictions from simulated histories.
    pub train: Reconstruction,
    pub eval: Option<(String, Reconstruction)>,
    /// Learnt kernel radius per body part (mm).
    pub radius_mm: Vec<(String, f64)>,
    pub last: Option<DynamicEpoch>,
    pub last_motion: Option<MotionEpoch>,
    /// Stage dynamic: the roll-out-aware fit's rounds.
    pub rollout_rounds: Vec<RolloutRound>,
    /// Stage dynamic: the held-out clip rolled out from its first simulated frame (each
    /// prediction the next history, no collision fix, latents held in the training range).
    pub eval_rollout: Option<(String, Reconstruction)>,
    /// Stage dynamic: how the model was settled towards the pose's garment; none: not settled.
    pub settle: Option<Settled>,
    /// Stage dynamic: the learnt dynamics' fit (`--dynamics-epochs`); none: the linear
    /// integrator alone.
    #[serde(default)]
    pub dynamics: Option<crate::models::dynamic::learned::DynamicsFit>,
}

/// Clips and their simulations, checked against each other.
fn sequences(
    motions: &[PathBuf],
    sims: &[PathBuf],
    args: &ClipArgs,
    skeleton: &Skeleton,
    vertices: usize,
) -> Result<Vec<Sequence>> {
    if motions.len() != sims.len() {
        bail!(
            "{} --motion clips but {} --sim caches: give each clip its simulation",
            motions.len(),
            sims.len()
        );
    }
    let maps = read_maps(&args.maps)?;
    motions
        .iter()
        .zip(sims)
        .map(|(m, s)| Sequence::load(m, s, &maps, skeleton, args.fps, vertices))
        .collect()
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
        match self.stage {
            StageArg::Space => self.train_space(say),
            StageArg::Dynamic => self.train_motion(say),
        }
    }

    fn print(r: &Report) {
        println!(
            "trained {} epochs on {} frames in {:.0} s ({:.1} frames/s)",
            r.fitted.epochs, r.frames, r.fitted.seconds, r.frames_per_second
        );
        println!(
            "{}:",
            if r.stage == "space" {
                "reconstruction (vertex L2)"
            } else {
                "one-step prediction from simulated history (vertex L2)"
            }
        );
        let row = |name: &str, x: &Reconstruction| {
            println!("{name:<24} {:>6} frames   mean {:>6.2} mm   p99 {:>6.2} mm   max {:>6.2} mm (worst frame {})", x.frames, x.mean_mm, x.p99_mm, x.max_mm, x.worst_frame);
        };
        row("training frames", &r.train);
        if let Some((name, e)) = &r.eval {
            row(&format!("{name} (held out)"), e);
        }
        for round in &r.rollout_rounds {
            println!(
                "roll-out-aware fit, round {}: training clips rolled out at mean {:.2} mm before the refit ({} rows)",
                round.round, round.train_rollout_mean_mm, round.rows
            );
        }
        if let Some(s) = r.settle {
            println!(
                "settled towards the pose's garment: a deviation fades to 1/e in {} s (pose regression ridge {})",
                s.seconds, s.pose_ridge
            );
        }
        if let Some((name, e)) = &r.eval_rollout {
            println!("roll-out from the first simulated frame (vertex L2, no collision fix):");
            row(&format!("{name} (held out)"), e);
        }
        if let Some(m) = &r.last_motion {
            println!(
                "last epoch: loss {:.4} (geometry {:.5} m, virtual {:.5} m, latent {:.4}, virtual {:.4})",
                m.loss,
                m.terms.geometry,
                m.terms.virtual_geometry,
                m.terms.latent,
                m.terms.virtual_latent
            );
        }
        let radii: Vec<String> = r
            .radius_mm
            .iter()
            .map(|(p, v)| format!("{p} {v:.1}"))
            .collect();
        println!("kernel radius per part (mm): {}", radii.join(", "));
        println!("wrote {}", r.fitted.out.display());
    }
}

impl Args {
    /// Stage `space`: the generative space from the simulated clips.
    fn train_space(&self, say: &dyn Fn(&str)) -> Result<Report> {
        let device = self.compute.apply()?;
        let (Some(body_path), Some(garment_path)) = (&self.body, &self.garment) else {
            bail!("--stage space needs --body and --garment");
        };
        let body = read_body(body_path)?;
        let garment = Garment::read(garment_path)?;
        // The UV layout first: a garment without one fails before any cache is read.
        crate::models::dynamic::UvRaster::new(
            &garment.mesh,
            8,
            &garment_path.display().to_string(),
        )?;
        let fabric = self.fabric.load()?;
        let n = garment.mesh.vertex_count();
        let train = sequences(
            &self.clips.motions,
            &self.sims,
            &self.clips,
            &body.skeleton,
            n,
        )?;
        let eval = self.eval_sequence(&body.skeleton, n)?;
        let mut shape = SpaceShape::preset(&self.preset)?;
        shape.latent = self.latent.unwrap_or(shape.latent);
        let mut settings = Settings::new(shape);
        settings.epochs = self.epochs;
        settings.kernel_radius = self.kernel_radius_mm / 1000.0;
        settings.batch = self.batch.unwrap_or(settings.batch);
        settings.learning_rate = self.lr.unwrap_or(settings.learning_rate);
        settings.seed = self.seed;
        settings.device = device;
        let mut trainer = SpaceTrainer::new(body, garment, fabric, &train, settings)?;
        let frames = trainer.data.len();
        say(&format!(
            "{frames} training frames from {} clip(s)",
            train.len()
        ));
        if self.resume {
            trainer.resume(&crate::train::checkpoint_path(&self.out))?;
        }
        let done = trainer.epochs_done();
        let fitted = fit(&mut trainer, &self.fit_options())?;
        let space = trainer.space();
        let train_err = SpaceTrainer::measure(space, &trainer.data);
        let eval = eval
            .map(|s| {
                let data = self.frame_data(&trainer.file, &s, device)?;
                Ok::<_, anyhow::Error>((s.name.clone(), SpaceTrainer::measure(space, &data)))
            })
            .transpose()?;
        let info = trainer.info();
        Ok(Report {
            stage: "space".into(),
            frames,
            frames_per_second: (frames * (fitted.epochs - done)) as f64 / fitted.seconds.max(1e-9),
            train: train_err,
            eval,
            radius_mm: radii_mm(info),
            last: info.history.last().cloned(),
            last_motion: None,
            rollout_rounds: Vec::new(),
            eval_rollout: None,
            settle: None,
            dynamics: None,
            fitted,
        })
    }

    /// Stage `dynamic`: the motion encoder on the frozen space of `--from`.
    fn train_motion(&self, say: &dyn Fn(&str)) -> Result<Report> {
        let Some(from) = &self.from else {
            bail!("--stage dynamic needs --from SPACE.safetensors (a model trained with --stage space)");
        };
        let round = self.round_settings()?;
        if !(self.pose_settle.is_finite() && self.pose_settle >= 0.0) {
            bail!(
                "--pose-settle {} is not a time: give seconds ≥ 0 (0: the pose alone), or --no-pose-settle",
                self.pose_settle
            );
        }
        if let Some(r) = self.pose_ridge.filter(|r| !(r.is_finite() && *r >= 0.0)) {
            bail!("--pose-ridge {r}: give a ridge ≥ 0");
        }
        let (file, device) = self.compute.load_model(from)?;
        let info = file.info.dynamic()?.clone();
        if self.resume && !crate::train::checkpoint_path(&self.out).exists() {
            bail!("--resume: no checkpoint next to {}", self.out.display());
        }
        let n = file.garment.vertex_count();
        let train = sequences(
            &self.clips.motions,
            &self.sims,
            &self.clips,
            &file.body.skeleton,
            n,
        )?;
        if let Some(s) = train.iter().find(|s| (s.clip.fps - info.fps).abs() > 1e-3) {
            bail!(
                "{} plays at {} fps, the space was trained at {} fps: give --fps {}",
                s.name,
                s.clip.fps,
                info.fps,
                info.fps
            );
        }
        let eval = self.eval_sequence(&file.body.skeleton, n)?;
        let data = FrameData::new(&file.body, &self.seeds(&file)?, &train, device);
        let frames = data.len();
        say(&format!(
            "{frames} training frames from {} clip(s); the space stays frozen",
            train.len()
        ));
        let mut shape = MotionShape::for_space(&info.shape.encoder, self.motion_features);
        if self.body_drive || self.settle_seconds().is_some() {
            shape.drive_joints = drive_joints(&file);
            let names: Vec<&str> = shape
                .drive_joints
                .iter()
                .map(|&j| file.body.skeleton.joint_names[j].as_str())
                .collect();
            say(&format!("body drive: {}", names.join(", ")));
        }
        let settings = MotionSettings {
            shape,
            epochs: self.epochs,
            batch: self.batch.unwrap_or(8),
            learning_rate: self.lr.unwrap_or(1e-3),
            seed: self.seed,
            device,
            ridge: self.ridge,
            drive_ridge: self.drive_ridge,
        };
        let fps = info.fps as f64;
        let mut trainer = MotionTrainer::new(file, data, fps, settings)?;
        if self.resume {
            trainer.resume(&crate::train::checkpoint_path(&self.out))?;
        }
        let rounds = if self.resume {
            trainer.info().rollout_rounds.clone()
        } else {
            let rounds = self.fit_on_rollouts(&mut trainer, &train, &round, device)?;
            if let Some(seconds) = self.settle_seconds() {
                say(&format!(
                    "settling towards the pose's garment in {seconds} s"
                ));
                trainer.settle_towards_pose(seconds, self.pose_ridge)?;
            }
            rounds
        };
        let done = trainer.epochs_done();
        let fitted = fit(&mut trainer, &self.fit_options())?;
        if self.dynamics_epochs > 0 {
            let settings = self.dynamics_settings()?;
            say(&format!(
                "learnt dynamics: {} epochs through roll-outs of {}..{} frames",
                settings.epochs, settings.horizon.0, settings.horizon.1
            ));
            let bar =
                crate::progress::bar(settings.epochs as u64, "learnt dynamics", self.output.json);
            let fit = crate::train::unroll::fit_model_dynamics(
                &mut trainer.file,
                &trainer.data,
                &settings,
                &mut |e| {
                    bar.set_message(format!(
                        "{} frames: {:.1} mm, {:.0} mm/s",
                        e.horizon, e.rms_mm, e.velocity_mm_s
                    ));
                    bar.set_position(e.epoch as u64);
                },
            )?;
            bar.finish_and_clear();
            if let Some(last) = fit.history.last() {
                say(&format!(
                    "learnt dynamics fitted in {:.0} s: {:.1} mm RMS over the last epoch's {}-frame roll-outs",
                    fit.seconds, last.rms_mm, last.horizon
                ));
            }
            if let Some(last) = fit.history.last() {
                say(&format!(
                    "{} fixed {}-frame training windows rolled out: {:.1} mm RMS with the linear integrator alone, {:.1} mm with the learnt dynamics",
                    fit.check_windows, last.horizon, fit.base_rms_mm, fit.fitted_rms_mm
                ));
            }
            crate::train::Training::save(&mut trainer, &self.out, false)?;
        }
        let dynamic = trainer.dynamic();
        let train_err = one_step(dynamic, &trainer.data, fps)?;
        let mut eval_rollout = None;
        let eval = eval
            .map(|s| {
                let data = self.frame_data(&trainer.file, &s, device)?;
                let bar =
                    crate::progress::bar(data.len() as u64, "held-out roll-out", self.output.json);
                let plain = RolloutSettings {
                    collision_fix: false,
                    ..round.clone()
                };
                let rolled = roll_clips(
                    &trainer.file,
                    std::slice::from_ref(&s),
                    &plain,
                    None,
                    device,
                    &mut |f| bar.set_position(f as u64),
                )?
                .garments;
                bar.finish_and_clear();
                // Frame 0 is the simulation's: the predicted frames follow.
                let n = data.len() as i64 - 1;
                let (rolled, truth) = (rolled.narrow(0, 1, n), data.garment.narrow(0, 1, n));
                eval_rollout = Some((s.name.clone(), Reconstruction::of(&rolled, &truth)));
                Ok::<_, anyhow::Error>((s.name.clone(), one_step(dynamic, &data, fps)?))
            })
            .transpose()?;
        let info = trainer.file.info.dynamic()?;
        Ok(Report {
            stage: "dynamic".into(),
            frames,
            frames_per_second: (frames * (fitted.epochs - done)) as f64 / fitted.seconds.max(1e-9),
            train: train_err,
            eval,
            radius_mm: radii_mm(info),
            last: None,
            last_motion: trainer.info().history.last().cloned(),
            rollout_rounds: rounds,
            eval_rollout,
            settle: trainer.info().settle,
            dynamics: trainer.info().dynamics.clone(),
            fitted,
        })
    }

    /// `--rollout-rounds` on the training clips `train`, with a progress bar.
    fn fit_on_rollouts(
        &self,
        trainer: &mut MotionTrainer,
        train: &[Sequence],
        settings: &RolloutSettings,
        device: tch::Device,
    ) -> Result<Vec<RolloutRound>> {
        let frames = trainer.data.len() as u64;
        let bar = crate::progress::bar(
            frames * self.rounds() as u64,
            "roll-out-aware fit",
            self.output.json,
        );
        let rounds = trainer.fit_on_rollouts(self.rounds(), &mut |file, round| {
            let window = (self.rollout_window > 0).then_some(self.rollout_window);
            roll_clips(file, train, settings, window, device, &mut |f| {
                bar.set_position(round as u64 * frames + f as u64)
            })
        })?;
        bar.finish_and_clear();
        Ok(rounds)
    }

    /// The learnt dynamics' fit from the flags.
    fn dynamics_settings(&self) -> Result<crate::models::dynamic::learned::DynamicsSettings> {
        let [first, last] = self.unroll_frames[..] else {
            bail!("--unroll-frames takes two lengths, FIRST,LAST (e.g. 8,32)");
        };
        if first == 0 || last < first {
            bail!("--unroll-frames {first},{last}: give 1 ≤ FIRST ≤ LAST");
        }
        if self.dynamics_widths.is_empty() || self.dynamics_widths.contains(&0) {
            bail!("--dynamics-widths: give positive layer widths, e.g. 128,128");
        }
        Ok(crate::models::dynamic::learned::DynamicsSettings {
            widths: self.dynamics_widths.clone(),
            epochs: self.dynamics_epochs,
            horizon: (first, last),
            noise: self.dynamics_noise,
            drive_history: self.dynamics_history,
            seed: self.seed,
            // The fit plays the frames as `rollout` does by default.
            strain_band: RolloutSettings::default().strain_band,
            strain_iterations: RolloutSettings::default().strain_iterations,
            ..Default::default()
        })
    }

    /// `--pose-settle` unless `--no-pose-settle`.
    fn settle_seconds(&self) -> Option<f64> {
        (!self.no_pose_settle).then_some(self.pose_settle)
    }

    /// `--rollout-rounds`, by default 0 when settling and 3 without.
    fn rounds(&self) -> usize {
        self.rollout_rounds
            .unwrap_or(if self.no_pose_settle { 3 } else { 0 })
    }

    /// The roll-outs of the rounds: the collision fix only with --rollout-fix; nothing measured.
    fn round_settings(&self) -> Result<RolloutSettings> {
        Ok(RolloutSettings {
            measure_collisions: false,
            ..self.collision.settings(self.rollout_fix)?
        })
    }

    fn fit_options(&self) -> FitOptions<'_> {
        FitOptions {
            epochs: self.epochs,
            out: &self.out,
            quiet: self.output.json,
            log: self.log.as_deref(),
        }
    }

    fn eval_sequence(&self, skeleton: &Skeleton, vertices: usize) -> Result<Option<Sequence>> {
        Ok(match (&self.eval_motion, &self.eval_sim) {
            (Some(m), Some(s)) => sequences(
                std::slice::from_ref(m),
                std::slice::from_ref(s),
                &self.clips,
                skeleton,
                vertices,
            )?
            .pop(),
            _ => None,
        })
    }

    fn seeds(&self, file: &ModelFile) -> Result<Seeds> {
        let info = file.info.dynamic()?;
        Seeds::from_vertices(&file.body, &info.seeds, &info.seed_parts)
    }

    fn frame_data(&self, file: &ModelFile, s: &Sequence, device: tch::Device) -> Result<FrameData> {
        Ok(FrameData::new(
            &file.body,
            &self.seeds(file)?,
            std::slice::from_ref(s),
            device,
        ))
    }
}

/// The model rolled out over `clips` as a round of the roll-out-aware fit sees it (latents held
/// in the training range; the collision fix as `settings` say): from each clip's first
/// simulated frame, or with `window`, restarted every that many frames from the simulation's
/// moving state there (its last three frames). `done` gets the frames so far.
fn roll_clips(
    file: &ModelFile,
    clips: &[Sequence],
    settings: &RolloutSettings,
    window: Option<usize>,
    device: tch::Device,
    done: &mut dyn FnMut(usize),
) -> Result<Rolled> {
    let mut garments: Vec<Vec<[f32; 3]>> = Vec::new();
    let (mut predicted, mut back) = (Vec::new(), [Vec::new(), Vec::new(), Vec::new()]);
    let mut played = 0;
    for s in clips.iter().filter(|s| !s.garment.is_empty()) {
        let (len, poses) = (s.garment.len(), s.poses());
        let every = window.unwrap_or(len).max(1);
        for start in (0..len.max(2) - 1).step_by(every) {
            let end = (start + every).min(len - 1);
            // The restart's history: up to three simulated frames, then its predictions.
            let from = start.saturating_sub(2);
            let base = garments.len() as i64 - from as i64;
            let init = Init::Moving(s.garment[from..=start].to_vec());
            let rolled = for_model(
                file,
                &poses[start..=end],
                &init,
                settings.clone(),
                &mut |f| done(played + f),
            )?;
            played += end - start;
            garments.extend_from_slice(&s.garment[from..start]);
            garments.extend(rolled.frames);
            for t in start + 1..=end {
                predicted.push(base + t as i64);
                for (k, b) in back.iter_mut().enumerate() {
                    b.push(base + (t - 1).saturating_sub(k).max(from) as i64);
                }
            }
        }
    }
    let flat: Vec<f32> = garments.iter().flatten().flatten().copied().collect();
    let index = |v: &[i64]| tch::Tensor::from_slice(v).to_device(device);
    Ok(Rolled {
        garments: tch::Tensor::from_slice(&flat)
            .reshape([garments.len() as i64, -1, 3])
            .to_device(device),
        predicted: index(&predicted),
        back: back.map(|b| index(&b)),
    })
}

fn radii_mm(info: &crate::models::file::DynamicInfo) -> Vec<(String, f64)> {
    info.parts
        .iter()
        .cloned()
        .zip(info.radii.iter().map(|r| r * 1e3))
        .collect()
}
