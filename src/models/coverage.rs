//! Pose coverage: how far a pose lies from the poses a model was trained on, measured as pose
//! balancing measures it, and the range of the network's blend-shape weights over those poses
//! (what clamped correctives keep to on poses beyond it).
//!
//! A pose is compared by the rotation vectors (axis × angle, radians) of the local rotations of
//! the joints that move the garment (the model's feature joints); the distance of two poses is
//! the largest difference of any component of any joint. Balancing keeps a frame when this
//! distance to every kept frame reaches its threshold. A pose is beyond the trained range when
//! it lies farther from every training pose than the training clips' own frames lie from the
//! poses of the clips' other parts (a high percentile of those held-out distances, learnt by
//! `train` and stored in the model), so the model never saw anything like it.

use nalgebra::{UnitQuaternion, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tch::{Kind, Tensor};

/// A pose as balancing compares it: one rotation vector per compared joint.
pub type PoseKey = Vec<Vector3<f32>>;

/// The key of a pose given all its local joint rotations, for the compared `joints`.
pub fn pose_key(rotations: &[UnitQuaternion<f32>], joints: &[usize]) -> PoseKey {
    joints.iter().map(|&j| rotations[j].scaled_axis()).collect()
}

/// The largest difference of any rotation-vector component of any joint (radians).
pub fn pose_distance(a: &[Vector3<f32>], b: &[Vector3<f32>]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).amax())
        .fold(0.0, f32::max)
}

/// The poses a model was trained on and its blend-shape weights over them.
#[derive(Clone, Debug, PartialEq)]
pub struct Coverage {
    /// Keys of the training poses (real and generated), in the model's feature joints.
    pub poses: Vec<PoseKey>,
    /// A pose at least this far from every training pose is beyond the trained range (learnt
    /// from the training clips' held-out distances; the balancing threshold in older files).
    pub threshold: f32,
    /// Lowest and highest weight of each blend shape (PSD basis vector) over the training poses.
    pub weight_min: Vec<f32>,
    pub weight_max: Vec<f32>,
}

impl Coverage {
    /// Distance from `key` to the nearest training pose.
    pub fn distance(&self, key: &[Vector3<f32>]) -> f32 {
        self.poses
            .iter()
            .map(|p| pose_distance(p, key))
            .fold(f32::INFINITY, f32::min)
    }

    /// [`Coverage::distance`] of many poses, in parallel.
    pub fn distances(&self, keys: &[PoseKey]) -> Vec<f32> {
        keys.par_iter().map(|k| self.distance(k)).collect()
    }

    /// Whether a pose this far from the training set is beyond the trained range.
    pub fn beyond(&self, distance: f32) -> bool {
        distance >= self.threshold
    }

    /// Which of the network's blend-shape weights `weights` (`[frames, K]`, unclamped) lie
    /// outside their training range: what clamped correctives change.
    pub fn weights_outside(&self, weights: &Tensor) -> OutsideWeights {
        let device = weights.device();
        let lo = Tensor::from_slice(&self.weight_min).to_device(device);
        let hi = Tensor::from_slice(&self.weight_max).to_device(device);
        let outside = weights.lt_tensor(&lo).logical_or(&weights.gt_tensor(&hi));
        let count = |t: Tensor| t.sum(Kind::Int64).int64_value(&[]) as usize;
        OutsideWeights {
            values: weights.numel(),
            outside: count(outside.shallow_clone()),
            frames: count(outside.any_dim(1, false)),
        }
    }
}

/// How many blend-shape weights of a clip lie outside the training range.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutsideWeights {
    /// Weights looked at (frames × blend shapes).
    pub values: usize,
    pub outside: usize,
    /// Frames with at least one weight outside.
    pub frames: usize,
}
