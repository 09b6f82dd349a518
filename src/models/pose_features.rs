//! The MLP's input: the pose as 6-D rotations (first two matrix columns) of the joints that move
//! the garment (never a root).
//!
//! Global orientation and root translation are excluded: skinning applies them, and a garment
//! must not deform differently because the character turned or walked elsewhere. Joints that do
//! not move the garment (a skirt's arms, fingers) are excluded too: in a few hundred training
//! poses they correlate by chance with the legs, and the network would learn those accidents and
//! fail on unseen poses. The 6-D form is continuous (unlike axis-angle or quaternions), which an
//! MLP needs; the identity's columns are subtracted so the rest pose maps to zeros.

use crate::rig::{JointTransform, Skeleton};
use nalgebra::UnitQuaternion;
use tch::{Device, Kind, Tensor};

/// Values per joint.
pub const PER_JOINT: usize = 6;

/// Every joint with a parent (roots carry the global orientation).
pub fn non_root_joints(skeleton: &Skeleton) -> Vec<usize> {
    (0..skeleton.joint_count())
        .filter(|&j| skeleton.parents[j].is_some())
        .collect()
}

/// Features of one pose given its local joint rotations, for the joints `joints`.
pub fn pose_features(joints: &[usize], rotations: &[UnitQuaternion<f32>]) -> Vec<f32> {
    let mut out = Vec::with_capacity(PER_JOINT * joints.len());
    for &j in joints {
        let m = rotations[j].to_rotation_matrix();
        let m = m.matrix();
        for c in 0..2 {
            for r in 0..3 {
                let identity = if r == c { 1.0 } else { 0.0 };
                out.push(m[(r, c)] - identity);
            }
        }
    }
    out
}

/// Skinning matrices of one pose, row-major 3×4 per joint (the last row of an affine matrix is
/// constant): `[J × 12]`.
pub fn skinning_rows(skeleton: &Skeleton, local: &[JointTransform]) -> Vec<f32> {
    let mut out = Vec::with_capacity(12 * skeleton.joint_count());
    for m in skeleton.skinning_matrices(local) {
        for r in 0..3 {
            for c in 0..4 {
                out.push(m[(r, c)]);
            }
        }
    }
    out
}

/// The two tensors a model needs for a batch of poses: features `[B, F]` and skinning matrices
/// `[B, J, 12]`; for a model that swings, the swing weights of the poses played in order `[B, S]`
/// (see [`crate::models::swing`]).
pub struct PoseBatch {
    pub features: Tensor,
    pub skinning: Tensor,
    pub swing: Option<Tensor>,
}

impl PoseBatch {
    /// Features of the joints `joints` and skinning matrices of every joint.
    pub fn new(
        skeleton: &Skeleton,
        joints: &[usize],
        poses: &[Vec<JointTransform>],
        device: Device,
    ) -> PoseBatch {
        let b = poses.len() as i64;
        let width = PER_JOINT * joints.len();
        let mut features = Vec::with_capacity(poses.len() * width);
        let mut skinning = Vec::with_capacity(poses.len() * 12 * skeleton.joint_count());
        for pose in poses {
            let rotations: Vec<_> = pose.iter().map(|t| t.rotation).collect();
            features.extend(pose_features(joints, &rotations));
            skinning.extend(skinning_rows(skeleton, pose));
        }
        PoseBatch {
            features: Tensor::from_slice(&features)
                .view([b, width as i64])
                .to_device(device),
            skinning: Tensor::from_slice(&skinning)
                .view([b, skeleton.joint_count() as i64, 12])
                .to_device(device),
            swing: None,
        }
    }

    /// Rows `index` of both tensors (a mini-batch out of a precomputed pose set).
    pub fn select(&self, index: &Tensor) -> PoseBatch {
        PoseBatch {
            features: self.features.index_select(0, index),
            skinning: self.skinning.index_select(0, index),
            swing: self.swing.as_ref().map(|s| s.index_select(0, index)),
        }
    }

    pub fn len(&self) -> usize {
        self.features.size()[0] as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Rows `start..start + len`.
    pub fn slice(&self, start: usize, len: usize) -> PoseBatch {
        PoseBatch {
            features: self.features.narrow(0, start as i64, len as i64),
            skinning: self.skinning.narrow(0, start as i64, len as i64),
            swing: self
                .swing
                .as_ref()
                .map(|s| s.narrow(0, start as i64, len as i64)),
        }
    }
}

/// Flattens an `[.., 3]` f32 tensor into points (copies to the CPU).
pub fn tensor_points(t: &Tensor) -> Vec<[f32; 3]> {
    let flat = t
        .to_device(Device::Cpu)
        .to_kind(Kind::Float)
        .contiguous()
        .view([-1]);
    let v: Vec<f32> = Vec::try_from(&flat).expect("float tensor");
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn rest_pose_maps_to_zero_and_roots_are_skipped() {
        let names: Vec<String> = ["root", "a"].iter().map(|s| s.to_string()).collect();
        let s = Skeleton::from_world_positions(
            &names,
            &[None, Some(0)],
            &[Vector3::zeros(), Vector3::y()],
        )
        .unwrap();
        let joints = non_root_joints(&s);
        assert_eq!(joints, [1]);
        let mut rot = vec![UnitQuaternion::identity(); 2];
        assert_eq!(pose_features(&joints, &rot), vec![0.0; 6]);
        rot[0] = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.0);
        assert_eq!(pose_features(&joints, &rot), vec![0.0; 6]);
        rot[1] = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.0);
        let f = pose_features(&joints, &rot);
        assert!((f[0] - (1f32.cos() - 1.0)).abs() < 1e-6 && (f[1] - 1f32.sin()).abs() < 1e-6);
    }
}
