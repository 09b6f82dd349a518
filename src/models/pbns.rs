//! The PBNS static model: `V(θ) = LBS(T + Σ_k X_k(θ)·D_k, θ, W)`.
//!
//! `X = f(θ)` is an MLP of fully-connected ReLU layers over the pose features, `D` the PSD basis
//! (`[K, N, 3]`, K = MLP width) and `W` sparse blend weights: every vertex has `influences` joint
//! slots fixed at initialisation and one trainable logit per slot; a softmax over the slots gives
//! non-negative weights that sum to one. Engines play at most 4 (or 8) influences, so keeping
//! the sparsity pattern fixed means baking the trained skin loses nothing.

use super::pose_features::PoseBatch;
use super::sparse_skin;
use super::swing::{self, Swing};
use crate::rig::{JointTransform, Skeleton, Skin};
use tch::{Device, Kind, Tensor};

/// Logit of a slot that holds no joint: its softmax weight is exactly zero in f32 and so is its
/// gradient, so it never becomes active.
pub const EMPTY_SLOT_LOGIT: f32 = -1.0e4;
/// Initial weight of a slot added as a training candidate (an ancestor of the vertex's main
/// joint): small enough that the initial skin is the proximity skin, large enough for Adam.
pub const CANDIDATE_WEIGHT: f32 = 1.0e-4;

/// Sizes of a model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PbnsShape {
    /// MLP inputs (pose features).
    pub features: usize,
    /// Width of every MLP layer = number of PSD basis vectors K.
    pub width: usize,
    /// Fully-connected ReLU layers.
    pub layers: usize,
    pub vertices: usize,
    pub joints: usize,
    /// Joint slots per vertex (4 or 8).
    pub influences: usize,
}

pub struct Pbns {
    pub shape: PbnsShape,
    /// Joints whose rotations are the MLP input (6 values each), in order.
    pub feature_joints: Vec<usize>,
    /// `(weight [in, out], bias [out])` per layer.
    pub mlp: Vec<(Tensor, Tensor)>,
    /// PSD basis `[K, N * 3]`.
    pub psd: Tensor,
    /// Rest garment `T` `[N, 3]`.
    pub template: Tensor,
    /// Joint of each slot `[N, influences]` (int64).
    pub joints: Tensor,
    /// Slot logits `[N, influences]`.
    pub logits: Tensor,
    /// Clamped correctives: the blend-shape weights kept within `(lowest, highest)` `[K]` each
    /// (the range over the training poses), as engine ML deformers do on unseen poses.
    pub clamp: Option<(Tensor, Tensor)>,
    /// A learnt dynamic response (`train-swing`): more blend shapes whose weights follow the
    /// motion; `None` for the quasi-static PBNS.
    pub swing: Option<Box<Swing>>,
}

/// What the forward pass returns: posed vertices and the rest-space PSD displacement (which the
/// pinning term needs).
pub struct Output {
    pub vertices: Tensor,
    pub displacement: Tensor,
}

impl Pbns {
    /// A fresh model: MLP initialised like PyTorch's `Linear` (uniform ±1/√fan_in, from the
    /// global tch seed), `D = 0` (so the untrained model is plain LBS), `W` from `skin`.
    pub fn new(
        shape: PbnsShape,
        feature_joints: Vec<usize>,
        template: &[[f32; 3]],
        skin: &Skin,
        skeleton: &Skeleton,
        device: Device,
    ) -> Pbns {
        let opts = (Kind::Float, device);
        let mut mlp = Vec::with_capacity(shape.layers);
        let mut fan_in = shape.features;
        for _ in 0..shape.layers {
            let bound = 1.0 / (fan_in as f64).sqrt();
            let w =
                Tensor::zeros([fan_in as i64, shape.width as i64], opts).uniform_(-bound, bound);
            let b = Tensor::zeros([shape.width as i64], opts).uniform_(-bound, bound);
            mlp.push((w, b));
            fan_in = shape.width;
        }
        let psd = Tensor::zeros([shape.width as i64, 3 * shape.vertices as i64], opts);
        let (joints, logits) = slot_logits(skin, skeleton, shape.influences);
        let n = shape.vertices as i64;
        let k = shape.influences as i64;
        Pbns {
            shape,
            feature_joints,
            mlp,
            psd,
            template: points_tensor(template, device),
            joints: Tensor::from_slice(&joints).view([n, k]).to_device(device),
            logits: Tensor::from_slice(&logits).view([n, k]).to_device(device),
            clamp: None,
            swing: None,
        }
    }

    /// The trainable tensors with their file names; `weights` adds the slot logits.
    pub fn parameters(&self, weights: bool) -> Vec<(String, &Tensor)> {
        let mut out = Vec::new();
        for (i, (w, b)) in self.mlp.iter().enumerate() {
            out.push((format!("mlp.{i}.weight"), w));
            out.push((format!("mlp.{i}.bias"), b));
        }
        out.push(("psd".to_string(), &self.psd));
        if weights {
            out.push(("W.logits".to_string(), &self.logits));
        }
        out
    }

    /// A detached copy of the trainable tensors (`weights`: with the slot logits), named as
    /// [`Pbns::parameters`] names them.
    pub fn snapshot(&self, weights: bool) -> Vec<(String, Tensor)> {
        self.parameters(weights)
            .into_iter()
            .map(|(n, t)| (n, t.detach().copy()))
            .collect()
    }

    /// This model with the tensors of `snapshot` in place of its own (no gradients): the model
    /// as it was when the snapshot was taken.
    pub fn with_snapshot(&self, snapshot: &[(String, Tensor)]) -> Pbns {
        let find = |name: &str, own: &Tensor| {
            snapshot
                .iter()
                .find(|(n, _)| n == name)
                .map_or_else(|| own.detach(), |(_, t)| t.detach())
        };
        Pbns {
            shape: self.shape,
            feature_joints: self.feature_joints.clone(),
            mlp: self
                .mlp
                .iter()
                .enumerate()
                .map(|(i, (w, b))| {
                    (
                        find(&format!("mlp.{i}.weight"), w),
                        find(&format!("mlp.{i}.bias"), b),
                    )
                })
                .collect(),
            psd: find("psd", &self.psd),
            template: self.template.shallow_clone(),
            joints: self.joints.shallow_clone(),
            logits: find("W.logits", &self.logits),
            clamp: self
                .clamp
                .as_ref()
                .map(|(lo, hi)| (lo.shallow_clone(), hi.shallow_clone())),
            // Snapshots are of a PBNS being trained, which has no swing yet.
            swing: None,
        }
    }

    /// Turns gradient tracking on for the trainable tensors.
    pub fn set_trainable(&mut self, weights: bool) {
        for (w, b) in &mut self.mlp {
            *w = w.set_requires_grad(true);
            *b = b.set_requires_grad(true);
        }
        self.psd = self.psd.set_requires_grad(true);
        self.logits = self.logits.set_requires_grad(weights);
    }

    /// Blend weights `[N, influences]`: non-negative, summing to one per vertex.
    pub fn weights(&self) -> Tensor {
        self.logits.softmax(-1, Kind::Float)
    }

    /// The inputs for `poses`: this model's pose features and the skinning matrices; with a
    /// swing, `poses` are one clip's frames in order at the swing's rate, played from rest.
    pub fn batch(
        &self,
        skeleton: &Skeleton,
        poses: &[Vec<JointTransform>],
        device: Device,
    ) -> PoseBatch {
        let mut batch = PoseBatch::new(skeleton, &self.feature_joints, poses, device);
        if let Some(s) = &self.swing {
            let motion = swing::motion_inputs(skeleton, poses, &s.shape);
            let motion = Tensor::from_slice(&motion)
                .view([poses.len() as i64, s.shape.motion_inputs() as i64])
                .to_device(device);
            let outputs = s.play(&motion, &batch.features);
            // Swing bones turn the garment's skinning; the blend-shape part stays in `swing`.
            batch.skinning = s.bend(&batch.skinning, &outputs);
            batch.swing = Some(outputs);
        }
        batch
    }

    /// Blend-shape weights of a batch, `[B, K (+ S)]`: the MLP output `X(θ)` and, with a swing,
    /// its weights (a baked clip's weight track before compression).
    pub fn blend_weights(&self, batch: &PoseBatch) -> Tensor {
        let x = self.coefficients(&batch.features);
        match (&self.swing, &batch.swing) {
            (Some(s), Some(y)) => Tensor::cat(&[&x, &s.blend_weights(y)], 1),
            (Some(_), None) => panic!("a swing model's batch needs its clip played in order"),
            (None, _) => x,
        }
    }

    /// All blend shapes `[K (+ S), N·3]`: the PSD basis, then the swing's.
    pub fn blend_shapes(&self) -> Tensor {
        match &self.swing {
            Some(s) => Tensor::cat(&[&self.psd, &s.basis], 0),
            None => self.psd.shallow_clone(),
        }
    }

    /// Blend shapes the model plays (K, plus S with a swing).
    pub fn blend_shape_count(&self) -> usize {
        self.shape.width + self.swing.as_ref().map_or(0, |s| s.shape.shapes)
    }

    /// The MLP output `X(θ)`, `[B, K]`: the weights of the PSD basis (a baked clip's
    /// blend-shape weights before compression).
    pub fn coefficients(&self, features: &Tensor) -> Tensor {
        let mut x = features.shallow_clone();
        for (w, b) in &self.mlp {
            x = b.addmm(&x, w).relu();
        }
        match &self.clamp {
            Some((lo, hi)) => x.maximum(lo).minimum(hi),
            None => x,
        }
    }

    /// Keeps every blend-shape weight within `[lowest[k], highest[k]]` from now on.
    pub fn clamp_weights(&mut self, lowest: &[f32], highest: &[f32]) {
        let device = self.psd.device();
        self.clamp = Some((
            Tensor::from_slice(lowest).to_device(device),
            Tensor::from_slice(highest).to_device(device),
        ));
    }

    /// `X(θ)·D (+ Y·E)` in rest space, `[B, N, 3]`.
    pub fn displacement(&self, batch: &PoseBatch) -> Tensor {
        let d = self.coefficients(&batch.features).matmul(&self.psd).view([
            -1,
            self.shape.vertices as i64,
            3,
        ]);
        match (&self.swing, &batch.swing) {
            (Some(s), Some(y)) => d + s.displacement(y),
            (Some(_), None) => panic!("a swing model's batch needs its clip played in order"),
            (None, _) => d,
        }
    }

    /// Linear blend skinning of rest points `[B, N, 3]` with skinning matrices `[B, J, 12]`.
    pub fn skin_points(&self, rest: &Tensor, skinning: &Tensor) -> Tensor {
        let (n, j) = (self.shape.vertices as i64, self.shape.joints as i64);
        // Dense [N, J] weights: one small matmul blends all joints at once (cheaper than
        // gathering k matrices per vertex, and differentiable in the weights).
        let dense = Tensor::zeros([n, j], (Kind::Float, rest.device())).scatter_add(
            1,
            &self.joints,
            &self.weights(),
        );
        let b = skinning.size()[0];
        let m = dense.matmul(skinning).view([b, n, 3, 4]);
        let linear = m.narrow(3, 0, 3);
        let translation = m.select(3, 3);
        (linear * rest.unsqueeze(2)).sum_dim_intlist(-1, false, Kind::Float) + translation
    }

    /// The garment of every pose of `poses` as one `[P, N, 3]` tensor, in chunks, no gradients.
    /// On the CPU the skinning blends only each vertex's slots (as the training step does).
    pub fn predict(&self, poses: &PoseBatch) -> Tensor {
        super::predict_chunks(poses.len(), |s, n| {
            let batch = poses.slice(s, n);
            if self.psd.device() != Device::Cpu {
                return self.forward(&batch).vertices;
            }
            let rest = self.template.unsqueeze(0) + self.displacement(&batch);
            let rest_points: Vec<f32> = flat(&rest, Kind::Float);
            let skinning: Vec<f32> = flat(&batch.skinning, Kind::Float);
            let x = sparse_skin::skin(&rest_points, &skinning, self.shape.joints, &self.slots());
            Tensor::from_slice(&x.points).view(rest.size().as_slice())
        })
    }

    /// Each vertex's slot joints and blend weights as arrays, for [`sparse_skin`].
    pub fn slots(&self) -> sparse_skin::Slots {
        sparse_skin::Slots {
            joints: flat(&self.joints, Kind::Int64),
            weights: flat(&self.weights(), Kind::Float),
            influences: self.shape.influences,
        }
    }

    /// [`Pbns::predict`] as points on the CPU, one list per pose.
    pub fn predict_points(&self, poses: &PoseBatch) -> Vec<Vec<[f32; 3]>> {
        let n = self.shape.vertices;
        super::pose_features::tensor_points(&self.predict(poses))
            .chunks_exact(n)
            .map(<[_]>::to_vec)
            .collect()
    }

    /// The network's own forward pass ([`Pbns::forward`]: dense skinning in torch, as training
    /// computes the loss) over `poses`, in chunks, no gradients, as points on the CPU, one list
    /// per pose. The reference the exported files are checked against: on the CPU it shares no
    /// skinning code with [`Pbns::predict_points`] (which `eval` writes caches with) nor with a
    /// bake's blend shapes and skin.
    pub fn forward_points(&self, poses: &PoseBatch) -> Vec<Vec<[f32; 3]>> {
        let n = self.shape.vertices;
        let x = super::predict_chunks(poses.len(), |s, k| {
            self.forward(&poses.slice(s, k)).vertices
        });
        super::pose_features::tensor_points(&x)
            .chunks_exact(n)
            .map(<[_]>::to_vec)
            .collect()
    }

    pub fn forward(&self, batch: &PoseBatch) -> Output {
        let displacement = self.displacement(batch);
        let rest = self.template.unsqueeze(0) + &displacement;
        Output {
            vertices: self.skin_points(&rest, &batch.skinning),
            displacement,
        }
    }

    /// The current blend weights as an engine skin (exactly the model's weights: the pattern
    /// already has at most `influences` entries).
    pub fn skin(&self) -> Skin {
        let joints: Vec<i64> = flat(&self.joints, Kind::Int64);
        let weights: Vec<f32> = flat(&self.weights(), Kind::Float);
        let per_vertex: Vec<Vec<(u16, f32)>> = joints
            .chunks_exact(self.shape.influences)
            .zip(weights.chunks_exact(self.shape.influences))
            .map(|(j, w)| j.iter().zip(w).map(|(&j, &w)| (j as u16, w)).collect())
            .collect();
        Skin::from_sparse(&per_vertex, self.shape.influences, 0)
    }
}

/// Slots and logits from an initial skin: its joints (log weights), then ancestors of the
/// vertex's main joint as low-weight candidates (a skirt's hem may need the hips), then empty.
fn slot_logits(skin: &Skin, skeleton: &Skeleton, influences: usize) -> (Vec<i64>, Vec<f32>) {
    let mut joints = Vec::with_capacity(skin.vertex_count() * influences);
    let mut logits = Vec::with_capacity(skin.vertex_count() * influences);
    for v in 0..skin.vertex_count() {
        let mut slots: Vec<(usize, f32)> = skin.vertex(v).filter(|(_, w)| *w > 0.0).collect();
        slots.truncate(influences);
        let mut ancestor = slots.first().and_then(|&(j, _)| skeleton.parents[j]);
        while let Some(a) = ancestor {
            if slots.len() >= influences {
                break;
            }
            if !slots.iter().any(|&(j, _)| j == a) {
                slots.push((a, CANDIDATE_WEIGHT));
            }
            ancestor = skeleton.parents[a];
        }
        for k in 0..influences {
            match slots.get(k) {
                Some(&(j, w)) => {
                    joints.push(j as i64);
                    logits.push(w.ln());
                }
                None => {
                    joints.push(0);
                    logits.push(EMPTY_SLOT_LOGIT);
                }
            }
        }
    }
    (joints, logits)
}

pub fn points_tensor(points: &[[f32; 3]], device: Device) -> Tensor {
    let flat: Vec<f32> = points.iter().flatten().copied().collect();
    Tensor::from_slice(&flat)
        .view([points.len() as i64, 3])
        .to_device(device)
}

/// Any tensor as a flat vector on the CPU.
pub fn flat<T: tch::kind::Element + Copy>(t: &Tensor, kind: Kind) -> Vec<T> {
    let t = t
        .detach()
        .to_device(Device::Cpu)
        .to_kind(kind)
        .contiguous()
        .view([-1]);
    Vec::try_from(&t).expect("tensor of the requested kind")
}
