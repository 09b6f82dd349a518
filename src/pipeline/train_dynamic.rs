//! `train-dynamic`: the motion-guided dynamic model trained on simulated clips, in two stages
//! (the generative space, then the motion encoder on the frozen space): clips and their
//! simulations read and checked against each other, the training tensors built, the trainers
//! of `crate::train` run, and the model measured (one step ahead, and a held-out clip rolled
//! out).

use super::{Clips, Feedback};
use crate::body::Body;
use crate::compute::Compute;
use crate::garment::Garment;
use crate::io::gltf_body::read_body;
use crate::metrics::deviation::Deviation;
use crate::models::dynamic::SpaceShape;
use crate::models::dynamic::{BodyAnchors, MotionShape};
use crate::models::file::{DynamicEpoch, ModelFile, MotionEpoch, RolloutRound, Settled};
use crate::rollout::{for_model, Init, Settings as RolloutSettings};
use crate::train::dynamic::{deviation, FrameData, Sequence, Settings, SpaceTrainer};
use crate::train::motion::{
    drive_joints, one_step, MotionTrainer, Rolled, Settings as MotionSettings,
};
use crate::train::{fit, FitOptions, Fitted, Training};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use std::fmt::{self, Display, Formatter};
use std::path::PathBuf;

/// Which stage to train: the generative space of garment deformations (first), or the motion
/// encoder on the frozen space of `from` (second). The variants carry no doc comments: clap
/// would list them in `--help`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Stage {
    Space,
    Dynamic,
}

/// What to train (the flags of `garmentbake train-dynamic`, resolved; see its help for each).
pub struct Request {
    pub stage: Stage,
    /// Stage space: the skinned body and the garment (OBJ with UVs) the simulations used.
    pub body: Option<PathBuf>,
    pub garment: Option<PathBuf>,
    /// Stage dynamic: the model whose trained space the motion encoder builds on.
    pub from: Option<PathBuf>,
    /// The training clips (their maps and rate; the axes are detected).
    pub clips: Clips,
    /// The simulated garment of each clip, in order.
    pub sims: Vec<PathBuf>,
    pub preset: String,
    pub latent: Option<usize>,
    pub kernel_radius_mm: f64,
    /// A fabric file or preset name.
    pub fabric: String,
    pub epochs: usize,
    pub batch: Option<usize>,
    pub lr: Option<f64>,
    pub ridge: f64,
    pub rollout_rounds: Option<usize>,
    /// Settling time towards the pose (s); none: the paper's integrator alone.
    pub pose_settle: Option<f64>,
    pub pose_ridge: Option<f64>,
    /// The strain limit and collision fix of the rounds' roll-outs (the fix on only when asked
    /// for: `collision_fix`).
    pub rounds_fix: RolloutSettings,
    pub rollout_window: usize,
    pub body_drive: bool,
    pub drive_ridge: f64,
    /// None: the recipe's (`DynamicsSettings::default`) when the networks are off, else 0.
    pub dynamics_epochs: Option<usize>,
    pub dynamics_widths: Vec<usize>,
    pub unroll_frames: Vec<usize>,
    pub dynamics_noise: f64,
    pub dynamics_history: usize,
    pub motion_features: usize,
    pub seed: u64,
    /// A held-out clip and its simulation.
    pub eval: Option<(PathBuf, PathBuf)>,
    pub out: PathBuf,
    pub resume: bool,
    pub log: Option<PathBuf>,
    pub compute: Compute,
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
    pub train: Deviation,
    pub eval: Option<(String, Deviation)>,
    /// Learnt kernel radius per body part (mm).
    pub radius_mm: Vec<(String, f64)>,
    pub last: Option<DynamicEpoch>,
    pub last_motion: Option<MotionEpoch>,
    /// Stage dynamic: the roll-out-aware fit's rounds.
    pub rollout_rounds: Vec<RolloutRound>,
    /// Stage dynamic: the held-out clip rolled out from its first simulated frame (each
    /// prediction the next history, no collision fix, latents held in the training range).
    pub eval_rollout: Option<(String, Deviation)>,
    /// Stage dynamic: how the model was settled towards the pose's garment; none: not settled.
    pub settle: Option<Settled>,
    /// Stage dynamic: the learnt dynamics' fit (`--dynamics-epochs`); none: the linear
    /// integrator alone.
    #[serde(default)]
    pub dynamics: Option<crate::models::dynamic::learned::DynamicsFit>,
}

/// The report for a person: the training's pace, the errors, the fit's rounds and settling,
/// the learnt radii, and the model written.
impl Display for Report {
    fn fmt(&self, f: &mut Formatter) -> fmt::Result {
        let r = self;
        writeln!(
            f,
            "trained {} epochs on {} frames in {:.0} s ({:.1} frames/s)",
            r.fitted.epochs, r.frames, r.fitted.seconds, r.frames_per_second
        )?;
        writeln!(
            f,
            "{}:",
            if r.stage == "space" {
                "reconstruction (vertex L2)"
            } else {
                "one-step prediction from simulated history (vertex L2)"
            }
        )?;
        let row = |f: &mut Formatter, name: &str, x: &Deviation| {
            writeln!(f, "{name:<24} {:>6} frames   mean {:>6.2} mm   p99 {:>6.2} mm   max {:>6.2} mm (worst frame {})", x.frames, x.mean_mm, x.p99_mm.unwrap_or(f64::NAN), x.max_mm, x.worst_frame)
        };
        row(f, "training frames", &r.train)?;
        if let Some((name, e)) = &r.eval {
            row(f, &format!("{name} (held out)"), e)?;
        }
        for round in &r.rollout_rounds {
            writeln!(
                f,
                "roll-out-aware fit, round {}: training clips rolled out at mean {:.2} mm before the refit ({} rows)",
                round.round, round.train_rollout_mean_mm, round.rows
            )?;
        }
        if let Some(s) = r.settle {
            writeln!(
                f,
                "settled towards the pose's garment: a deviation fades to 1/e in {} s (pose regression ridge {}{})",
                s.seconds,
                s.pose_ridge,
                s.pose_explained_pct.map_or(String::new(), |p| format!(
                    "; on training clips left out of its fit it explains {p:.1} % of the latents' spread around the mean garment"
                ))
            )?;
        }
        if let Some((name, e)) = &r.eval_rollout {
            writeln!(
                f,
                "roll-out from the first simulated frame (vertex L2, no collision fix):"
            )?;
            row(f, &format!("{name} (held out)"), e)?;
        }
        if let Some(m) = &r.last_motion {
            writeln!(
                f,
                "last epoch: loss {:.4} (geometry {:.5} m, virtual {:.5} m, latent {:.4}, virtual {:.4})",
                m.loss,
                m.terms.geometry,
                m.terms.virtual_geometry,
                m.terms.latent,
                m.terms.virtual_latent
            )?;
        }
        let radii: Vec<String> = r
            .radius_mm
            .iter()
            .map(|(p, v)| format!("{p} {v:.1}"))
            .collect();
        writeln!(f, "kernel radius per part (mm): {}", radii.join(", "))?;
        writeln!(f, "wrote {}", r.fitted.out.display())?;
        Ok(())
    }
}

/// Trains `request`'s stage; the trainer writes the model (and its checkpoints) atomically
/// itself, as it goes.
pub fn run(request: &Request, feedback: &Feedback) -> Result<Report> {
    match request.stage {
        Stage::Space => request.train_space(feedback),
        Stage::Dynamic => request.train_motion(feedback),
    }
}

/// Clips and their simulations, checked against each other.
fn sequences(
    motions: &[PathBuf],
    sims: &[PathBuf],
    clips: &Clips,
    body: &Body,
    vertices: usize,
) -> Result<Vec<Sequence>> {
    if motions.len() != sims.len() {
        bail!(
            "{} --motion clips but {} --sim caches: give each clip its simulation",
            motions.len(),
            sims.len()
        );
    }
    let reader = clips.reader()?;
    motions
        .iter()
        .zip(sims)
        .map(|(m, s)| Sequence::load(m, s, &reader, body, clips.fps, vertices))
        .collect()
}

impl Request {
    /// Stage `space`: the generative space from the simulated clips.
    fn train_space(&self, feedback: &Feedback) -> Result<Report> {
        let say = feedback.say;
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
        let fabric = crate::fabric::Fabric::load(&self.fabric)?;
        let n = garment.mesh.vertex_count();
        let train = sequences(&self.clips.motions, &self.sims, &self.clips, &body, n)?;
        let eval = self.eval_sequence(&body, n)?;
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
        let fitted = fit(&mut trainer, &self.fit_options(feedback.hide_bars))?;
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
    fn train_motion(&self, feedback: &Feedback) -> Result<Report> {
        let say = feedback.say;
        let Some(from) = &self.from else {
            bail!("--stage dynamic needs --from SPACE.safetensors (a model trained with --stage space)");
        };
        // The roll-outs of the rounds: nothing measured.
        let round = RolloutSettings {
            measure_collisions: false,
            ..self.rounds_fix.clone()
        };
        if let Some(s) = self.pose_settle.filter(|s| !(s.is_finite() && *s >= 0.0)) {
            bail!(
                "--pose-settle {s} is not a time: give seconds ≥ 0 (0: the pose alone), or --no-pose-settle"
            );
        }
        if let Some(r) = self.pose_ridge.filter(|r| !(r.is_finite() && *r >= 0.0)) {
            bail!("--pose-ridge {r}: give a ridge ≥ 0");
        }
        let device = self.compute.apply()?;
        let file = crate::models::file::load(from, device)?;
        let info = file.info.dynamic()?.clone();
        if self.resume && !crate::train::checkpoint_path(&self.out).exists() {
            bail!("--resume: no checkpoint next to {}", self.out.display());
        }
        let n = file.garment.vertex_count();
        let train = sequences(&self.clips.motions, &self.sims, &self.clips, &file.body, n)?;
        if let Some(s) = train.iter().find(|s| (s.clip.fps - info.fps).abs() > 1e-3) {
            bail!(
                "{} plays at {} fps, the space was trained at {} fps: give --fps {}",
                s.name,
                s.clip.fps,
                info.fps,
                info.fps
            );
        }
        let eval = self.eval_sequence(&file.body, n)?;
        let data = FrameData::new(&file.body, &self.anchors(&file)?, &train, device);
        let frames = data.len();
        say(&format!(
            "{frames} training frames from {} clip(s); the space stays frozen",
            train.len()
        ));
        let mut shape = MotionShape::for_space(&info.shape.encoder, self.motion_features);
        if self.body_drive || self.pose_settle.is_some() {
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
        let bar =
            crate::progress::bar(2 * data.len() as u64, "encoding frames", feedback.hide_bars);
        let mut trainer = MotionTrainer::new(file, data, fps, settings, &mut |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        })?;
        bar.finish_and_clear();
        if self.resume {
            trainer.resume(&crate::train::checkpoint_path(&self.out))?;
        }
        let rounds = if self.resume {
            trainer.info().rollout_rounds.clone()
        } else {
            let rounds =
                self.fit_on_rollouts(&mut trainer, &train, &round, device, feedback.hide_bars)?;
            if let Some(seconds) = self.pose_settle {
                say(&format!(
                    "settling towards the pose's garment in {seconds} s"
                ));
                trainer.settle_towards_pose(seconds, self.pose_ridge)?;
            }
            rounds
        };
        let done = trainer.epochs_done();
        let fitted = fit(&mut trainer, &self.fit_options(feedback.hide_bars))?;
        let dynamics_epochs = self.dynamics_epochs(trainer.dynamic().space.networks_idle());
        if dynamics_epochs > 0 {
            let settings = self.dynamics_settings(dynamics_epochs)?;
            say(&format!(
                "learnt dynamics: {} epochs through roll-outs of {}..{} frames",
                settings.epochs, settings.horizon.0, settings.horizon.1
            ));
            let bar = crate::progress::bar(
                settings.epochs as u64,
                "learnt dynamics",
                feedback.hide_bars,
            );
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
        let train_err = one_step_with_bar(dynamic, &trainer.data, fps, feedback.hide_bars)?;
        let mut eval_rollout = None;
        let eval = eval
            .map(|s| {
                let data = self.frame_data(&trainer.file, &s, device)?;
                let bar = crate::progress::bar(
                    data.len() as u64,
                    "held-out roll-out",
                    feedback.hide_bars,
                );
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
                eval_rollout = Some((s.name.clone(), deviation(&rolled, &truth)));
                let err = one_step_with_bar(dynamic, &data, fps, feedback.hide_bars)?;
                Ok::<_, anyhow::Error>((s.name.clone(), err))
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
        hide_bar: bool,
    ) -> Result<Vec<RolloutRound>> {
        let frames = trainer.data.len() as u64;
        let bar = crate::progress::bar(
            frames * self.rounds() as u64,
            "roll-out-aware fit",
            hide_bar,
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
    fn dynamics_settings(
        &self,
        epochs: usize,
    ) -> Result<crate::models::dynamic::learned::DynamicsSettings> {
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
            epochs,
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

    /// `--dynamics-epochs`, by default the recipe's when the space and the motion stage are
    /// linear (the learnt dynamics sit beside the linear paths only), else none.
    fn dynamics_epochs(&self, linear_space: bool) -> usize {
        let recipe = crate::models::dynamic::learned::DynamicsSettings::default().epochs;
        let linear = linear_space && self.epochs == 0;
        self.dynamics_epochs
            .unwrap_or(if linear { recipe } else { 0 })
    }

    /// `--rollout-rounds`, by default 0 when settling and 3 without.
    fn rounds(&self) -> usize {
        self.rollout_rounds
            .unwrap_or(if self.pose_settle.is_none() { 3 } else { 0 })
    }

    fn fit_options(&self, hide_bar: bool) -> FitOptions<'_> {
        FitOptions {
            epochs: self.epochs,
            out: &self.out,
            hide_bar,
            log: self.log.as_deref(),
        }
    }

    fn eval_sequence(&self, body: &Body, vertices: usize) -> Result<Option<Sequence>> {
        Ok(match &self.eval {
            Some((m, s)) => sequences(
                std::slice::from_ref(m),
                std::slice::from_ref(s),
                &self.clips,
                body,
                vertices,
            )?
            .pop(),
            _ => None,
        })
    }

    fn anchors(&self, file: &ModelFile) -> Result<BodyAnchors> {
        let info = file.info.dynamic()?;
        BodyAnchors::from_vertices(&file.body, &info.anchors, &info.anchor_parts)
    }

    fn frame_data(&self, file: &ModelFile, s: &Sequence, device: tch::Device) -> Result<FrameData> {
        Ok(FrameData::new(
            &file.body,
            &self.anchors(file)?,
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
                &poses,
                start..end + 1,
                &init,
                settings.clone(),
                &mut |f| done(played + f),
            )?;
            played += end - start;
            garments.extend_from_slice(&s.garment[from..start]);
            garments.extend(rolled.frames.into_points());
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

/// [`one_step`] with a progress bar: on a many-take set it is minutes of work after the fit.
fn one_step_with_bar(
    dynamic: &crate::models::dynamic::Dynamic,
    data: &FrameData,
    fps: f64,
    hide_bar: bool,
) -> Result<Deviation> {
    let bar = crate::progress::bar(data.len() as u64, "one-step error", hide_bar);
    let err = one_step(dynamic, data, fps, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    Ok(err)
}

fn radii_mm(info: &crate::models::file::DynamicInfo) -> Vec<(String, f64)> {
    info.parts
        .iter()
        .cloned()
        .zip(info.radii.iter().map(|r| r * 1e3))
        .collect()
}
