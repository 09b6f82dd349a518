//! Training a swing on a trained PBNS, from physics alone: the quasi-static part stays frozen
//! and the swing's weights minimise, frame after frame, the incremental potential of an implicit
//! Euler step — the PBNS potential plus inertia `Σ m_i/(2Δt²)·|x_t − 2x_{t−1} + x_{t−2}|²`.
//!
//! The earlier frames come from the model itself: every training frame keeps the swing weights
//! the model last gave it (a whole pass over each clip in order at every epoch, and each step's
//! own output written back), and a step unrolls a few frames from those. The past is detached:
//! each frame's loss trains the step from the state it was given, as a time integrator is
//! judged, not a trajectory bent to make later frames cheaper.

use super::adam::Adam;
use super::losses::{self, Cloth};
use super::nearest::{self, Correspondences};
use super::poses::{shuffle, Rng};
use super::{Blowup, Training};
use crate::models::file::{KindInfo, LossTerms, ModelFile, SwingEpoch, SwingInfo, SwingTraining};
use crate::models::pbns::flat;
use crate::models::pose_features::{tensor_points, PER_JOINT};
use crate::models::swing::{self, Swing, SwingIntegrator, SwingShape};
use crate::models::{Model, Pbns, PREDICT_CHUNK};
use crate::rig::SkelAnimation;
use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::ops::Range;
use std::path::Path;
use std::time::Instant;
use tch::{Device, Kind, Tensor};

/// The swing's first blend shapes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SwingBasis {
    /// Joint turns (a joint's share of the skirt turned about it) and the edge graph's slowest
    /// Laplacian modes along x, y and z.
    Turns,
    /// The garment's least-stretching smooth motions (`isometric_shapes`): the pinned cloth's
    /// lowest edge-strain modes within its smoothest displacement fields.
    Isometric,
}

/// Training settings (the CLI's options).
#[derive(Clone, Debug)]
pub struct Settings {
    pub epochs: usize,
    /// Sequences per step.
    pub batch: usize,
    /// Frames unrolled per sequence.
    pub unroll: usize,
    pub learning_rate: f64,
    pub width: usize,
    pub layers: usize,
    pub shapes: usize,
    /// Swing bones: the joints carrying most of the garment's skin, each turned by the network
    /// (`models::swing::SwingShape::bones`); 0 for blend shapes only.
    pub bones: usize,
    /// Where the swing's blend shapes start (`SwingBasis`).
    pub basis: SwingBasis,
    /// How the weights are stepped (`models::swing::SwingIntegrator`).
    pub integrator: SwingIntegrator,
    pub lags: Vec<usize>,
    pub fps: f32,
    /// Weight of the inertia term (1: physical; 0 turns the dynamics off, for ablations).
    pub inertia: f32,
    pub seed: u64,
    /// Candidate body vertices per garment vertex, and epochs between their refreshes.
    pub candidates: usize,
    pub refresh_every: usize,
    /// Body vertices farther than this from the garment at rest are never nearest (metres).
    pub reach: f32,
    pub device: Device,
}

impl Settings {
    /// The documented recipe (docs/swing.md).
    pub fn recipe() -> Settings {
        Settings {
            epochs: 30,
            batch: 16,
            unroll: 3,
            learning_rate: 3e-3,
            width: 128,
            layers: 2,
            shapes: 32,
            bones: 0,
            basis: SwingBasis::Turns,
            integrator: SwingIntegrator::Network,
            lags: vec![0, 1, 2, 4, 8],
            fps: 30.0,
            // The fabric's own density leaves the sample skirt all but still (docs/swing.md).
            inertia: 100.0,
            seed: 0,
            candidates: 6,
            refresh_every: 2,
            reach: 0.3,
            device: Device::Cpu,
        }
    }
}

/// The clips a swing learns from (already retargeted and at `Settings::fps`).
pub struct Inputs {
    /// A trained PBNS (its network stays as it is).
    pub model: ModelFile,
    pub clips: Vec<SkelAnimation>,
    pub motion_names: Vec<String>,
}

impl Inputs {
    /// The clips retargeted onto the model's skeleton at `fps`.
    pub fn read(
        model: ModelFile,
        motions: &[std::path::PathBuf],
        reader: &crate::motion::ClipReader,
        fps: f32,
    ) -> Result<Inputs> {
        let mut clips = Vec::new();
        let mut motion_names = Vec::new();
        for m in motions {
            clips.push(crate::motion::load_clip(m, reader, &model.body, Some(fps))?.animation);
            motion_names.push(
                m.file_name()
                    .map_or(String::new(), |n| n.to_string_lossy().into_owned()),
            );
        }
        Ok(Inputs {
            model,
            clips,
            motion_names,
        })
    }
}

pub struct Trainer {
    pub settings: Settings,
    file: ModelFile,
    cloth: Cloth,
    /// Every training frame of every clip, concatenated: pose features `[G, P]`, skinning
    /// `[G, J, 12]`, the quasi-static rest garment `T + X·D` `[G, N, 3]`, raw motion inputs `[G, M]`.
    features: Tensor,
    skinning: Tensor,
    rest: Tensor,
    motion: Tensor,
    /// Each clip's frames in the concatenation.
    clips: Vec<Range<usize>>,
    /// Frames a sequence may start at (two earlier frames and the unroll inside its clip).
    starts: Vec<usize>,
    /// The swing weights the model last gave every frame `[G, S]`.
    states: Tensor,
    correspondences: Correspondences,
    adam: Adam,
    rng: Rng,
    dt: f64,
}

/// One epoch as logged.
#[derive(Clone, Debug, Serialize)]
pub struct EpochLine {
    #[serde(flatten)]
    pub record: SwingEpoch,
    pub learning_rate: f64,
}

impl Trainer {
    pub fn new(inputs: Inputs, settings: Settings) -> Result<Trainer> {
        if settings.batch == 0 || settings.unroll == 0 {
            bail!("--batch and --unroll must be positive");
        }
        if settings.shapes + settings.bones == 0 {
            bail!("--shapes and --bones are both 0: the swing would have nothing to move");
        }
        if settings.fps <= 0.0 {
            bail!("--fps must be positive");
        }
        if settings.integrator == SwingIntegrator::Modal
            && (settings.bones > 0 || settings.shapes == 0)
        {
            bail!("--integrator modal steps blend shapes only: give --shapes and --bones 0");
        }
        tch::manual_seed(settings.seed as i64);
        let Inputs {
            mut model,
            clips,
            motion_names,
        } = inputs;
        let device = settings.device;
        let network = match &mut model.model {
            Model::Pbns(p) => p,
            Model::Dynamic(_) => bail!("train-swing starts from a PBNS model (garmentbake train), not a simulation-trained dynamic one"),
        };
        if network.swing.is_some() {
            bail!("this PBNS already swings; start from the quasi-static model it was trained on");
        }
        let skeleton = model.body.skeleton.clone();
        let rest_world = skeleton.rest_world();
        let bones = skin_joints(&network.skin(), &skeleton, settings.bones);
        let pivots = bones
            .iter()
            .map(|&j| {
                let c = rest_world[j].fixed_view::<3, 1>(0, 3);
                [c[0], c[1], c[2]]
            })
            .collect();
        let shape = SwingShape {
            lags: settings.lags.clone(),
            joints: network.feature_joints.clone(),
            pose_features: PER_JOINT * network.feature_joints.len(),
            width: settings.width,
            layers: settings.layers,
            shapes: settings.shapes,
            bones,
            pivots,
            vertices: network.shape.vertices,
            fps: settings.fps,
            integrator: settings.integrator,
        };
        let mut ranges = Vec::new();
        let mut locals = Vec::new();
        let mut motion = Vec::new();
        for clip in &clips {
            let poses: Vec<_> = (0..clip.frame_count())
                .map(|f| clip.local_pose(f))
                .collect();
            motion.extend(swing::motion_inputs(&skeleton, &poses, &shape));
            ranges.push(locals.len()..locals.len() + poses.len());
            locals.extend(poses);
        }
        let starts: Vec<usize> = ranges
            .iter()
            .flat_map(|r| r.start + 2..(r.end + 1).saturating_sub(settings.unroll).max(r.start + 2))
            .collect();
        if starts.is_empty() {
            bail!(
                "the clips are too short: a sequence needs {} frames",
                settings.unroll + 2
            );
        }
        let frames = locals.len() as i64;
        let m = shape.motion_inputs() as i64;
        let motion = Tensor::from_slice(&motion)
            .view([frames, m])
            .to_device(device);
        let mean = motion.mean_dim(0, false, Kind::Float);
        // A constant input (a lag no clip reaches, a joint that never turns) is left unscaled.
        let scale = motion.std_dim(0, false, false).clamp_min(1e-3);
        let batch = network.batch(&skeleton, &locals, device);
        let rest = super::super::models::predict_chunks(locals.len(), |s, n| {
            network.template.unsqueeze(0) + network.displacement(&batch.slice(s, n))
        });
        let mut swing = Swing::new(shape.clone(), mean, scale, device);
        let pinned = model.info.garment.pinned.clone();
        swing.basis = match settings.basis {
            SwingBasis::Turns => {
                let turns =
                    joint_turns(&model.garment, &network.skin(), &skeleton, settings.shapes);
                let rest_of = settings.shapes - turns.size()[0] as usize;
                Tensor::cat(
                    &[turns, vibration_shapes(&model.garment, &pinned, rest_of)],
                    0,
                )
            }
            SwingBasis::Isometric => isometric_shapes(&model.garment, &pinned, settings.shapes),
        }
        .to_device(device);
        swing.set_trainable();
        let adam = Adam::new(&swing.parameters());
        let fabric = model.info.fabric.clone();
        let cloth = Cloth::new(&model.garment, &fabric, &pinned, device)?;
        let subset = nearest::body_subset(&model.body, &model.garment.positions, settings.reach);
        let mut correspondences = Correspondences::new(
            &model.body,
            &subset,
            &locals,
            settings.candidates,
            network.shape.vertices,
            device,
        );
        let static_points = tensor_points(&super::super::models::predict_chunks(
            locals.len(),
            |s, n| {
                network.skin_points(
                    &rest.narrow(0, s as i64, n as i64),
                    &batch.skinning.narrow(0, s as i64, n as i64),
                )
            },
        ));
        let per_frame: Vec<Vec<[f32; 3]>> = static_points
            .chunks_exact(network.shape.vertices)
            .map(<[_]>::to_vec)
            .collect();
        correspondences.refresh(&per_frame);
        let outputs = network.swing.as_ref().map_or(0, |s| s.shape.outputs());
        let states = Tensor::zeros([frames, outputs as i64], (Kind::Float, device));
        let info = SwingInfo {
            shape,
            training: SwingTraining {
                seed: settings.seed,
                epochs: 0,
                batch: settings.batch,
                unroll: settings.unroll,
                learning_rate: settings.learning_rate,
                inertia: settings.inertia,
                motions: motion_names,
                frames: locals.len(),
            },
            history: Vec::new(),
        };
        network.swing = Some(Box::new(swing));
        match &mut model.info.model {
            KindInfo::Pbns(p) => p.swing = Some(info),
            KindInfo::Dynamic(_) => unreachable!("checked above"),
        }
        model.extra.clear();
        let mut trainer = Trainer {
            dt: 1.0 / settings.fps as f64,
            rng: Rng::new(settings.seed),
            settings,
            file: model,
            cloth,
            features: batch.features,
            skinning: batch.skinning,
            rest,
            motion,
            clips: ranges,
            starts,
            states,
            correspondences,
            adam,
        };
        if trainer.settings.integrator == SwingIntegrator::Modal {
            trainer.start_modes();
        }
        Ok(trainer)
    }

    /// The modal integrator's start: the swing's blend shapes turned into the garment's own
    /// vibration modes about the PBNS state. The potential's Hessian and the lumped mass are
    /// projected onto the shapes — `H_B` from central differences of the potential's gradient
    /// (1 mm RMS each way) at 8 training frames, `M_B = E·diag(m)·Eᵀ` — and the shapes replaced by
    /// the solutions of `H_B·v = λ·M_B·v` scaled to unit mass. The weights' kinetic energy is
    /// then `½|Ẏ|²` as the step assumes, the stiffness `diag(λ)`, and every mode starts at its
    /// physical frequency `√λ` (damped at 10 % of critical); the drive starts at zero, so the
    /// untrained swing is the PBNS garment, still.
    fn start_modes(&mut self) {
        let device = self.settings.device;
        let basis = self.swing().basis.detach().to_kind(Kind::Double);
        let s = basis.size()[0];
        let n = self.network().shape.vertices as i64;
        let frames = self.states.size()[0];
        let rms = basis.square().mean_dim(1, false, Kind::Double).sqrt();
        let step = (rms.reciprocal() * 1e-3).to_kind(Kind::Float);
        let eye = Tensor::eye(s, (Kind::Float, device));
        let signed = Tensor::cat(&[&eye, &(-&eye)], 0) * step.unsqueeze(0);
        let samples = 8i64.min(frames);
        let fabric = self.file.info.fabric.clone();
        // One Hessian per term of the potential (edge, bend, collision, gravity, pin), to say
        // which of them holds the slowest mode.
        let terms = losses::TERM_NAMES.len() as i64;
        let per_term = Tensor::zeros([terms, s, s], (Kind::Double, device));
        for i in 0..samples {
            let frame = (2 * i + 1) * frames / (2 * samples);
            let idx = Tensor::full([2 * s], frame, (Kind::Int64, device));
            let y = signed.detach().set_requires_grad(true);
            let (x, displacement) = self.garment(&idx, &y);
            let (body_points, body_normals) = self.correspondences.resolve(&idx, &x);
            let potential = losses::potential(
                &self.cloth,
                &fabric,
                &x,
                &displacement,
                &body_points,
                &body_normals,
            );
            for (t, term) in potential.weighted.iter().enumerate() {
                let grad = Tensor::run_backward(&[&(term * (2 * s) as f64)], &[&y], true, false)[0]
                    .to_kind(Kind::Double);
                let column = (grad.narrow(0, 0, s) - grad.narrow(0, s, s))
                    / (step.to_kind(Kind::Double).unsqueeze(1) * 2.0);
                let mut slot = per_term.get(t as i64);
                slot += column.tr() / samples as f64;
            }
        }
        let per_term = (&per_term + per_term.transpose(1, 2)) * 0.5;
        let hessian = per_term.sum_dim_intlist(0, false, Kind::Double);
        // The mass the inertia term weighs (`--inertia` scales it).
        let mass = Tensor::from_slice(&self.cloth.arrays.mass)
            .to_kind(Kind::Double)
            .to_device(device)
            * f64::from(self.settings.inertia);
        let weighted = basis.view([s, n, 3]) * mass.sqrt().view([1, n, 1]);
        let weighted = weighted.view([s, 3 * n]);
        let mass_b = weighted.matmul(&weighted.tr());
        let l_inv = mass_b.linalg_cholesky(false).inverse();
        let (lambda, v) = l_inv.matmul(&hessian).matmul(&l_inv.tr()).linalg_eigh("L");
        let coefficients = v.tr().matmul(&l_inv);
        let modes = coefficients.matmul(&basis).to_kind(Kind::Float);
        let slowest = coefficients.get(0);
        let share: Vec<f64> = Vec::try_from(
            per_term
                .matmul(&slowest.view([1, s, 1]))
                .squeeze_dim(-1)
                .matmul(&slowest),
        )
        .expect("double tensor");
        let whole: f64 = share.iter().sum();
        let lambda = lambda.to_kind(Kind::Float);
        let hz: Vec<f64> =
            Vec::try_from(lambda.clamp_min(0.0).sqrt() / (2.0 * std::f64::consts::PI))
                .expect("float tensor");
        let held: Vec<String> = losses::TERM_NAMES
            .iter()
            .zip(&share)
            .map(|(name, v)| format!("{name} {:.0} %", 100.0 * v / whole))
            .collect();
        crate::progress::note(&format!(
            "modal start: {s} modes, {:.2}–{:.2} Hz (median {:.2} Hz); the slowest held by {}",
            hz.first().copied().unwrap_or(0.0),
            hz.last().copied().unwrap_or(0.0),
            hz[hz.len() / 2],
            held.join(", ")
        ));
        let swing = self.swing_mut();
        swing.basis = modes.set_requires_grad(true);
        let m = swing.modes.as_mut().expect("a modal swing has modes");
        m.set_frequencies(&lambda);
        let (w, b) = swing.mlp.last_mut().expect("a network has a last layer");
        let _ = tch::no_grad(|| (w.zero_(), b.zero_()));
        self.adam = Adam::new(&self.swing().parameters());
    }

    fn swing_mut(&mut self) -> &mut Swing {
        match &mut self.file.model {
            Model::Pbns(p) => p.swing.as_mut().expect("the trainer installed a swing"),
            Model::Dynamic(_) => unreachable!("a swing trainer holds a PBNS"),
        }
    }

    fn network(&self) -> &Pbns {
        match &self.file.model {
            Model::Pbns(p) => p,
            Model::Dynamic(_) => unreachable!("a swing trainer holds a PBNS"),
        }
    }

    fn swing(&self) -> &Swing {
        self.network()
            .swing
            .as_ref()
            .expect("the trainer installed a swing")
    }

    fn info_mut(&mut self) -> &mut SwingInfo {
        match &mut self.file.info.model {
            KindInfo::Pbns(p) => p.swing.as_mut().expect("installed"),
            KindInfo::Dynamic(_) => unreachable!("a swing trainer holds a PBNS"),
        }
    }

    pub fn info(&self) -> &SwingInfo {
        match &self.file.info.model {
            KindInfo::Pbns(p) => p.swing.as_ref().expect("installed"),
            KindInfo::Dynamic(_) => unreachable!("a swing trainer holds a PBNS"),
        }
    }

    /// Training frames (at the swing's rate) and the frames a sequence can start at.
    pub fn frames(&self) -> (usize, usize) {
        (self.states.size()[0] as usize, self.starts.len())
    }

    /// Steps per epoch: every start frame's unrolled sequence once, on average.
    pub fn steps_per_epoch(&self) -> usize {
        self.starts
            .len()
            .div_ceil(self.settings.batch * self.settings.unroll)
            .max(1)
    }

    /// The garment for frames `idx` `[B]` with swing weights `y` `[B, S]`, and its rest-space
    /// displacement from the template (what pinning holds).
    fn garment(&self, idx: &Tensor, y: &Tensor) -> (Tensor, Tensor) {
        let network = self.network();
        let rest = self.rest.index_select(0, idx) + self.swing().displacement(y);
        let skinning = self.swing().bend(&self.skinning.index_select(0, idx), y);
        let x = network.skin_points(&rest, &skinning);
        (x, rest - network.template.unsqueeze(0))
    }

    /// Plays every clip in order with the current network: the states the next steps start from.
    fn replay(&mut self) {
        let parts: Vec<Tensor> = self
            .clips
            .iter()
            .map(|r| {
                let (s, n) = (r.start as i64, (r.end - r.start) as i64);
                self.swing()
                    .play(&self.motion.narrow(0, s, n), &self.features.narrow(0, s, n))
            })
            .collect();
        self.states = Tensor::cat(&parts, 0);
    }

    /// New candidate lists from the current garment of every frame.
    fn refresh(&mut self) {
        let frames = self.states.size()[0] as usize;
        let x = super::super::models::predict_chunks(frames, |s, n| {
            let idx = Tensor::arange_start(
                s as i64,
                (s + n) as i64,
                (Kind::Int64, self.settings.device),
            );
            self.garment(&idx, &self.states.index_select(0, &idx)).0
        });
        let v = self.network().shape.vertices;
        let per_frame: Vec<Vec<[f32; 3]>> = tensor_points(&x)
            .chunks_exact(v)
            .map(<[_]>::to_vec)
            .collect();
        self.correspondences.refresh(&per_frame);
    }

    /// One step on the sequences starting at `starts`: returns the weighted terms (edge, bend,
    /// collision, gravity, pin, inertia) and the collided fraction, means over the unroll.
    fn step(&mut self, starts: &[usize], lr: f64) -> Result<[f64; 7], Blowup> {
        let device = self.settings.device;
        let fabric = self.file.info.fabric.clone();
        let at = |offset: i64| {
            let v: Vec<i64> = starts.iter().map(|&s| s as i64 + offset).collect();
            Tensor::from_slice(&v).to_device(device)
        };
        let (mut last, mut before) = (
            self.states.index_select(0, &at(-1)),
            self.states.index_select(0, &at(-2)),
        );
        let (mut x_last, mut x_before) = tch::no_grad(|| {
            (
                self.garment(&at(-1), &last).0,
                self.garment(&at(-2), &before).0,
            )
        });
        let mut total = Tensor::zeros([], (Kind::Float, device));
        let mut values = [0.0f64; 7];
        let unroll = self.settings.unroll;
        let mut outputs = Vec::with_capacity(unroll);
        for k in 0..unroll as i64 {
            let idx = at(k);
            let swing = self.swing();
            let motion = swing.normalise(&self.motion.index_select(0, &idx));
            let y = swing.step(
                &motion,
                &self.features.index_select(0, &idx),
                &last,
                &before,
            );
            let (x, displacement) = self.garment(&idx, &y);
            let (body_points, body_normals) = self.correspondences.resolve(&idx, &x);
            let potential = |x: &Tensor, displacement: &Tensor| {
                losses::potential(
                    &self.cloth,
                    &fabric,
                    x,
                    displacement,
                    &body_points,
                    &body_normals,
                )
            };
            let terms = potential(&x, &displacement);
            // The PBNS garment is the rest state: its own residual force (what the quasi-static
            // network left unbalanced) is taken out, so the swing learns the motion's response
            // and not a correction of the pose's garment.
            let still = self.garment(&idx, &y.zeros_like().detach());
            let x_still = still.0.detach().set_requires_grad(true);
            let residual = &Tensor::run_backward(
                &[&potential(&x_still, &still.1.detach()).total()],
                &[&x_still],
                false,
                false,
            )[0];
            let balance = (residual * (&x - x_still.detach())).sum(Kind::Float);
            let inertia =
                self.cloth.inertia(&x, &x_last, &x_before, self.dt) * self.settings.inertia as f64;
            total = total + terms.total() - balance + &inertia;
            let mut scalars: Vec<Tensor> = terms.weighted.iter().map(Tensor::detach).collect();
            scalars.push(inertia.detach());
            scalars.push(terms.metrics[2].shallow_clone());
            let v: Vec<f64> = flat(&Tensor::stack(&scalars, 0), Kind::Double);
            for (a, b) in values.iter_mut().zip(v) {
                *a += b / unroll as f64;
            }
            before = last;
            last = y.detach();
            x_before = x_last;
            x_last = x.detach();
            outputs.push((idx, last.shallow_clone()));
        }
        let names = ["edge", "bend", "collision", "gravity", "pin", "inertia"];
        let named: Vec<(&'static str, f64)> = names.into_iter().zip(values).collect();
        let step = self.adam.step as usize + 1;
        Blowup::check(&named, self.info().history.len() + 1, step)?;
        let params: Vec<Tensor> = self
            .swing()
            .parameters()
            .into_iter()
            .map(|(_, t)| t.shallow_clone())
            .collect();
        let grads = Tensor::run_backward(&[&(total / unroll as f64)], &params, false, false);
        let rates = vec![lr; params.len()];
        self.adam.update_with(&params, &grads, &rates);
        // The model's own output becomes the state later sequences start from.
        tch::no_grad(|| {
            for (idx, y) in outputs {
                let _ = self.states.index_copy_(0, &idx, &y);
            }
        });
        Ok(values)
    }

    /// RMS of how far the swing moves the garment over the training frames (mm): blend shapes
    /// and bones together, in the world.
    fn swing_rms_mm(&self) -> f64 {
        tch::no_grad(|| {
            let frames = self.states.size()[0] as usize;
            let mut sum = 0.0;
            for s in (0..frames).step_by(PREDICT_CHUNK) {
                let n = PREDICT_CHUNK.min(frames - s);
                let idx = Tensor::arange_start(
                    s as i64,
                    (s + n) as i64,
                    (Kind::Int64, self.settings.device),
                );
                let y = self.states.index_select(0, &idx);
                let d = self.garment(&idx, &y).0 - self.garment(&idx, &y.zeros_like()).0;
                sum += d.square().sum(Kind::Double).double_value(&[]);
            }
            let count = (frames * self.network().shape.vertices).max(1) as f64;
            1000.0 * (sum / count).sqrt()
        })
    }

    pub fn epoch(&self) -> usize {
        self.info().history.len()
    }

    fn learning_rate(&self) -> f64 {
        super::cosine_rate(
            self.settings.learning_rate,
            self.epoch(),
            self.settings.epochs,
        )
    }

    pub fn model_file(&self) -> &ModelFile {
        &self.file
    }
}

/// At most `count` joints carrying more than 2 % of the garment's skin weight, most first.
fn skin_joints(
    skin: &crate::rig::Skin,
    skeleton: &crate::rig::Skeleton,
    count: usize,
) -> Vec<usize> {
    let mut share = vec![0.0f64; skeleton.joint_count()];
    for (j, w) in skin.joint_indices.iter().zip(&skin.joint_weights) {
        share[*j as usize] += f64::from(*w);
    }
    let n = skin.vertex_count() as f64;
    let mut joints: Vec<usize> = (0..share.len()).filter(|&j| share[j] > 0.02 * n).collect();
    joints.sort_by(|a, b| share[*b].total_cmp(&share[*a]));
    joints.truncate(count);
    joints
}

/// Blend shapes that turn the garment's part skinned to a joint about that joint (its skin weight
/// times `a × (x − joint)`, for the three axes `a`), for the joints carrying most of the garment's
/// skin, at most two thirds of `shapes`: a thigh's share of the skirt swinging about the hip is
/// isometric to first order, what a lagging hem does; scaled to 1 cm at most.
fn joint_turns(
    mesh: &crate::geometry::TriMesh,
    skin: &crate::rig::Skin,
    skeleton: &crate::rig::Skeleton,
    shapes: usize,
) -> Tensor {
    let n = mesh.vertex_count();
    let joints = skin_joints(skin, skeleton, 2 * shapes / 9);
    let rest = skeleton.rest_world();
    let mut out = Vec::new();
    for &j in &joints {
        let c = rest[j].fixed_view::<3, 1>(0, 3).into_owned();
        let weight: Vec<f32> = skin
            .joint_indices
            .chunks_exact(skin.influences)
            .zip(skin.joint_weights.chunks_exact(skin.influences))
            .map(|(js, ws)| {
                js.iter()
                    .zip(ws)
                    .filter(|(&i, _)| i as usize == j)
                    .map(|(_, w)| w)
                    .sum()
            })
            .collect();
        for axis in 0..3 {
            let a = nalgebra::Vector3::from_fn(|r, _| if r == axis { 1.0f32 } else { 0.0 });
            let field: Vec<nalgebra::Vector3<f32>> = (0..n)
                .map(|v| {
                    let x = nalgebra::Vector3::from(mesh.positions[v]);
                    a.cross(&(x - c)) * weight[v]
                })
                .collect();
            let peak = field
                .iter()
                .map(|u| u.norm())
                .fold(0.0f32, f32::max)
                .max(1e-9);
            out.extend(
                field
                    .iter()
                    .flat_map(|u| (u * (0.01 / peak)).iter().copied().collect::<Vec<_>>()),
            );
        }
    }
    let k = out.len() / (3 * n);
    Tensor::from_slice(&out).view([k as i64, 3 * n as i64])
}

/// The swing's first blend shapes: the garment's slowest vibration shapes — the lowest
/// eigenvectors of its edge graph's Laplacian with the pinned vertices held (Dirichlet), each
/// along x, y and z, scaled to 1 cm at most. Near the pins they barely move and they grow towards
/// the free edges: a skirt swinging from its waist. Inertia is tiny beside stretching, so a basis
/// that stretches the cloth (random shapes, or the PBNS's own correctives) never moves: Y stays at
/// zero and E then gets no gradient either.
fn vibration_shapes(mesh: &crate::geometry::TriMesh, pinned: &[u32], shapes: usize) -> Tensor {
    let n = mesh.vertex_count();
    let modes = LaplacianModes::new(mesh, pinned);
    let m = modes.free.len();
    let per_axis = shapes.div_ceil(3);
    let vectors: Vec<f64> = Vec::try_from(
        modes
            .vectors
            .narrow(1, 0, per_axis.min(m) as i64)
            .transpose(0, 1)
            .contiguous()
            .view([-1]),
    )
    .expect("double tensor");
    let mut out = vec![0.0f32; shapes * 3 * n];
    for k in 0..shapes {
        let (mode, axis) = (k / 3, k % 3);
        let Some(phi) = vectors.get(mode * m..(mode + 1) * m) else {
            continue;
        };
        let peak = phi.iter().fold(0.0f64, |a, b| a.max(b.abs())).max(1e-12);
        for (i, &v) in modes.free.iter().enumerate() {
            out[k * 3 * n + 3 * v + axis] = (0.01 * phi[i] / peak) as f32;
        }
    }
    Tensor::from_slice(&out).view([shapes as i64, 3 * n as i64])
}

/// The eigenvectors of the garment's edge-graph Laplacian with the pinned vertices held
/// (Dirichlet), over the free vertices, smoothest first.
struct LaplacianModes {
    free: Vec<usize>,
    /// `[free, free]` (f64), one eigenvector per column.
    vectors: Tensor,
    /// Ascending eigenvalues `[free]`.
    values: Tensor,
}

impl LaplacianModes {
    fn new(mesh: &crate::geometry::TriMesh, pinned: &[u32]) -> LaplacianModes {
        let n = mesh.vertex_count();
        let held: std::collections::HashSet<u32> = pinned.iter().copied().collect();
        let free: Vec<usize> = (0..n).filter(|v| !held.contains(&(*v as u32))).collect();
        let mut slot = vec![usize::MAX; n];
        for (i, &v) in free.iter().enumerate() {
            slot[v] = i;
        }
        let m = free.len();
        let mut lap = vec![0.0f64; m * m];
        for &[a, b] in &crate::geometry::Topology::new(mesh).edges {
            let (a, b) = (a as usize, b as usize);
            for (p, q) in [(a, b), (b, a)] {
                if slot[p] != usize::MAX {
                    lap[slot[p] * m + slot[p]] += 1.0;
                    if slot[q] != usize::MAX {
                        lap[slot[p] * m + slot[q]] -= 1.0;
                    }
                }
            }
        }
        let lap = Tensor::from_slice(&lap).view([m as i64, m as i64]);
        let (values, vectors) = lap.linalg_eigh("L");
        LaplacianModes {
            free,
            vectors,
            values,
        }
    }
}

/// Smooth fields the swing draws from: this many of the smoothest Laplacian modes per axis.
const SMOOTH_MODES: usize = 200;

/// The swing's blend shapes as the garment's least-stretching smooth motions: within the span
/// of the `SMOOTH_MODES` smoothest Laplacian modes along x, y and z (pins held), the lowest
/// eigenvectors of `Σ_edges ((d·(u_a − u_b))/L)²` (first-order edge strain; `d` the rest edge's
/// direction) plus a little of the Laplacian energy, so that among near-isometric motions the
/// smoother come first. A skirt hanging from its waist swings and flares this way without
/// stretching to first order, which the per-axis Laplacian modes cannot (a sideways field that
/// varies down the skirt stretches every vertical edge). Each scaled to 1 cm at most.
fn isometric_shapes(mesh: &crate::geometry::TriMesh, pinned: &[u32], shapes: usize) -> Tensor {
    let n = mesh.vertex_count();
    let modes = LaplacianModes::new(mesh, pinned);
    let free = &modes.free;
    let r = SMOOTH_MODES.min(free.len());
    let phi: Vec<f64> = Vec::try_from(modes.vectors.narrow(1, 0, r as i64).contiguous().view([-1]))
        .expect("double tensor");
    let lambda: Vec<f64> =
        Vec::try_from(modes.values.narrow(0, 0, r as i64)).expect("double tensor");
    // Row v of phi for every vertex (zero where pinned).
    let mut row = vec![usize::MAX; n];
    for (i, &v) in free.iter().enumerate() {
        row[v] = i;
    }
    let at = |v: usize, j: usize| {
        if row[v] == usize::MAX {
            0.0
        } else {
            phi[row[v] * r + j]
        }
    };
    let edges = crate::geometry::Topology::new(mesh).edges;
    let p = &mesh.positions;
    // Strain rows: edge e, coefficient (j, axis) -> d_axis (phi_j(a) - phi_j(b)) / L.
    let mut strain = vec![0.0f64; edges.len() * 3 * r];
    let mut mean_length = 0.0f64;
    for (e, &[a, b]) in edges.iter().enumerate() {
        let (a, b) = (a as usize, b as usize);
        let d: [f64; 3] = std::array::from_fn(|k| f64::from(p[a][k] - p[b][k]));
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-9);
        mean_length += len / edges.len() as f64;
        for j in 0..r {
            let g = (at(a, j) - at(b, j)) / len;
            for k in 0..3 {
                strain[e * 3 * r + 3 * j + k] = d[k] / len * g;
            }
        }
    }
    let s = Tensor::from_slice(&strain).view([edges.len() as i64, 3 * r as i64]);
    let smooth: Vec<f64> = lambda
        .iter()
        .flat_map(|l| [*l; 3])
        .map(|l| SMOOTHNESS * l / (mean_length * mean_length))
        .collect();
    let stiffness = s.transpose(0, 1).matmul(&s) + Tensor::from_slice(&smooth).diag(0);
    let (_, coefficients) = stiffness.linalg_eigh("L");
    let coefficients: Vec<f64> = Vec::try_from(coefficients.contiguous().view([-1])).expect("f64");
    let mut out = vec![0.0f32; shapes * 3 * n];
    for k in 0..shapes.min(3 * r) {
        let mut field = vec![0.0f64; 3 * n];
        for (i, &v) in free.iter().enumerate() {
            for j in 0..r {
                for axis in 0..3 {
                    field[3 * v + axis] +=
                        phi[i * r + j] * coefficients[(3 * j + axis) * 3 * r + k];
                }
            }
        }
        let peak = field
            .chunks_exact(3)
            .map(|u| (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt())
            .fold(0.0f64, f64::max)
            .max(1e-12);
        for (o, f) in out[k * 3 * n..(k + 1) * 3 * n].iter_mut().zip(&field) {
            *o = (0.01 * f / peak) as f32;
        }
    }
    Tensor::from_slice(&out).view([shapes as i64, 3 * n as i64])
}

/// Weight of the Laplacian energy beside the edge strain in [`isometric_shapes`] (per squared
/// mean edge length): small, so it only orders motions that stretch about equally.
const SMOOTHNESS: f64 = 1e-2;

impl Training for Trainer {
    type Record = EpochLine;

    fn epochs_done(&self) -> usize {
        self.epoch()
    }

    fn run_epoch(&mut self) -> Result<EpochLine, Blowup> {
        let start = Instant::now();
        let epoch = self.epoch();
        if epoch > 0 && epoch.is_multiple_of(self.settings.refresh_every.max(1)) {
            self.refresh();
        }
        self.replay();
        let lr = self.learning_rate();
        let mut order = self.starts.clone();
        shuffle(&mut order, self.rng.next_u64());
        let steps = self.steps_per_epoch();
        let mut sums = [0.0f64; 7];
        for k in 0..steps {
            let batch: Vec<usize> = (0..self.settings.batch)
                .map(|i| order[(k * self.settings.batch + i) % order.len()])
                .collect();
            let v = self.step(&batch, lr)?;
            for (a, b) in sums.iter_mut().zip(v) {
                *a += b / steps as f64;
            }
        }
        self.replay();
        let terms = LossTerms {
            edge: sums[0],
            bend: sums[1],
            collision: sums[2],
            gravity: sums[3],
            pin: sums[4],
        };
        let record = SwingEpoch {
            epoch: epoch + 1,
            loss: terms.total() + sums[5],
            terms,
            inertia: sums[5],
            collided: sums[6],
            swing_rms_mm: self.swing_rms_mm(),
            seconds: start.elapsed().as_secs_f64(),
        };
        let info = self.info_mut();
        info.history.push(record.clone());
        info.training.epochs = info.history.len();
        Ok(EpochLine {
            record,
            learning_rate: lr,
        })
    }

    fn save(&mut self, path: &Path, checkpoint: bool) -> Result<()> {
        self.file.extra = if checkpoint {
            self.adam.state(&self.swing().parameters())
        } else {
            Vec::new()
        };
        let r = crate::models::file::save(path, &self.file);
        self.file.extra.clear();
        r
    }

    /// Continues from the checkpoint's network, optimiser state and history (the candidate
    /// lists and states are rebuilt from that network, so the run differs slightly from one
    /// that never stopped).
    fn resume(&mut self, checkpoint: &Path) -> Result<()> {
        let ckpt = crate::models::file::load(checkpoint, self.settings.device)
            .with_context(|| "--resume needs the checkpoint of an earlier run")?;
        let theirs = ckpt.info.pbns()?.swing.clone();
        let same = theirs.as_ref().is_some_and(|t| {
            t.shape == self.info().shape
                && t.training.seed == self.settings.seed
                && t.training.frames == self.info().training.frames
        });
        if !same || ckpt.info.garment != self.file.info.garment {
            bail!(
                "{}: checkpoint was made with other inputs or settings; start without --resume",
                checkpoint.display()
            );
        }
        let Model::Pbns(mut network) = ckpt.model else {
            bail!("{}: not a PBNS checkpoint", checkpoint.display());
        };
        let mut swing = network.swing.take().expect("checked above");
        swing.set_trainable();
        self.adam.restore(&swing.parameters(), &ckpt.extra)?;
        if let Model::Pbns(p) = &mut self.file.model {
            p.swing = Some(swing);
        }
        *self.info_mut() = theirs.expect("checked above");
        self.refresh();
        Ok(())
    }

    fn describe(line: &EpochLine) -> String {
        let r = &line.record;
        format!(
            "loss {:.4}  inertia {:.4}  collided {:.2} %  swing {:.1} mm",
            r.loss,
            r.inertia,
            100.0 * r.collided,
            r.swing_rms_mm
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::grid;

    /// Each shape's largest first-order edge strain `|d·(u_a − u_b)|/L` (rows of `[S, 3N]`).
    fn first_order_strain(mesh: &crate::geometry::TriMesh, shapes: &Tensor) -> Vec<f64> {
        let u: Vec<f32> = Vec::try_from(shapes.contiguous().view([-1])).unwrap();
        let n = mesh.vertex_count();
        let mut out = Vec::new();
        for shape in u.chunks_exact(3 * n) {
            let mut worst = 0.0f64;
            for &[a, b] in &crate::geometry::Topology::new(mesh).edges {
                let (a, b) = (a as usize, b as usize);
                let d: [f32; 3] =
                    std::array::from_fn(|k| mesh.positions[a][k] - mesh.positions[b][k]);
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let stretch: f32 = (0..3)
                    .map(|k| d[k] * (shape[3 * a + k] - shape[3 * b + k]))
                    .sum();
                worst = worst.max(f64::from((stretch / (len * len)).abs()));
            }
            out.push(worst);
        }
        out
    }

    /// A flat cloth hanging from its top row can move out of its plane without stretching to
    /// first order: the isometric shapes are mostly those motions and stretch far less than the
    /// per-axis Laplacian fields (which include in-plane ones).
    #[test]
    fn isometric_shapes_do_not_stretch_a_hanging_cloth() {
        let mesh = grid(8, 8, 0.05);
        let top: Vec<u32> = (0..9).map(|x| (8 * 9 + x) as u32).collect();
        let iso = isometric_shapes(&mesh, &top, 6);
        let laplacian = vibration_shapes(&mesh, &top, 6);
        assert_eq!(iso.size(), [6, 3 * 81]);
        let peak = iso
            .view([6, 81, 3])
            .square()
            .sum_dim_intlist(-1, false, Kind::Float)
            .sqrt()
            .amax(1, false);
        let peak: Vec<f32> = Vec::try_from(peak).unwrap();
        assert!(peak.iter().all(|p| (p - 0.01).abs() < 1e-6), "{peak:?}");
        let (a, b) = (
            first_order_strain(&mesh, &iso),
            first_order_strain(&mesh, &laplacian),
        );
        // Measured: five of six exact out-of-plane flexes (~1e-16) and one shear (0.015, cheaper
        // in stretch plus smoothness than the sixth flex); the Laplacian fields 0 to 0.059.
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let flexes = a.iter().filter(|&&s| s < 1e-9).count();
        assert!(
            flexes >= 3 && mean(&a) < mean(&b) / 3.0,
            "isometric {a:?}, laplacian {b:?}"
        );
    }
}
