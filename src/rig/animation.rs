//! SkelAnimation: local joint transforms of a skeleton sampled at a fixed frame rate.

use super::{JointTransform, Skeleton};
use nalgebra::{UnitQuaternion, Vector3};

#[derive(Clone, Debug, PartialEq)]
pub struct SkelAnimation {
    pub name: String,
    pub fps: f32,
    /// `[frame][joint]`, in the skeleton's joint order.
    pub translations: Vec<Vec<Vector3<f32>>>,
    pub rotations: Vec<Vec<UnitQuaternion<f32>>>,
}

impl SkelAnimation {
    /// A clip from local poses per frame (e.g. several clips chained for one roll-out).
    pub fn from_poses(name: &str, fps: f32, poses: &[Vec<JointTransform>]) -> SkelAnimation {
        SkelAnimation {
            name: name.into(),
            fps,
            translations: poses
                .iter()
                .map(|p| p.iter().map(|j| j.translation).collect())
                .collect(),
            rotations: poses
                .iter()
                .map(|p| p.iter().map(|j| j.rotation).collect())
                .collect(),
        }
    }

    pub fn frame_count(&self) -> usize {
        self.rotations.len()
    }

    pub fn duration(&self) -> f32 {
        self.frame_count().saturating_sub(1) as f32 / self.fps
    }

    /// Local joint transforms at `frame` (scale stays 1).
    pub fn local_pose(&self, frame: usize) -> Vec<JointTransform> {
        self.translations[frame]
            .iter()
            .zip(&self.rotations[frame])
            .map(|(t, r)| JointTransform {
                translation: *t,
                rotation: *r,
                scale: Vector3::repeat(1.0),
            })
            .collect()
    }

    /// World-space joint positions at `frame`.
    pub fn joint_positions(&self, skeleton: &Skeleton, frame: usize) -> Vec<Vector3<f32>> {
        skeleton
            .world_matrices(&self.local_pose(frame))
            .iter()
            .map(|m| m.fixed_view::<3, 1>(0, 3).into_owned())
            .collect()
    }

    /// Keeps every `step`-th frame from `start` (explicit resampling for `--fps`-style requests).
    pub fn subsampled(&self, start: usize, step: usize) -> SkelAnimation {
        let step = step.max(1);
        SkelAnimation {
            name: self.name.clone(),
            fps: self.fps / step as f32,
            translations: self
                .translations
                .iter()
                .skip(start)
                .step_by(step)
                .cloned()
                .collect(),
            rotations: self
                .rotations
                .iter()
                .skip(start)
                .step_by(step)
                .cloned()
                .collect(),
        }
    }
}
