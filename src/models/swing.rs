//! A PBNS that swings: dynamic blend-shape weights learnt from physics alone.
//!
//! The quasi-static PBNS gives `T + X(θ_t)·D`; the swing adds `Y_t·E`, a second blend-shape set
//! `E` (`[S, N·3]`) whose weights come from a small MLP over the motion history (the root's linear
//! and angular velocity in the root's frame, the garment joints' angular velocities, a few frames
//! back, and the gravity direction), the pose features and the swing's own last two weights
//! `Y_{t−1}, Y_{t−2}`. Over a clip played in order the weights are a recurrence from rest
//! (`Y = 0`), so a baked clip is the same skin, the blend shapes `[D; E]` and one weight track:
//! no runtime beyond blend shapes. A swing may also turn "swing bones" (see `SwingShape::bones`):
//! the garment's copy of a joint rotated about the joint, as engines swing skirts. The frame rate is part of the model (the recurrence is a time
//! step); clips are played at that rate.

use crate::rig::{JointTransform, Skeleton};
use anyhow::{bail, Result};
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use tch::{Device, Kind, Tensor};

/// How a swing's weights follow from one frame to the next.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum SwingIntegrator {
    /// The network maps the motion history, the pose and the last two weights to the new ones.
    #[default]
    Network,
    /// A damped oscillator over the blend shapes, stepped implicitly:
    /// `(I + Δt·C + Δt²·K)·Y_t = (2I + Δt·C)·Y_{t−1} − Y_{t−2} + F_t`, with a learnt stiffness
    /// `K` and damping `C` (symmetric, positive definite) and the network giving only the drive
    /// `F_t` from the motion and the pose. Momentum is carried from the first step (a network
    /// must learn to carry it, and from rest it never started), and the recurrence is stable
    /// whatever the drive, so a clip of any length plays without blowing up.
    Modal,
}

impl SwingIntegrator {
    fn is_network(&self) -> bool {
        *self == SwingIntegrator::Network
    }
}

/// Sizes and inputs of the swing network.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SwingShape {
    /// Frames back at which the motion history is sampled (0: the current frame).
    pub lags: Vec<usize>,
    /// Joints whose local angular velocities are inputs (the PBNS feature joints).
    pub joints: Vec<usize>,
    /// Pose features of the PBNS network (its MLP inputs), also inputs here.
    pub pose_features: usize,
    /// Hidden width and count of hidden ReLU layers.
    pub width: usize,
    pub layers: usize,
    /// Swing blend shapes `S`.
    pub shapes: usize,
    /// Swing bones: joints whose garment copy turns by a learnt rotation about the joint's rest
    /// position (a turn moves cloth without stretching it, which a blend shape cannot). Empty in
    /// files without them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bones: Vec<usize>,
    /// Each bone's pivot: its joint's rest position (metres, rest space).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pivots: Vec<[f32; 3]>,
    pub vertices: usize,
    /// The rate the recurrence steps at (frames per second).
    pub fps: f32,
    /// How the weights are stepped (files without it: `Network`).
    #[serde(default, skip_serializing_if = "SwingIntegrator::is_network")]
    pub integrator: SwingIntegrator,
}

impl SwingShape {
    /// Motion-history inputs per frame: per lag the root's velocity and angular velocity and
    /// each joint's angular velocity (3 each), then the gravity direction.
    pub fn motion_inputs(&self) -> usize {
        self.lags.len() * (6 + 3 * self.joints.len()) + 3
    }

    /// Network outputs per frame: `S` blend-shape weights, then a rotation vector per bone.
    pub fn outputs(&self) -> usize {
        self.shapes + 3 * self.bones.len()
    }

    /// All network inputs: motion history, pose features, and (stepped by the network) the
    /// last two outputs.
    pub fn inputs(&self) -> usize {
        let state = match self.integrator {
            SwingIntegrator::Network => 2 * self.outputs(),
            SwingIntegrator::Modal => 0,
        };
        self.motion_inputs() + self.pose_features + state
    }
}

/// The modal integrator's matrices: `K = A·Aᵀ + k₀·I` (1/s²) and `C = B·Bᵀ` (1/s), so both stay
/// symmetric and positive whatever training does to `A` and `B`.
pub struct Modes {
    pub stiffness: Tensor,
    pub damping: Tensor,
}

/// The stiffness floor `k₀`: a 0.2 Hz oscillation, so no blend shape drifts without a pull back.
const STIFFNESS_FLOOR: f64 =
    (2.0 * std::f64::consts::PI * 0.2) * (2.0 * std::f64::consts::PI * 0.2);

impl Modes {
    /// Every shape a 1 Hz oscillator damped at 10 % of critical (a skirt swings about once a
    /// second); training moves both.
    pub fn new(shapes: usize, device: Device) -> Modes {
        let omega = 2.0 * std::f64::consts::PI;
        let eye = Tensor::eye(shapes as i64, (Kind::Float, device));
        Modes {
            stiffness: &eye * (omega * omega - STIFFNESS_FLOOR).sqrt(),
            damping: eye * (2.0 * 0.1 * omega).sqrt(),
        }
    }

    /// Each shape its own oscillator: stiffness `λ_k` (1/s², at least the floor) damped at 10 %
    /// of critical, for weights whose kinetic energy is `½|Ẏ|²`.
    pub fn set_frequencies(&mut self, lambda: &Tensor) {
        let k = lambda.clamp_min(STIFFNESS_FLOOR);
        let stiffness = (&k - STIFFNESS_FLOOR).sqrt().diag(0);
        let damping = (k.sqrt() * (2.0 * 0.1)).sqrt().diag(0);
        self.stiffness = stiffness.set_requires_grad(self.stiffness.requires_grad());
        self.damping = damping.set_requires_grad(self.damping.requires_grad());
    }

    /// The step's matrices for time step `dt`: `(I + Δt·C + Δt²·K)⁻¹` and `2I + Δt·C`.
    fn step_matrices(&self, dt: f64) -> (Tensor, Tensor) {
        let s = self.stiffness.size()[0];
        let eye = Tensor::eye(s, (Kind::Float, self.stiffness.device()));
        let k = self.stiffness.matmul(&self.stiffness.tr()) + &eye * STIFFNESS_FLOOR;
        let c = self.damping.matmul(&self.damping.tr());
        let lhs = &eye + &c * dt + k * (dt * dt);
        (lhs.inverse(), eye * 2.0 + c * dt)
    }
}

/// One modal step for rows of frames: `Y_t = (carry·Y_{t−1} − Y_{t−2} + F)·lhs⁻ᵀ` with
/// `(lhs⁻¹, carry)` from [`Modes::step_matrices`] (both symmetric).
fn modal_step(
    (inverse, carry): &(Tensor, Tensor),
    last: &Tensor,
    before: &Tensor,
    drive: &Tensor,
) -> Tensor {
    (last.matmul(carry) - before + drive).matmul(inverse)
}

pub struct Swing {
    pub shape: SwingShape,
    /// `(weight [in, out], bias [out])`: hidden ReLU layers, then a linear layer to `S`.
    pub mlp: Vec<(Tensor, Tensor)>,
    /// Swing blend shapes `E` `[S, N·3]` (rest space, as PBNS's `D`).
    pub basis: Tensor,
    /// Normalisation of the motion inputs (from the training frames) `[M]`.
    pub input_mean: Tensor,
    pub input_scale: Tensor,
    /// Stiffness and damping of the modal integrator (`None` for the network integrator).
    pub modes: Option<Modes>,
}

/// Which gravity the rig lives in (glTF bodies are Y-up).
const DOWN: [f32; 3] = [0.0, -1.0, 0.0];

impl Swing {
    /// A fresh network: hidden layers initialised like PyTorch's `Linear`, the last layer and
    /// the basis small, so the untrained swing is (nearly) the quasi-static PBNS.
    pub fn new(
        shape: SwingShape,
        input_mean: Tensor,
        input_scale: Tensor,
        device: Device,
    ) -> Swing {
        let opts = (Kind::Float, device);
        let mut mlp = Vec::new();
        let mut fan_in = shape.inputs();
        for layer in 0..=shape.layers {
            let last = layer == shape.layers;
            let out = if last { shape.outputs() } else { shape.width };
            let bound = 1.0 / (fan_in as f64).sqrt() * if last { 0.1 } else { 1.0 };
            let w = Tensor::zeros([fan_in as i64, out as i64], opts).uniform_(-bound, bound);
            let b = Tensor::zeros([out as i64], opts);
            mlp.push((w, b));
            fan_in = out;
        }
        // One centimetre per unit weight spread over the garment: the weights start near 1.
        let scale = 0.01 / (shape.vertices as f64).sqrt();
        let basis = Tensor::randn([shape.shapes as i64, 3 * shape.vertices as i64], opts) * scale;
        let modes =
            (shape.integrator == SwingIntegrator::Modal).then(|| Modes::new(shape.shapes, device));
        Swing {
            shape,
            mlp,
            basis,
            input_mean,
            input_scale,
            modes,
        }
    }

    /// The trainable tensors with their file names.
    pub fn parameters(&self) -> Vec<(String, &Tensor)> {
        let mut out = Vec::new();
        for (i, (w, b)) in self.mlp.iter().enumerate() {
            out.push((format!("swing.mlp.{i}.weight"), w));
            out.push((format!("swing.mlp.{i}.bias"), b));
        }
        out.push(("swing.basis".to_string(), &self.basis));
        if let Some(m) = &self.modes {
            out.push(("swing.stiffness".to_string(), &m.stiffness));
            out.push(("swing.damping".to_string(), &m.damping));
        }
        out
    }

    /// Every tensor the file stores (parameters and the input normalisation).
    pub fn tensors(&self) -> Vec<(String, &Tensor)> {
        let mut out = self.parameters();
        out.push(("swing.input_mean".to_string(), &self.input_mean));
        out.push(("swing.input_scale".to_string(), &self.input_scale));
        out
    }

    pub fn set_trainable(&mut self) {
        for (w, b) in &mut self.mlp {
            *w = w.set_requires_grad(true);
            *b = b.set_requires_grad(true);
        }
        self.basis = self.basis.set_requires_grad(true);
        if let Some(m) = &mut self.modes {
            m.stiffness = m.stiffness.set_requires_grad(true);
            m.damping = m.damping.set_requires_grad(true);
        }
    }

    /// Normalised motion inputs `[F, M]` from raw ones.
    pub fn normalise(&self, motion: &Tensor) -> Tensor {
        (motion - &self.input_mean) / &self.input_scale
    }

    /// One step for a batch: `motion` normalised `[B, M]`, `pose` `[B, P]`, the last two swing
    /// weights `[B, S]` each → the new weights `[B, S]`.
    pub fn step(&self, motion: &Tensor, pose: &Tensor, last: &Tensor, before: &Tensor) -> Tensor {
        match &self.modes {
            None => self.mlp_forward(Tensor::cat(&[motion, pose, last, before], 1)),
            Some(modes) => {
                let drive = self.mlp_forward(Tensor::cat(&[motion, pose], 1));
                modal_step(&modes.step_matrices(self.dt()), last, before, &drive)
            }
        }
    }

    fn dt(&self) -> f64 {
        1.0 / f64::from(self.shape.fps)
    }

    fn mlp_forward(&self, mut x: Tensor) -> Tensor {
        let n = self.mlp.len();
        for (i, (w, b)) in self.mlp.iter().enumerate() {
            x = b.addmm(&x, w);
            if i + 1 < n {
                x = x.relu();
            }
        }
        x
    }

    /// The swing weights of one clip played in order from rest, `[F, S]`, without gradients:
    /// `motion` raw `[F, M]`, `pose` `[F, P]`.
    pub fn play(&self, motion: &Tensor, pose: &Tensor) -> Tensor {
        tch::no_grad(|| {
            let frames = motion.size()[0];
            let motion = self.normalise(motion);
            let zero = Tensor::zeros(
                [1, self.shape.outputs() as i64],
                (Kind::Float, motion.device()),
            );
            // The modal drive reads no state: one network pass for the clip, and the step's
            // matrices once, leave only the recurrence per frame.
            let modal = self.modes.as_ref().map(|modes| {
                let drives = self.mlp_forward(Tensor::cat(&[&motion, pose], 1));
                (modes.step_matrices(self.dt()), drives)
            });
            let (mut last, mut before) = (zero.shallow_clone(), zero.shallow_clone());
            let mut out = Vec::with_capacity(frames as usize);
            for f in 0..frames {
                let y = match &modal {
                    Some((matrices, drives)) => {
                        modal_step(matrices, &last, &before, &drives.narrow(0, f, 1))
                    }
                    None => self.step(
                        &motion.narrow(0, f, 1),
                        &pose.narrow(0, f, 1),
                        &last,
                        &before,
                    ),
                };
                before = last;
                last = y.shallow_clone();
                out.push(y);
            }
            if out.is_empty() {
                return zero.narrow(0, 0, 0);
            }
            Tensor::cat(&out, 0)
        })
    }

    /// The swing's displacement `Y·E` in rest space `[B, N, 3]` (from the first `S` outputs).
    pub fn displacement(&self, outputs: &Tensor) -> Tensor {
        self.blend_weights(outputs)
            .matmul(&self.basis)
            .view([-1, self.shape.vertices as i64, 3])
    }

    /// The blend-shape weights among the outputs `[B, S]`.
    pub fn blend_weights(&self, outputs: &Tensor) -> Tensor {
        outputs.narrow(1, 0, self.shape.shapes as i64)
    }

    /// Skinning matrices `[B, J, 12]` with each bone's joint turned by its rotation (the outputs
    /// after the first `S`) about its rest position: `M'·v = M·(R·(v − p) + p)`.
    pub fn bend(&self, skinning: &Tensor, outputs: &Tensor) -> Tensor {
        let bones = self.shape.bones.len() as i64;
        if bones == 0 {
            return skinning.shallow_clone();
        }
        let b = skinning.size()[0];
        let device = skinning.device();
        let r = outputs
            .narrow(1, self.shape.shapes as i64, 3 * bones)
            .view([b, bones, 3]);
        let rotation = rodrigues(&r);
        let joints: Vec<i64> = self.shape.bones.iter().map(|&j| j as i64).collect();
        let joints = Tensor::from_slice(&joints).to_device(device);
        let pivots: Vec<f32> = self.shape.pivots.iter().flatten().copied().collect();
        let pivot = Tensor::from_slice(&pivots)
            .view([1, bones, 3, 1])
            .to_device(device);
        let m = skinning.index_select(1, &joints).view([b, bones, 3, 4]);
        let linear = m.narrow(3, 0, 3);
        let translation = m.narrow(3, 3, 1);
        let turned = linear.matmul(&rotation);
        let shift = translation + linear.matmul(&(&pivot - rotation.matmul(&pivot)));
        let bent = Tensor::cat(&[turned, shift], 3).view([b, bones, 12]);
        skinning.index_copy(1, &joints, &bent)
    }

    /// Checks a loaded network against its shape.
    pub fn check(&self) -> Result<()> {
        let s = &self.shape;
        if self.mlp.len() != s.layers + 1 {
            bail!(
                "swing: {} layers stored, {} described",
                self.mlp.len(),
                s.layers + 1
            );
        }
        if self.mlp[0].0.size() != [s.inputs() as i64, self.mlp[0].0.size()[1]] {
            bail!(
                "swing: first layer takes {:?}, the description needs {} inputs",
                self.mlp[0].0.size(),
                s.inputs()
            );
        }
        if s.bones.len() != s.pivots.len() {
            bail!(
                "swing: {} bones but {} pivots",
                s.bones.len(),
                s.pivots.len()
            );
        }
        if self.basis.size() != [s.shapes as i64, 3 * s.vertices as i64] {
            bail!(
                "swing: basis {:?} does not match {} shapes",
                self.basis.size(),
                s.shapes
            );
        }
        let modal = s.integrator == SwingIntegrator::Modal;
        if modal != self.modes.is_some() {
            bail!(
                "swing: the {:?} integrator with modes {}",
                s.integrator,
                self.modes.is_some()
            );
        }
        if modal && !s.bones.is_empty() {
            bail!("swing: the modal integrator steps blend shapes only, not bones");
        }
        Ok(())
    }
}

/// Rotation matrices `[.., 3, 3]` from rotation vectors `[.., 3]` (Rodrigues), smooth at zero.
fn rodrigues(r: &Tensor) -> Tensor {
    let theta2 = r
        .square()
        .sum_dim_intlist(-1, true, Kind::Float)
        .clamp_min(1e-12);
    let theta = theta2.sqrt();
    let a = (theta.sin() / &theta).unsqueeze(-1);
    let c = ((-theta.cos() + 1.0) / &theta2).unsqueeze(-1);
    let (x, y, z) = (r.select(-1, 0), r.select(-1, 1), r.select(-1, 2));
    let zero = x.zeros_like();
    let k = Tensor::stack(
        &[&zero, &(-&z), &y, &z, &zero, &(-&x), &(-&y), &x, &zero],
        -1,
    );
    let mut shape = r.size();
    shape.push(3);
    let k = k.view(shape.as_slice());
    let eye = Tensor::eye(3, (Kind::Float, r.device()));
    eye + &a * &k + &c * k.matmul(&k)
}

/// The motion-history inputs of a clip's frames played in order at `shape.fps`, `[F × M]` raw
/// (metres, radians, seconds). Frames before the first repeat it: the clip starts from rest.
pub fn motion_inputs(
    skeleton: &Skeleton,
    poses: &[Vec<JointTransform>],
    shape: &SwingShape,
) -> Vec<f32> {
    let root = (0..skeleton.joint_count())
        .find(|&j| skeleton.parents[j].is_none())
        .unwrap_or(0);
    let fps = shape.fps;
    let mut out = Vec::with_capacity(poses.len() * shape.motion_inputs());
    let rot = |f: usize, j: usize| poses[f][j].rotation;
    for t in 0..poses.len() {
        let to_root = rot(t, root).inverse();
        for &lag in &shape.lags {
            let s = t.saturating_sub(lag);
            let r = s.saturating_sub(1);
            let v = to_root * (poses[s][root].translation - poses[r][root].translation) * fps;
            // Angular velocity: the turn from r to s in r's frame, carried into t's root frame.
            let turn = scaled_axis(&(rot(r, root).inverse() * rot(s, root)));
            let w = to_root * (rot(r, root) * turn) * fps;
            out.extend([v.x, v.y, v.z, w.x, w.y, w.z]);
            for &j in &shape.joints {
                let a = scaled_axis(&(rot(r, j).inverse() * rot(s, j))) * fps;
                out.extend([a.x, a.y, a.z]);
            }
        }
        let g = to_root * Vector3::from(DOWN);
        out.extend([g.x, g.y, g.z]);
    }
    out
}

/// The rate a model's clips are played at: a swing steps at its own rate, so a clip is
/// resampled to it (an `--fps` that differs is an error); other models take `fps` as given.
pub fn clip_rate(network: &super::Pbns, fps: Option<f32>) -> Result<Option<f32>> {
    let Some(s) = &network.swing else {
        return Ok(fps);
    };
    match fps {
        Some(f) if (f - s.shape.fps).abs() > 1e-3 => bail!(
            "--fps {f}: this model swings at {} fps (its time step); leave --fps out or give {}",
            s.shape.fps,
            s.shape.fps
        ),
        _ => Ok(Some(s.shape.fps)),
    }
}

fn scaled_axis(q: &UnitQuaternion<f32>) -> Vector3<f32> {
    q.scaled_axis()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_joint() -> Skeleton {
        let names: Vec<String> = ["root", "leg"].iter().map(|s| s.to_string()).collect();
        Skeleton::from_world_positions(&names, &[None, Some(0)], &[Vector3::zeros(), -Vector3::y()])
            .unwrap()
    }

    fn shape(lags: Vec<usize>) -> SwingShape {
        SwingShape {
            lags,
            joints: vec![1],
            pose_features: 6,
            width: 8,
            layers: 1,
            shapes: 2,
            bones: vec![],
            pivots: vec![],
            vertices: 3,
            fps: 30.0,
            integrator: SwingIntegrator::Network,
        }
    }

    /// A bone turns its joint's garment skinning about the joint's rest position; other joints
    /// and a zero rotation leave the matrices as they were, and the turn is differentiable at zero.
    #[test]
    fn a_bone_turns_its_joint_about_the_pivot() {
        let mut shape = shape(vec![0]);
        shape.shapes = 1;
        shape.bones = vec![1];
        shape.pivots = vec![[0.0, 1.0, 0.0]];
        let swing = Swing::new(
            shape,
            Tensor::zeros([1], (Kind::Float, Device::Cpu)),
            Tensor::ones([1], (Kind::Float, Device::Cpu)),
            Device::Cpu,
        );
        let identity: Vec<f32> = [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.].repeat(2);
        let skinning = Tensor::from_slice(&identity).view([1, 2, 12]);
        let quarter = std::f32::consts::FRAC_PI_2;
        let outputs = Tensor::from_slice(&[0.5f32, 0.0, 0.0, quarter]).view([1, 4]);
        let bent = swing.bend(&skinning, &outputs);
        let m: Vec<f32> = Vec::try_from(bent.view([-1])).unwrap();
        assert_eq!(&m[..12], &identity[..12], "joint 0 is not a bone");
        let v = [1.0f32, 1.0, 0.0];
        let x: Vec<f32> = (0..3)
            .map(|r| (0..3).map(|c| m[12 + 4 * r + c] * v[c]).sum::<f32>() + m[12 + 4 * r + 3])
            .collect();
        for (a, b) in x.iter().zip([0.0f32, 2.0, 0.0]) {
            assert!((a - b).abs() < 1e-5, "{x:?}");
        }
        let still = swing.bend(
            &skinning,
            &Tensor::from_slice(&[0.5f32, 0.0, 0.0, 0.0]).view([1, 4]),
        );
        assert!(f64::try_from((still - &skinning).abs().max()).unwrap() < 1e-7);
        let r = Tensor::zeros([1, 4], (Kind::Float, Device::Cpu)).set_requires_grad(true);
        let g = Tensor::run_backward(
            &[&swing.bend(&skinning, &r).sum(Kind::Float)],
            &[&r],
            false,
            false,
        );
        assert!(bool::try_from(g[0].isfinite().all()).unwrap());
    }

    /// A root walking +x at 1.5 m/s while turned 90° about y reads as moving along its own −z
    /// (the root's frame), at every lag once the lag is inside the clip; the first frame is at rest.
    #[test]
    fn root_velocity_is_read_in_the_roots_frame_and_the_clip_starts_at_rest() {
        let s = two_joint();
        let turn = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f32::consts::FRAC_PI_2);
        let poses: Vec<Vec<JointTransform>> = (0..5)
            .map(|f| {
                let mut root =
                    JointTransform::from_translation(Vector3::new(0.05 * f as f32, 1.0, 0.0));
                root.rotation = turn;
                vec![root, JointTransform::from_translation(-Vector3::y())]
            })
            .collect();
        let shape = shape(vec![0, 2]);
        let m = motion_inputs(&s, &poses, &shape);
        let per = shape.motion_inputs();
        assert_eq!(m.len(), 5 * per);
        assert!(
            m[..6].iter().all(|v| v.abs() < 1e-6),
            "frame 0 moves: {:?}",
            &m[..6]
        );
        let f4 = &m[4 * per..5 * per];
        for lag in 0..2 {
            let v = &f4[lag * 9..lag * 9 + 3];
            assert!(
                (v[0]).abs() < 1e-5 && (v[2] - 1.5).abs() < 1e-4,
                "lag {lag}: {v:?}"
            );
        }
        // Gravity in the root's frame: still down (the turn is about the vertical).
        assert!((f4[per - 2] + 1.0).abs() < 1e-6);
    }

    /// A swing of one blend shape and no hidden layer, with its motion-input and network-input
    /// counts.
    fn one_shape(integrator: SwingIntegrator) -> (Swing, i64, i64) {
        let shape = SwingShape {
            layers: 0,
            shapes: 1,
            integrator,
            ..shape(vec![0])
        };
        let m = shape.motion_inputs() as i64;
        let inputs = shape.inputs() as i64;
        let swing = Swing::new(
            shape,
            Tensor::zeros([m], (Kind::Float, Device::Cpu)),
            Tensor::ones([m], (Kind::Float, Device::Cpu)),
            Device::Cpu,
        );
        (swing, m, inputs)
    }

    /// The recurrence feeds its own output back: with the motion and pose fixed, a network
    /// whose only nonzero weight copies `Y_{t−1}` plus a constant counts frames.
    #[test]
    fn play_feeds_the_last_weights_back() {
        let (mut swing, m, inputs) = one_shape(SwingIntegrator::Network);
        let w = Tensor::zeros([inputs, 1], (Kind::Float, Device::Cpu));
        let _ = w.get(m + 6).fill_(1.0); // Y_{t−1}
        swing.mlp = vec![(w, Tensor::from_slice(&[1.0f32]))];
        let y = swing.play(
            &Tensor::zeros([4, m], (Kind::Float, Device::Cpu)),
            &Tensor::zeros([4, 6], (Kind::Float, Device::Cpu)),
        );
        let y: Vec<f32> = Vec::try_from(y.view([-1])).unwrap();
        assert_eq!(y, [1.0, 2.0, 3.0, 4.0]);
    }

    /// The modal integrator is a damped oscillator: released from a held weight with no drive it
    /// swings through zero about a quarter second later (a 1 Hz shape), comes back smaller, and
    /// never exceeds where it started; under a constant drive it settles at the static deflection
    /// `F / (Δt²·K)` instead of drifting.
    #[test]
    fn a_modal_swing_oscillates_decays_and_settles_under_a_steady_drive() {
        let (mut swing, m, inputs) = one_shape(SwingIntegrator::Modal);
        assert_eq!(inputs, m + 6, "no state among the network's inputs");
        let drive = |swing: &mut Swing, f: f32| {
            swing.mlp = vec![(
                Tensor::zeros([inputs, 1], (Kind::Float, Device::Cpu)),
                Tensor::from_slice(&[f]),
            )];
        };
        let run = |swing: &Swing, start: f32, frames: usize| -> Vec<f32> {
            let zero = |n: i64| Tensor::zeros([1, n], (Kind::Float, Device::Cpu));
            let (mut last, mut before) = (zero(1) + f64::from(start), zero(1) + f64::from(start));
            (0..frames)
                .map(|_| {
                    let y = swing.step(&zero(m), &zero(6), &last, &before);
                    before = std::mem::replace(&mut last, y);
                    f32::try_from(last.view([-1]).get(0)).unwrap()
                })
                .collect()
        };
        drive(&mut swing, 0.0);
        let y = run(&swing, 1.0, 300);
        let crossing = y.iter().position(|&v| v < 0.0).unwrap();
        assert!(
            (6..=9).contains(&crossing),
            "first zero crossing at frame {crossing}: {:?}",
            &y[..12]
        );
        let trough = y[..30].iter().copied().fold(f32::INFINITY, f32::min);
        let back = y[20..40].iter().copied().fold(f32::NEG_INFINITY, f32::max);
        assert!(
            trough < -0.2 && back > 0.05 && back < 0.9,
            "trough {trough}, back {back}"
        );
        assert!(
            y.iter().all(|v| v.abs() <= 1.0) && y[299].abs() < 1e-3,
            "{:?}",
            &y[290..]
        );
        drive(&mut swing, 0.1);
        let y = run(&swing, 0.0, 600);
        let k = (2.0 * std::f32::consts::PI).powi(2);
        let settled = 0.1 * 30.0 * 30.0 / k;
        assert!(
            (y[599] - settled).abs() < 1e-3 * settled,
            "{} vs {settled}",
            y[599]
        );
        assert!(y.iter().all(|v| v.is_finite() && *v < 2.0 * settled));
    }

    /// `play` (one network pass and the step's matrices once per clip) is the modal step
    /// applied frame after frame, for a drive that changes every frame.
    #[test]
    fn a_modal_play_is_its_steps_in_order() {
        let (mut swing, m, inputs) = one_shape(SwingIntegrator::Modal);
        let cpu = (Kind::Float, Device::Cpu);
        swing.mlp = vec![(
            Tensor::ones([inputs, 1], cpu) * 0.05,
            Tensor::from_slice(&[0.02f32]),
        )];
        let frames = 40;
        let motion = Tensor::linspace(-3.0, 3.0, frames * m, cpu)
            .view([frames, m])
            .sin();
        let pose = Tensor::zeros([frames, 6], cpu);
        let played = swing.play(&motion, &pose);
        let normalised = swing.normalise(&motion);
        let (mut last, mut before) = (Tensor::zeros([1, 1], cpu), Tensor::zeros([1, 1], cpu));
        let mut worst = 0.0f64;
        for f in 0..frames {
            let y = swing.step(
                &normalised.narrow(0, f, 1),
                &pose.narrow(0, f, 1),
                &last,
                &before,
            );
            worst = worst.max((&y - played.narrow(0, f, 1)).abs().max().double_value(&[]));
            before = std::mem::replace(&mut last, y);
        }
        let size = played.abs().max().double_value(&[]);
        assert!(size > 0.01, "the drive moves the swing: {size}");
        assert!(
            worst <= 1e-5 * size,
            "play and steps differ by {worst} (size {size})"
        );
    }
}
