//! Training the dynamic model's motion encoder (stage `dynamic`) on simulated sequences, the
//! generative space frozen: `L = L_geo + L_Z + λ2·L_reg` over the frame and the virtual sample
//! `E_t = 0` (paper Sec. 5): `L_geo = |G_t − G*_t|₁ + |G^v − G*_{t−1}|₁`,
//! `L_Z = |Z_t − Z*_t|₁ + |Z^v − Z*_{t−1}|₁` with `Z*` the frozen static encoder's latents of the
//! simulated frames, `L_reg = |mean z_t² − 1| + |mean z^v² − 1|`. Histories are the simulated
//! frames (teacher forcing). L1 terms are means (metres, latent units).

use super::adam::Adam;
use super::dynamic::{deviation, FrameData};
use super::{Blowup, Training};
use crate::metrics::deviation::Deviation;
use crate::models::dynamic::motion::{
    body_drive, motion_inputs, History, MotionInputs, StaticInputs,
};
use crate::models::dynamic::settle::{keep_per_frame, PoseRegression, POSE_RIDGES};
use crate::models::dynamic::{Dynamic, MotionEncoder, MotionShape};
use crate::models::file::{
    self, KindInfo, ModelFile, MotionEpoch, MotionInfo, MotionTerms, RolloutRound, Settled,
};
use crate::models::Model;
use anyhow::{bail, Result};
use std::path::Path;
use tch::{Device, Kind, Tensor};

pub const LAMBDA_REG: f64 = 0.001;
/// Learning-rate factor of the fitted linear path.
const LINEAR_LR: f64 = 0.01;

#[derive(Clone, Debug)]
pub struct Settings {
    pub shape: MotionShape,
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f64,
    pub seed: u64,
    pub device: Device,
    /// See [`MotionEncoder::init_linear`].
    pub ridge: f64,
    pub drive_ridge: f64,
}

/// Share of the garment's skin weight a joint's subtree must carry to drive the integrator.
const DRIVE_SHARE: f32 = 0.02;

/// The joints whose rotations drive the latent integrator: those that move the garment by its
/// fixed skin (`ModelFile::lbs`), never a root (skinning carries the global motion).
pub fn drive_joints(file: &ModelFile) -> Vec<usize> {
    super::poses::moving_joints(&file.body.skeleton, &file.lbs, DRIVE_SHARE)
}

/// Each frame's history: the indices of frames `t−1, t−2, t−3`, held at the clip's first frame
/// (a clip starts at rest relative to its past: zero velocity).
pub fn history_indices(data: &FrameData, device: Device) -> [Tensor; 3] {
    let n = data.len();
    let mut ends = data.clip_starts[1..].to_vec();
    ends.push(n);
    let back = |k: usize| -> Vec<i64> {
        data.clip_starts
            .iter()
            .zip(&ends)
            .flat_map(|(&s, &e)| (s..e).map(move |t| t.saturating_sub(k).max(s) as i64))
            .collect()
    };
    [1, 2, 3].map(|k| Tensor::from_slice(&back(k)).to_device(device))
}

/// The frozen space's inputs of every frame (teacher-forced histories), in chunks.
fn static_inputs(
    space: &crate::models::dynamic::Space,
    data: &FrameData,
    garments: &Tensor,
    history: &[Tensor; 3],
    fps: f64,
    progress: &mut dyn FnMut(usize),
) -> StaticInputs {
    let all = Tensor::arange(data.len() as i64, (Kind::Int64, data.garment.device()));
    inputs_at(
        space,
        data,
        (garments, history),
        history,
        &all,
        fps,
        progress,
    )
}

/// The frozen space's inputs of frames `frames`, their garment histories `back[k][i]` (the
/// garment `k + 1` frames before `frames[i]`) indices into `garments`, in chunks.
fn inputs_at(
    space: &crate::models::dynamic::Space,
    data: &FrameData,
    (garments, back): (&Tensor, &[Tensor; 3]),
    history: &[Tensor; 3],
    frames: &Tensor,
    fps: f64,
    progress: &mut dyn FnMut(usize),
) -> StaticInputs {
    let count = frames.size()[0];
    let mut parts = Vec::new();
    for start in (0..count).step_by(crate::models::PREDICT_CHUNK) {
        let n = (crate::models::PREDICT_CHUNK as i64).min(count - start);
        let idx = frames.narrow(0, start, n);
        let chunk = back.each_ref().map(|b| b.narrow(0, start, n));
        let h = history_of(data, garments, chunk, history, &idx, fps);
        parts.push(StaticInputs::new(space, &h));
        progress((start + n) as usize);
    }
    let cat =
        |f: fn(&StaticInputs) -> &Tensor| Tensor::cat(&parts.iter().map(f).collect::<Vec<_>>(), 0);
    StaticInputs {
        static_features: cat(|p| &p.static_features),
        previous_latent: cat(|p| &p.previous_latent),
        inertia: cat(|p| &p.inertia),
    }
}

/// Garments a round of the roll-out-aware fit made, and where each predicted training frame's
/// own prediction and history lie among them: `predicted[i]` and `back[k][i]` (its garment
/// `k + 1` frames before) index `garments` for the `i`-th predicted frame of the training data.
/// A roll-out of whole clips is one garment per frame; roll-outs restarted from the
/// simulation also hold the simulated frames each restart began from.
pub struct Rolled {
    pub garments: Tensor,
    pub predicted: Tensor,
    pub back: [Tensor; 3],
}

/// The simulated history of frames `idx` (teacher forcing) and the body around them.
fn teacher_history(data: &FrameData, history: &[Tensor; 3], idx: &Tensor, fps: f64) -> History {
    let back = history.each_ref().map(|h| h.index_select(0, idx));
    history_of(data, &data.garment, back, history, idx, fps)
}

/// The history of frames `idx`: their garments `back[k]` (`k + 1` frames before, indices into
/// `garments`: the simulation's frames or a roll-out's) and the body around them.
fn history_of(
    data: &FrameData,
    garments: &Tensor,
    back: [Tensor; 3],
    history: &[Tensor; 3],
    idx: &Tensor,
    fps: f64,
) -> History {
    History {
        garment: back.map(|b| garments.index_select(0, &b)),
        before: data.body.select(&history[0].index_select(0, idx)),
        now: data.body.select(idx),
        fps,
    }
}

/// Frames that have a previous frame in their clip (the ones a roll-out predicts).
fn predicted_frames(data: &FrameData) -> Vec<i64> {
    let starts = &data.clip_starts;
    (0..data.len() as i64)
        .filter(|t| !starts.contains(&(*t as usize)))
        .collect()
}

/// Teacher-forced inputs and targets for frames `idx`.
struct Batch {
    inputs: MotionInputs,
    previous: Tensor,
}

/// The motion-encoder trainer.
pub struct MotionTrainer {
    pub file: ModelFile,
    pub data: FrameData,
    settings: Settings,
    adam: Adam,
    fps: f64,
    history: [Tensor; 3],
    frames: Tensor,
    /// The frozen space's inputs of every frame's step (teacher-forced), and `Z*` of every frame.
    statics: StaticInputs,
    latents: Tensor,
    /// The body drive of every predicted frame (`frames`), the same in every round's rows.
    drives: Tensor,
    /// The linear path's regression rows: teacher-forced ones, then those of each roll-out
    /// round (inputs `[Z^ball, Z^stay]`, `Z_{t−1}`, and the simulated target `Z*_t`).
    rows: Vec<Rows>,
}

/// Regression rows of the linear path.
struct Rows {
    inertia: Tensor,
    previous: Tensor,
    drive: Tensor,
    target: Tensor,
}

impl Rows {
    fn cat(all: &[Rows]) -> Rows {
        let cat = |f: fn(&Rows) -> &Tensor| Tensor::cat(&all.iter().map(f).collect::<Vec<_>>(), 0);
        Rows {
            inertia: cat(|r| &r.inertia),
            previous: cat(|r| &r.previous),
            drive: cat(|r| &r.drive),
            target: cat(|r| &r.target),
        }
    }
}

impl MotionTrainer {
    /// Grows `file` (a dynamic model with its space trained) a motion encoder.
    /// `progress(done, total)` while every frame is encoded (twice: its latent, then its step's
    /// inputs; minutes on a many-take set).
    pub fn new(
        mut file: ModelFile,
        data: FrameData,
        fps: f64,
        settings: Settings,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<MotionTrainer> {
        if data.len() < 2 || settings.batch == 0 {
            bail!("nothing to train on: the motion encoder needs clips of at least two frames and a positive --batch");
        }
        tch::manual_seed(settings.seed as i64);
        let device = settings.device;
        let Model::Dynamic(dynamic) = &mut file.model else {
            bail!(
                "this is a PBNS model; --from needs a dynamic model (train-dynamic --stage space)"
            );
        };
        dynamic.space.freeze();
        let encoder = MotionEncoder::new(settings.shape.clone(), &dynamic.space, device);
        let fps = fps.max(1.0);
        let space = &dynamic.space;
        let history = history_indices(&data, device);
        let total = 2 * data.len();
        let latents = crate::models::predict_chunks(data.len(), |start, n| {
            let (g, b, m) = data.batch(&data.range(start, n));
            progress(start + n, total);
            space.encode(&g, &b, &m)
        });
        let statics = static_inputs(space, &data, &data.garment, &history, fps, &mut |done| {
            progress(data.len() + done, total)
        });
        let frames = Tensor::from_slice(&predicted_frames(&data)).to_device(device);
        let mut encoder = encoder;
        let fitted = statics.select(&frames);
        let before = data.body.select(&history[0].index_select(0, &frames));
        let drives = body_drive(&before, &data.body.select(&frames), &settings.shape, fps);
        let teacher = Rows {
            inertia: fitted.inertia,
            previous: fitted.previous_latent,
            drive: drives.shallow_clone(),
            target: latents.index_select(0, &frames),
        };
        encoder.init_linear(
            &teacher.inertia,
            &teacher.previous,
            &teacher.drive,
            &teacher.target,
            settings.ridge,
            settings.drive_ridge,
        );
        let (lo, hi) = latent_range(&latents);
        let params = encoder.parameters();
        let adam = Adam::new(
            &params
                .iter()
                .map(|(n, t)| (n.clone(), t))
                .collect::<Vec<_>>(),
        );
        let info = MotionInfo {
            shape: settings.shape.clone(),
            seed: settings.seed,
            batch: settings.batch,
            learning_rate: settings.learning_rate,
            motions: Vec::new(),
            frames: data.len(),
            ridge: settings.ridge,
            drive_ridge: settings.drive_ridge,
            latent_min: lo,
            latent_max: hi,
            history: Vec::new(),
            rollout_rounds: Vec::new(),
            settle: None,
            dynamics: None,
        };
        dynamic.motion = Some(encoder);
        match &mut file.info.model {
            KindInfo::Dynamic(d) => {
                d.motion = Some(MotionInfo {
                    motions: d.training.motions.clone(),
                    ..info
                });
                if !d.training.stages.iter().any(|s| s == "dynamic") {
                    d.training.stages.push("dynamic".into());
                }
            }
            KindInfo::Pbns(_) => unreachable!("checked above"),
        }
        Ok(MotionTrainer {
            file,
            data,
            settings,
            adam,
            fps,
            history,
            frames,
            statics,
            latents,
            drives,
            rows: vec![teacher],
        })
    }

    /// Roll-out-aware fit of the linear path ("data as demonstrator", Venkatraman et al. 2015):
    /// each round `roll`s the model out over every training clip (the caller decides how:
    /// `rollout::roll_out` from each clip's first simulated frame or restarted along it, with
    /// or without the collision fix) and returns what it made ([`Rolled`]); every
    /// predicted frame's inputs (a history the model made itself) join the rows with the
    /// simulated frame's latent as the target, and the linear path is refitted on all rows so
    /// far. The integrator thus learns to pull its own drifted states back, which teacher
    /// forcing never shows it. Returns each round's roll-out error on the training clips
    /// before its refit.
    pub fn fit_on_rollouts(
        &mut self,
        rounds: usize,
        roll: &mut dyn FnMut(&ModelFile, usize) -> Result<Rolled>,
    ) -> Result<Vec<RolloutRound>> {
        let mut done = Vec::new();
        for round in 0..rounds {
            let rolled = roll(&self.file, round)?;
            let frames = self.frames.size()[0];
            if rolled.predicted.size() != [frames]
                || rolled.back.iter().any(|b| b.size() != [frames])
            {
                bail!(
                    "a roll-out of {:?} predicted frames for training data with {frames}",
                    rolled.predicted.size()
                );
            }
            let predicted = rolled.garments.index_select(0, &rolled.predicted);
            let truth = self.data.garment.index_select(0, &self.frames);
            let error = deviation(&predicted, &truth);
            let space = &self.dynamic().space;
            let inputs = inputs_at(
                space,
                &self.data,
                (&rolled.garments, &rolled.back),
                &self.history,
                &self.frames,
                self.fps,
                &mut |_| {},
            );
            self.rows.push(Rows {
                target: self.latents.index_select(0, &self.frames),
                inertia: inputs.inertia,
                previous: inputs.previous_latent,
                drive: self.drives.shallow_clone(),
            });
            let all = Rows::cat(&self.rows);
            let (ridge, drive_ridge) = (self.settings.ridge, self.settings.drive_ridge);
            self.encoder_mut().init_linear(
                &all.inertia,
                &all.previous,
                &all.drive,
                &all.target,
                ridge,
                drive_ridge,
            );
            done.push(RolloutRound {
                round: round + 1,
                rows: all.target.size()[0] as usize,
                train_rollout_mean_mm: error.mean_mm,
            });
        }
        self.info_mut().rollout_rounds = done.clone();
        Ok(done)
    }

    /// Settles the fitted integrator towards the garment the pose alone predicts, fitted on
    /// the simulated frames ([`MotionEncoder::settle_towards`]): a deviation fades to `1/e` in
    /// `seconds`. The pose regression's ridge is `ridge`, or chosen leaving one clip out when
    /// none. Needs the body drive.
    pub fn settle_towards_pose(&mut self, seconds: f64, ridge: Option<f64>) -> Result<()> {
        let teacher = &self.rows[0];
        if teacher.drive.size()[1] == 0 {
            bail!("settling towards the pose needs the body drive (--body-drive)");
        }
        let clip = self.clip_of_rows();
        let ridges = ridge.map_or(POSE_RIDGES.to_vec(), |r| vec![r]);
        let (pose, held) =
            PoseRegression::fit_across_clips(&teacher.drive, &teacher.target, &clip, &ridges);
        let keep = keep_per_frame(seconds, self.fps);
        self.encoder_mut().settle_towards(&pose, keep);
        self.info_mut().settle = Some(Settled {
            seconds,
            pose_ridge: held.ridge,
            pose_explained_pct: Some(held.explained_pct),
        });
        Ok(())
    }

    /// The clip of each predicted frame (the teacher-forced rows' order).
    fn clip_of_rows(&self) -> Vec<usize> {
        let starts = &self.data.clip_starts;
        Vec::<i64>::try_from(&self.frames)
            .expect("frame indices")
            .iter()
            .map(|&t| starts.partition_point(|&s| s <= t as usize) - 1)
            .collect()
    }

    pub fn dynamic(&self) -> &Dynamic {
        match &self.file.model {
            Model::Dynamic(d) => d,
            Model::Pbns(_) => unreachable!("a dynamic trainer holds a dynamic model"),
        }
    }

    fn encoder(&self) -> &MotionEncoder {
        self.dynamic().motion.as_ref().expect("set in new")
    }

    fn encoder_mut(&mut self) -> &mut MotionEncoder {
        let Model::Dynamic(d) = &mut self.file.model else {
            unreachable!("a dynamic trainer holds a dynamic model")
        };
        d.motion.as_mut().expect("set in new")
    }

    pub fn info(&self) -> &MotionInfo {
        match &self.file.info.model {
            KindInfo::Dynamic(d) => d.motion.as_ref().expect("set in new"),
            KindInfo::Pbns(_) => unreachable!("a dynamic trainer holds a dynamic model"),
        }
    }

    fn info_mut(&mut self) -> &mut MotionInfo {
        match &mut self.file.info.model {
            KindInfo::Dynamic(d) => d.motion.as_mut().expect("set in new"),
            KindInfo::Pbns(_) => unreachable!("a dynamic trainer holds a dynamic model"),
        }
    }

    fn batch(&self, idx: &Tensor) -> Batch {
        let previous = self.history[0].index_select(0, idx);
        let h = teacher_history(&self.data, &self.history, idx, self.fps);
        Batch {
            inputs: motion_inputs(
                &self.dynamic().space,
                &h,
                &self.settings.shape,
                Some(self.statics.select(idx)),
            ),
            previous,
        }
    }

    /// One optimisation step on frames `idx`: the weighted terms and the batch's mean error (m).
    fn step(&mut self, idx: &Tensor, lr: f64) -> (MotionTerms, f64) {
        let batch = self.batch(idx);
        let (dynamic, encoder) = (self.dynamic(), self.encoder());
        let space = &dynamic.space;
        let e = encoder.dynamic_features(space, &batch.inputs);
        let z = encoder.latent(&batch.inputs, Some(&e));
        let zv = encoder.latent(&batch.inputs, None);
        let now = self.data.body.select(idx);
        let before = self.data.body.select(&batch.previous);
        let pred = space.skin(&space.canonical(&z), &now.transforms);
        let pred_v = space.skin(&space.canonical(&zv), &before.transforms);
        let target = self.data.garment.index_select(0, idx);
        let target_v = self.data.garment.index_select(0, &batch.previous);
        let l1 = |a: &Tensor, b: &Tensor| (a - b).abs().mean(Kind::Float);
        let geometry = l1(&pred, &target);
        let virtual_geometry = l1(&pred_v, &target_v);
        let latent = l1(&z, &self.latents.index_select(0, idx));
        let virtual_latent = l1(&zv, &self.latents.index_select(0, &batch.previous));
        let reg = |z: &Tensor| {
            (z.square().mean_dim(1, false, Kind::Float) - 1.0)
                .abs()
                .mean(Kind::Float)
        };
        let regulariser = (reg(&z) + reg(&zv)) * LAMBDA_REG;
        let loss = &geometry + &virtual_geometry + &latent + &virtual_latent + &regulariser;
        loss.backward();
        let err = tch::no_grad(|| {
            vertex_distance(&pred, &target)
                .mean(Kind::Float)
                .double_value(&[])
        });
        let (names, params): (Vec<String>, Vec<Tensor>) = encoder.parameters().into_iter().unzip();
        // The fitted linear path moves slowly (as the space's does).
        let lrs: Vec<f64> = names
            .iter()
            .map(|n| {
                if n.ends_with(".linear") {
                    lr * LINEAR_LR
                } else {
                    lr
                }
            })
            .collect();
        self.adam.update(&params, &lrs);
        let v = |t: &Tensor| t.double_value(&[]);
        (
            MotionTerms {
                geometry: v(&geometry),
                virtual_geometry: v(&virtual_geometry),
                latent: v(&latent),
                virtual_latent: v(&virtual_latent),
                regulariser: v(&regulariser),
            },
            err,
        )
    }

    /// Cosine decay from the learning rate to a tenth of it.
    fn learning_rate(&self, epoch: usize) -> f64 {
        super::cosine_rate(self.settings.learning_rate, epoch, self.settings.epochs)
    }
}

/// Per dimension, the latents' range widened by a tenth on each side.
fn latent_range(latents: &Tensor) -> (Vec<f32>, Vec<f32>) {
    let (lo, hi) = (latents.amin(0, false), latents.amax(0, false));
    let pad = (&hi - &lo) * 0.1;
    let v = |t: Tensor| Vec::<f32>::try_from(t).unwrap_or_default();
    (v(&lo - &pad), v(&hi + &pad))
}

/// Per-vertex L2 distance `[B, V]`.
pub fn vertex_distance(a: &Tensor, b: &Tensor) -> Tensor {
    (a - b)
        .square()
        .sum_dim_intlist(2, false, Kind::Float)
        .sqrt()
}

/// One-step predictions (teacher-forced histories) of every frame that has a previous frame in
/// its clip, against the simulation; `progress(done, total)` after each chunk of frames. A
/// linear model ([`Dynamic::linear_only`], every model with learnt dynamics) blends each
/// frame's seeds once (`unroll::one_step_linear`); one with networks blends them per encode.
pub fn one_step(
    dynamic: &Dynamic,
    data: &FrameData,
    fps: f64,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Deviation> {
    let encoder = dynamic.motion()?;
    let frames = predicted_frames(data);
    if dynamic.linear_only() {
        return Ok(super::unroll::one_step_linear(
            dynamic, data, fps, &frames, progress,
        ));
    }
    let space = &dynamic.space;
    let history = history_indices(data, space.consts.rest.device());
    let idx_all = Tensor::from_slice(&frames).to_device(space.consts.rest.device());
    let pred = crate::models::predict_chunks(frames.len(), |s, n| {
        let idx = idx_all.narrow(0, s as i64, n as i64);
        let h = teacher_history(data, &history, &idx, fps);
        let x = motion_inputs(space, &h, &encoder.shape, None);
        let z = encoder.latent(&x, Some(&encoder.dynamic_features(space, &x)));
        let skinned = space.skin(&space.canonical(&z), &h.now.transforms);
        progress(s + n, frames.len());
        skinned
    });
    let truth = data.garment.index_select(0, &idx_all);
    Ok(deviation(&pred, &truth))
}

impl Training for MotionTrainer {
    type Record = MotionEpoch;

    fn epochs_done(&self) -> usize {
        self.info().history.len()
    }

    fn run_epoch(&mut self) -> Result<MotionEpoch, Blowup> {
        let epoch = self.epochs_done();
        tch::manual_seed(
            (self.settings.seed as i64)
                .wrapping_mul(1_000_003)
                .wrapping_add(epoch as i64),
        );
        let lr = self.learning_rate(epoch);
        let n = self.frames.size()[0];
        let order = self
            .frames
            .index_select(0, &Tensor::randperm(n, (Kind::Int64, self.settings.device)));
        let batch = self.settings.batch as i64;
        let mut sum = MotionTerms::default();
        let (mut err, mut steps) = (0.0, 0usize);
        for (step, start) in (0..n).step_by(batch as usize).enumerate() {
            let idx = order.narrow(0, start, batch.min(n - start));
            let (t, e) = self.step(&idx, lr);
            Blowup::check(
                &[
                    ("geometry", t.geometry),
                    ("virtual geometry", t.virtual_geometry),
                    ("latent", t.latent),
                    ("virtual latent", t.virtual_latent),
                ],
                epoch,
                step,
            )?;
            sum.geometry += t.geometry;
            sum.virtual_geometry += t.virtual_geometry;
            sum.latent += t.latent;
            sum.virtual_latent += t.virtual_latent;
            sum.regulariser += t.regulariser;
            err += e;
            steps += 1;
        }
        let k = steps.max(1) as f64;
        let terms = MotionTerms {
            geometry: sum.geometry / k,
            virtual_geometry: sum.virtual_geometry / k,
            latent: sum.latent / k,
            virtual_latent: sum.virtual_latent / k,
            regulariser: sum.regulariser / k,
        };
        let record = MotionEpoch {
            epoch: epoch + 1,
            loss: terms.total(),
            terms,
            learning_rate: lr,
            train_mean_mm: 1e3 * err / k,
        };
        self.info_mut().history.push(record.clone());
        Ok(record)
    }

    fn save(&mut self, path: &Path, checkpoint: bool) -> Result<()> {
        self.file.extra = if checkpoint {
            let p = self.encoder().parameters();
            self.adam
                .state(&p.iter().map(|(n, t)| (n.clone(), t)).collect::<Vec<_>>())
        } else {
            Vec::new()
        };
        file::save(path, &self.file)
    }

    fn resume(&mut self, path: &Path) -> Result<()> {
        let checkpoint = file::load(path, self.settings.device)?;
        let theirs = checkpoint.info.dynamic()?;
        let (Some(theirs_motion), Ok(dynamic)) = (&theirs.motion, checkpoint.dynamic()) else {
            bail!(
                "{}: checkpoint has no motion encoder; start without --resume",
                path.display()
            );
        };
        let mine = self.info();
        if theirs_motion.shape != mine.shape
            || theirs_motion.seed != mine.seed
            || theirs_motion.motions != mine.motions
            || checkpoint.info.garment.rest_hash != self.file.info.garment.rest_hash
        {
            bail!("{}: checkpoint was made with other inputs or settings (garment, clips, seed); start without --resume", path.display());
        }
        let history = theirs_motion.history.clone();
        // The fitted path comes back as it was fitted: its rounds and settling with it.
        let (rounds, settle) = (theirs_motion.rollout_rounds.clone(), theirs_motion.settle);
        let stored = dynamic.motion()?.parameters();
        self.encoder_mut().load_parameters(&stored)?;
        let p = self.encoder().parameters();
        self.adam.restore(
            &p.iter().map(|(n, t)| (n.clone(), t)).collect::<Vec<_>>(),
            &checkpoint.extra,
        )?;
        let info = self.info_mut();
        (info.history, info.rollout_rounds, info.settle) = (history, rounds, settle);
        Ok(())
    }

    fn describe(r: &MotionEpoch) -> String {
        format!("loss {:.4} one-step mean {:.1} mm", r.loss, r.train_mean_mm)
    }
}
