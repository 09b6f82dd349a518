//! Unsupervised PBNS training: the loop (Adam, balanced pose batches, candidate nearest
//! neighbours), validation metrics, checkpoints, the NaN guard and resume.

pub mod fabric;
pub mod losses;
pub mod nearest;
pub mod poses;

use crate::eval::{ClothGeometry, Metrics, PosedBody};
use crate::garment::Garment;
use crate::io::gltf_body::Body;
use crate::models::file::{
    points_hash, BodyInfo, EpochRecord, GarmentInfo, ModelFile, ModelInfo, SkeletonInfo,
    TrainingInfo, UvInfo, FORMAT, VERSION,
};
use crate::models::pbns::flat;
use crate::models::pose_features::{tensor_points, PoseBatch, PER_JOINT};
use crate::models::{Pbns, PbnsShape};
use crate::rig::{weights, SkelAnimation};
use anyhow::{bail, Result};
use fabric::Fabric;
use losses::{Cloth, TERM_NAMES};
use nearest::Correspondences;
use poses::PoseSet;
use std::time::{Duration, Instant};
use tch::{Device, Kind, Tensor};

/// Body vertices this close to the garment at rest (metres) are the parts it can touch.
const TOUCH: f32 = 0.05;

/// Training settings (the CLI's options).
#[derive(Clone, Debug)]
pub struct Settings {
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f64,
    /// The learning rate decays (cosine) to this fraction of the initial one at the last epoch.
    pub final_lr_fraction: f64,
    pub width: usize,
    pub layers: usize,
    pub influences: usize,
    pub train_weights: bool,
    pub seed: u64,
    pub pose_threshold: f32,
    /// A joint is compared for pose balancing if its subtree carries this share of the skin.
    pub joint_share: f32,
    pub validation: f32,
    /// Recombined training poses per real one (limb chains from different frames).
    pub recombine: usize,
    /// Body vertices averaged for the proximity weights.
    pub neighbours: usize,
    /// Candidate body vertices per garment vertex.
    pub candidates: usize,
    /// Epochs between candidate refreshes.
    pub refresh_every: usize,
    /// Refresh candidates by brute force on the device (GPU) instead of CPU k-d trees.
    pub dense_refresh: bool,
    /// Body vertices farther than this from the garment at rest are never nearest.
    pub reach: f32,
    pub device: Device,
    /// Learning rate of the skin logits relative to the network's.
    pub weights_lr_scale: f64,
    /// Epochs between validation passes (the last epoch is always validated).
    pub validate_every: usize,
    /// Garment vertices farther than this from the body at rest get inpainted weights.
    pub inpaint_beyond: Option<f32>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            epochs: 100,
            batch: 16,
            learning_rate: 1e-3,
            final_lr_fraction: 0.1,
            width: 256,
            layers: 4,
            influences: 4,
            train_weights: true,
            seed: 0,
            pose_threshold: 0.2,
            joint_share: 0.01,
            validation: 0.15,
            recombine: 0,
            neighbours: 8,
            candidates: 8,
            refresh_every: 2,
            dense_refresh: false,
            reach: 0.3,
            device: Device::Cpu,
            weights_lr_scale: 10.0,
            validate_every: 5,
            inpaint_beyond: Some(0.02),
        }
    }
}

/// What training reads.
pub struct Inputs {
    pub body: Body,
    pub garment: Garment,
    pub fabric: Fabric,
    pub clips: Vec<SkelAnimation>,
    /// Clip file names (no directories), for the model description.
    pub motion_names: Vec<String>,
}

/// Wall time per phase of the training steps.
#[derive(Clone, Copy, Debug, Default)]
pub struct PhaseTimes {
    pub forward: Duration,
    pub nearest: Duration,
    pub losses: Duration,
    pub backward: Duration,
    /// Candidate upkeep on the training thread (snapshot forward passes, installing lists,
    /// waiting for a worker, synchronous refreshes): part of nearest neighbour.
    pub refresh: Duration,
    pub steps: usize,
    pub poses: usize,
    /// Validation passes (not part of the step time).
    pub validation: Duration,
}

impl PhaseTimes {
    pub fn total(&self) -> Duration {
        self.forward + self.nearest + self.losses + self.backward + self.refresh
    }
}

/// The loss became NaN or infinite.
#[derive(Debug, thiserror::Error)]
#[error("the loss became {value} at epoch {epoch}, step {step}: the {term} term blew up")]
pub struct Blowup {
    pub epoch: usize,
    pub step: usize,
    pub term: &'static str,
    pub value: f64,
}

pub struct Trainer {
    pub settings: Settings,
    pub file: ModelFile,
    pub poses: PoseSet,
    pub times: PhaseTimes,
    cloth: Cloth,
    train: PoseBatch,
    validation: PoseBatch,
    correspondences: Correspondences,
    validation_bodies: Vec<PosedBody>,
    geometry: ClothGeometry,
    adam: Adam,
    refreshed: bool,
    /// A candidate refresh running on a worker thread, applied at the next epoch.
    pending: Option<std::thread::JoinHandle<Vec<i64>>>,
}

/// Sums of one epoch's step values.
#[derive(Default)]
struct EpochSums {
    steps: usize,
    values: [f64; 9],
}

impl Trainer {
    /// Builds the pose set, the model (proximity weights) and all precomputed tensors.
    pub fn new(inputs: Inputs, settings: Settings) -> Result<Trainer> {
        if settings.batch == 0 || settings.width == 0 || settings.layers == 0 {
            bail!("--batch, --width and the layer count must be positive");
        }
        if ![4, 8].contains(&settings.influences) {
            bail!(
                "--influences must be 4 or 8 (what engines play), not {}",
                settings.influences
            );
        }
        tch::manual_seed(settings.seed as i64);
        let Inputs {
            body,
            garment,
            fabric,
            clips,
            motion_names,
        } = inputs;
        let device = settings.device;
        let rest = &garment.mesh.positions;
        let body_index = crate::geometry::PointIndex::new(&body.mesh.positions)?;
        let (lbs, inpainted) = weights::garment_skin(
            &garment.mesh,
            &body.skin,
            body.skeleton.joint_count(),
            &body_index,
            settings.neighbours,
            settings.influences,
            settings.inpaint_beyond,
        );
        let joints = garment_joints(&body, rest, &lbs, settings.joint_share);
        let mut poses = poses::pose_set(
            &clips,
            joints,
            settings.pose_threshold,
            settings.validation,
            settings.seed,
        );
        let extra = poses::recombined(
            &poses.train,
            &body.skeleton,
            settings.recombine * poses.train.len(),
            poses::RECOMBINE_AMPLIFY,
            settings.seed,
        );
        poses.train.extend(extra);
        if poses.train.is_empty() || poses.validation.is_empty() {
            bail!(
                "only {} balanced poses from {} frames: add clips or lower --pose-threshold",
                poses.train.len() + poses.validation.len(),
                poses.frames_seen
            );
        }
        let shape = PbnsShape {
            features: PER_JOINT * poses.joints.len(),
            width: settings.width,
            layers: settings.layers,
            vertices: rest.len(),
            joints: body.skeleton.joint_count(),
            influences: settings.influences,
        };
        let mut model = Pbns::new(
            shape,
            poses.joints.clone(),
            rest,
            &lbs,
            &body.skeleton,
            device,
        );
        model.set_trainable(settings.train_weights);
        let pinned_list = pinned_vertices(&fabric, &garment)?;
        let cloth = Cloth::new(&garment.mesh, &fabric, &pinned_list, device)?;
        let locals = |set: &[poses::Pose]| set.iter().map(|p| p.local.clone()).collect::<Vec<_>>();
        let train_locals = locals(&poses.train);
        let validation_locals = locals(&poses.validation);
        let subset = nearest::body_subset(&body, rest, settings.reach);
        let correspondences = Correspondences::new(
            &body,
            &subset,
            &train_locals,
            settings.candidates,
            rest.len(),
            device,
        );
        let info = describe(
            &body,
            &garment,
            &fabric,
            &settings,
            &poses,
            shape,
            &pinned_list,
            motion_names,
            inpainted,
        );
        let adam = Adam::new(&model.parameters(settings.train_weights));
        Ok(Trainer {
            train: model.batch(&body.skeleton, &train_locals, device),
            validation: model.batch(&body.skeleton, &validation_locals, device),
            validation_bodies: PosedBody::many(&body, &validation_locals),
            geometry: ClothGeometry::new(&garment.mesh, fabric.density),
            file: ModelFile {
                model,
                info,
                lbs,
                garment: garment.mesh,
                body,
                extra: Vec::new(),
            },
            settings,
            poses,
            times: PhaseTimes::default(),
            cloth,
            correspondences,
            adam,
            refreshed: false,
            pending: None,
        })
    }

    /// The training poses, precomputed for the network.
    pub fn train_batch(&self) -> &PoseBatch {
        &self.train
    }

    pub fn correspondences(&self) -> &Correspondences {
        &self.correspondences
    }

    pub fn model(&self) -> &Pbns {
        &self.file.model
    }

    pub fn fabric(&self) -> &Fabric {
        &self.file.info.fabric
    }

    /// Epochs done so far.
    pub fn epoch(&self) -> usize {
        self.file.info.history.len()
    }

    /// Steps in one epoch.
    pub fn steps_per_epoch(&self) -> usize {
        self.train.len().div_ceil(self.settings.batch)
    }

    /// Learning rate of `epoch`: cosine decay to `final_lr_fraction`.
    pub fn learning_rate(&self, epoch: usize) -> f64 {
        let s = &self.settings;
        let t = epoch as f64 / (s.epochs.max(2) - 1) as f64;
        let f = s.final_lr_fraction
            + (1.0 - s.final_lr_fraction) * 0.5 * (1.0 + (std::f64::consts::PI * t.min(1.0)).cos());
        s.learning_rate * f
    }

    /// Garment positions of every training pose (no gradients).
    fn predict_train(&self) -> Vec<Vec<[f32; 3]>> {
        predict(self.model(), &self.train)
    }

    /// Candidate upkeep at the start of an epoch. Every `refresh_every` epochs the model's
    /// output is snapshot and the k-d trees are queried on a worker thread while training goes
    /// on; the lists are installed at the next due epoch, so the worker has `refresh_every`
    /// epochs of steps to finish and the training thread rarely waits. The first epoch of a
    /// run refreshes synchronously. Deterministic: snapshots and installs happen at fixed epochs.
    fn upkeep(&mut self) {
        let t = Instant::now();
        if self.settings.dense_refresh {
            if !self.refreshed
                || self
                    .epoch()
                    .is_multiple_of(self.settings.refresh_every.max(1))
            {
                self.refresh_dense();
            }
            self.times.refresh += t.elapsed();
            return;
        }
        let fresh = !self.refreshed;
        if fresh {
            self.refresh();
        }
        if fresh
            || self
                .epoch()
                .is_multiple_of(self.settings.refresh_every.max(1))
        {
            self.finish_refresh();
            self.start_refresh();
        }
        self.times.refresh += t.elapsed();
    }

    /// New nearest-body-vertex candidate lists from the model's current output, now.
    pub fn refresh(&mut self) {
        let x = self.predict_train();
        self.correspondences.refresh(&x);
        self.refreshed = true;
    }

    /// The same by brute force on the device (see [`Correspondences::refresh_dense`]).
    pub fn refresh_dense(&mut self) {
        let x = predict_tensor(self.model(), &self.train);
        self.correspondences.refresh_dense(&x);
        self.refreshed = true;
    }

    /// Starts a refresh on a worker thread (see [`Trainer::upkeep`]); `finish_refresh` installs it.
    pub fn start_refresh(&mut self) {
        let x = self.predict_train();
        self.pending = Some(self.correspondences.spawn_refresh(x));
    }

    /// Waits for a pending refresh and installs it; returns whether there was one.
    pub fn finish_refresh(&mut self) -> bool {
        match self.pending.take() {
            Some(job) => {
                let lists = job.join().expect("candidate refresh worker panicked");
                self.correspondences.apply(lists);
                true
            }
            None => false,
        }
    }

    /// One optimisation step on the training poses `ids`.
    pub fn step(&mut self, ids: &[i64], lr: f64) -> Result<[f64; 9], Blowup> {
        let device = self.settings.device;
        let t0 = Instant::now();
        let index = Tensor::from_slice(ids).to_device(device);
        let batch = self.train.select(&index);
        let out = self.file.model.forward(&batch);
        let t1 = Instant::now();
        let (body_points, body_normals) = self.correspondences.resolve(&index, &out.vertices);
        let t2 = Instant::now();
        let fabric = &self.file.info.fabric;
        let terms = losses::potential(
            &self.cloth,
            fabric,
            &out.vertices,
            &out.displacement,
            &body_points,
            &body_normals,
        );
        let loss = terms.total();
        let mut all: Vec<Tensor> = terms.weighted.iter().map(Tensor::detach).collect();
        all.extend(terms.metrics.iter().map(Tensor::shallow_clone));
        let values: Vec<f64> = flat(&Tensor::stack(&all, 0), Kind::Double);
        let t3 = Instant::now();
        if let Some(k) = (0..5).find(|&k| !values[k].is_finite()) {
            return Err(Blowup {
                epoch: self.epoch() + 1,
                step: self.adam.step as usize + 1,
                term: TERM_NAMES[k],
                value: values[k],
            });
        }
        loss.backward();
        let named = self.model().parameters(self.settings.train_weights);
        // The skin logits move on another scale than the network (a weight going from 1e-4 to
        // 0.5 is a logit change of ~9): they get a larger learning rate.
        let rates: Vec<f64> = named
            .iter()
            .map(|(n, _)| {
                if n == "W.logits" {
                    lr * self.settings.weights_lr_scale
                } else {
                    lr
                }
            })
            .collect();
        let params: Vec<Tensor> = named.into_iter().map(|(_, t)| t.shallow_clone()).collect();
        self.adam.update(&params, &rates);
        let t4 = Instant::now();
        let times = &mut self.times;
        times.forward += t1 - t0;
        times.nearest += t2 - t1;
        times.losses += t3 - t2;
        times.backward += t4 - t3;
        times.steps += 1;
        times.poses += ids.len();
        let mut out = [0.0; 9];
        out.copy_from_slice(&values);
        Ok(out)
    }

    /// Runs one epoch; `on_step(done, total)` after each step. Appends to the history.
    pub fn run_epoch(
        &mut self,
        mut on_step: impl FnMut(usize, usize),
    ) -> Result<EpochRecord, Blowup> {
        self.upkeep();
        let epoch = self.epoch();
        let lr = self.learning_rate(epoch);
        let mut order: Vec<i64> = (0..self.train.len() as i64).collect();
        poses::shuffle(
            &mut order,
            self.settings
                .seed
                .wrapping_add(1 + epoch as u64)
                .wrapping_mul(0x2545_F491_4F6C_DD1D),
        );
        let total = self.steps_per_epoch();
        let mut sums = EpochSums::default();
        for (s, ids) in order.chunks(self.settings.batch).enumerate() {
            let v = self.step(ids, lr)?;
            for (a, b) in sums.values.iter_mut().zip(v) {
                *a += b;
            }
            sums.steps += 1;
            on_step(s + 1, total);
        }
        let n = sums.steps.max(1) as f64;
        let m = sums.values.map(|v| v / n);
        let record = EpochRecord {
            epoch: epoch + 1,
            loss: m[..5].iter().sum(),
            terms: [m[0], m[1], m[2], m[3], m[4]],
            train: Metrics {
                edge_mm: 1e3 * m[5],
                bend: m[6],
                collided_pct: 100.0 * m[7],
                collided_overlap_pct: 0.0,
                gravity_j: m[8],
            },
            validation: self.validation_due(epoch + 1).then(|| self.validate()),
        };
        self.file.info.history.push(record.clone());
        self.file.info.training.epochs = self.epoch();
        Ok(record)
    }

    /// Validation runs every `validate_every` epochs and after the last one.
    fn validation_due(&self, epochs_done: usize) -> bool {
        epochs_done.is_multiple_of(self.settings.validate_every.max(1))
            || epochs_done >= self.settings.epochs
    }

    /// Exact metrics on the validation poses.
    pub fn validate(&mut self) -> Metrics {
        let t = Instant::now();
        let x = predict(self.model(), &self.validation);
        let m = self.geometry.frames(&x, &self.validation_bodies);
        self.times.validation += t.elapsed();
        m
    }

    /// The model file with the current weights (no optimizer state).
    pub fn model_file(&self) -> &ModelFile {
        &self.file
    }

    /// Writes the model; with `checkpoint`, the Adam state too (for `--resume`).
    pub fn save(&mut self, path: &std::path::Path, checkpoint: bool) -> Result<()> {
        self.file.extra = if checkpoint {
            self.adam
                .state(&self.model().parameters(self.settings.train_weights))
        } else {
            Vec::new()
        };
        let r = crate::models::file::save(path, &self.file);
        self.file.extra.clear();
        r
    }

    /// Continues from a checkpoint written by [`Trainer::save`] for the same inputs.
    pub fn resume(&mut self, checkpoint: ModelFile, path: &std::path::Path) -> Result<()> {
        let (mine, theirs) = (&self.file.info, &checkpoint.info);
        let same = mine.shape == theirs.shape
            && mine.garment == theirs.garment
            && mine.body == theirs.body
            && mine.skeleton == theirs.skeleton
            && mine.fabric == theirs.fabric
            && mine.training.seed == theirs.training.seed
            && mine.training.poses_train == theirs.training.poses_train
            && mine.training.train_weights == theirs.training.train_weights;
        if !same {
            bail!(
                "{}: checkpoint was made with other inputs or settings (garment, body, fabric, seed, width, influences, poses); start without --resume",
                path.display()
            );
        }
        let mut model = checkpoint.model;
        model.set_trainable(self.settings.train_weights);
        self.file.model = model;
        self.file.info.history = checkpoint.info.history.clone();
        self.file.info.training.epochs = self.epoch();
        let params = self.file.model.parameters(self.settings.train_weights);
        self.adam.restore(&params, &checkpoint.extra)?;
        self.refreshed = false;
        Ok(())
    }
}

/// Joints that move the garment, or the body parts it can touch (a long skirt's hem meets the
/// feet, whose weights are not on the skirt): the pose-balancing joints and the MLP inputs.
fn garment_joints(
    body: &Body,
    rest: &[[f32; 3]],
    skin: &crate::rig::Skin,
    share: f32,
) -> Vec<usize> {
    let touched = body.skin.subset(&nearest::body_subset(body, rest, TOUCH));
    let mut joints = poses::moving_joints(&body.skeleton, skin, share);
    joints.extend(poses::moving_joints(&body.skeleton, &touched, 0.5 * share));
    joints.sort_unstable();
    joints.dedup();
    joints
}

/// The fabric's pin set, else the garment sidecar's; checked against the vertex count.
fn pinned_vertices(fabric: &Fabric, garment: &Garment) -> Result<Vec<u32>> {
    let pinned = fabric
        .pinned
        .clone()
        .unwrap_or_else(|| garment.sidecar.pinned.clone());
    let n = garment.mesh.vertex_count();
    if let Some(bad) = pinned.iter().find(|&&v| v as usize >= n) {
        bail!(
            "fabric '{}': pinned vertex {bad} out of range ({n} vertices)",
            fabric.name
        );
    }
    Ok(pinned)
}

/// The model description written into the file's metadata (no history yet).
#[allow(clippy::too_many_arguments)]
fn describe(
    body: &Body,
    garment: &Garment,
    fabric: &Fabric,
    settings: &Settings,
    poses: &PoseSet,
    shape: PbnsShape,
    pinned_list: &[u32],
    motion_names: Vec<String>,
    inpainted: usize,
) -> ModelInfo {
    let rest = &garment.mesh.positions;
    ModelInfo {
        format: FORMAT.into(),
        version: VERSION,
        shape,
        skeleton: SkeletonInfo::new(&body.skeleton, poses.joints.clone()),
        garment: GarmentInfo {
            name: garment.name.clone(),
            vertices: rest.len(),
            faces: garment.mesh.triangles.clone(),
            uv: garment.mesh.uv.as_ref().map(|uv| UvInfo {
                coords: uv.coords.clone(),
                triangles: uv.triangles.clone(),
            }),
            pinned: pinned_list.to_vec(),
            rest_hash: points_hash(rest),
        },
        body: BodyInfo {
            name: body.name.clone(),
            vertices: body.mesh.vertex_count(),
            rest_hash: points_hash(&body.mesh.positions),
        },
        fabric: fabric.clone(),
        training: TrainingInfo {
            seed: settings.seed,
            epochs: 0,
            batch: settings.batch,
            learning_rate: settings.learning_rate,
            train_weights: settings.train_weights,
            motions: motion_names,
            pose_threshold: settings.pose_threshold,
            poses_train: poses.train.len(),
            poses_validation: poses.validation.len(),
            poses_recombined: poses.train.iter().filter(|p| p.recombined).count(),
            inpaint_beyond: settings.inpaint_beyond,
            inpainted,
        },
        history: Vec::new(),
    }
}

/// Poses per forward pass when predicting without gradients.
const PREDICT_CHUNK: usize = 64;

/// The model's garment for every pose of a precomputed batch, in chunks, without gradients.
pub fn predict(model: &Pbns, poses: &PoseBatch) -> Vec<Vec<[f32; 3]>> {
    let n = model.shape.vertices;
    tensor_points(&predict_tensor(model, poses))
        .chunks_exact(n)
        .map(<[_]>::to_vec)
        .collect()
}

/// [`predict`] as one `[P, N, 3]` tensor on the model's device.
pub fn predict_tensor(model: &Pbns, poses: &PoseBatch) -> Tensor {
    tch::no_grad(|| {
        let n = poses.len();
        if n == 0 {
            let shape = [0, model.shape.vertices as i64, 3];
            return Tensor::zeros(shape, (Kind::Float, poses.features.device()));
        }
        let parts: Vec<Tensor> = (0..n)
            .step_by(PREDICT_CHUNK)
            .map(|s| {
                model
                    .forward(&poses.slice(s, PREDICT_CHUNK.min(n - s)))
                    .vertices
            })
            .collect();
        Tensor::cat(&parts, 0)
    })
}

/// Adam (Kingma & Ba) written out, so its state can go into checkpoints and resume exactly.
pub struct Adam {
    step: i64,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
}

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPSILON: f64 = 1e-8;

impl Adam {
    fn new(params: &[(String, &Tensor)]) -> Adam {
        Adam {
            step: 0,
            m: params.iter().map(|(_, p)| p.zeros_like()).collect(),
            v: params.iter().map(|(_, p)| p.zeros_like()).collect(),
        }
    }

    /// One Adam step; `lr[i]` is parameter `i`'s learning rate.
    fn update(&mut self, params: &[Tensor], lr: &[f64]) {
        self.step += 1;
        let c1 = 1.0 - BETA1.powi(self.step as i32);
        let c2 = 1.0 - BETA2.powi(self.step as i32);
        tch::no_grad(|| {
            for (((p, m), v), &lr) in params.iter().zip(&mut self.m).zip(&mut self.v).zip(lr) {
                let mut g = p.grad();
                if !g.defined() {
                    continue;
                }
                let _ = m.lerp_(&g, 1.0 - BETA1);
                let _ = v.g_mul_scalar_(BETA2);
                let _ = v.addcmul_(&(&g * (1.0 - BETA2)), &g);
                let denom = (v.g_div_scalar(c2)).sqrt() + EPSILON;
                let mut p = p.shallow_clone();
                let _ = p.addcdiv_(&(&*m * (-lr / c1)), &denom);
                let _ = g.zero_();
            }
        });
    }

    fn state(&self, params: &[(String, &Tensor)]) -> Vec<(String, Tensor)> {
        let mut out = vec![(
            "adam.step".to_string(),
            Tensor::from_slice(&[self.step as f32]),
        )];
        for ((name, _), (m, v)) in params.iter().zip(self.m.iter().zip(&self.v)) {
            out.push((format!("adam.m.{name}"), m.shallow_clone()));
            out.push((format!("adam.v.{name}"), v.shallow_clone()));
        }
        out
    }

    fn restore(&mut self, params: &[(String, &Tensor)], saved: &[(String, Tensor)]) -> Result<()> {
        let find = |name: &str| -> Result<&Tensor> {
            saved
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, t)| t)
                .ok_or_else(|| {
                    anyhow::anyhow!("checkpoint has no '{name}' (a model file, not a checkpoint?)")
                })
        };
        self.step = find("adam.step")?.double_value(&[0]) as i64;
        for (i, (name, p)) in params.iter().enumerate() {
            self.m[i] = find(&format!("adam.m.{name}"))?.to_device(p.device());
            self.v[i] = find(&format!("adam.v.{name}"))?.to_device(p.device());
        }
        Ok(())
    }
}
