//! What the dynamic model needs of the posed body at each frame, as tensors: the anchors'
//! positions, transforms and normals, the root joint's rotation and position, and every joint's
//! local rotation (the motion stage's body drive).

use super::anchors::BodyAnchors;
use crate::body::Body;
use crate::models::pose_features::{pose_features, PER_JOINT};
use crate::rig::JointTransform;
use tch::{Device, Tensor};

/// Per-frame body quantities `[F, ...]`.
pub struct BodyFrames {
    /// Seed positions `[F, N, 3]`.
    pub anchors: Tensor,
    /// Seed LBS transforms, row-major 3×4, `[F, N, 12]`.
    pub transforms: Tensor,
    /// Seed normals (the rest normal turned by the transform) `[F, N, 3]`.
    pub normals: Tensor,
    /// The root joint's rotation against the bind pose `[F, 3, 3]`.
    pub root: Tensor,
    /// The root joint's world position `[F, 3]`.
    pub origin: Tensor,
    /// Every joint's local rotation as 6-D features (`pose_features`: rest = 0) `[F, J, 6]`.
    pub rotations: Tensor,
}

impl BodyFrames {
    pub fn new(
        body: &Body,
        anchors: &BodyAnchors,
        poses: &[Vec<JointTransform>],
        device: Device,
    ) -> BodyFrames {
        let (mut b, mut m, mut n, mut r) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let (mut origin, mut rotations) = (Vec::new(), Vec::new());
        let joints: Vec<usize> = (0..body.skeleton.joint_count()).collect();
        for pose in poses {
            let skinning = body.skeleton.skinning_matrices(pose);
            for (j, t) in anchors.transforms(body, &skinning).iter().enumerate() {
                let (p, normal) = (anchors.rest[j], body.normals[anchors.vertices[j] as usize]);
                let row = |k: usize, x: [f32; 3], w: f32| {
                    t[4 * k] * x[0] + t[4 * k + 1] * x[1] + t[4 * k + 2] * x[2] + t[4 * k + 3] * w
                };
                b.extend((0..3).map(|k| row(k, p, 1.0)));
                let turned: [f32; 3] = std::array::from_fn(|k| row(k, normal, 0.0));
                let len = turned.iter().map(|x| x * x).sum::<f32>().sqrt().max(1e-12);
                n.extend(turned.map(|x| x / len));
                m.extend_from_slice(t);
            }
            let root = skinning[0];
            r.extend((0..9).map(|k| root[(k / 3, k % 3)]));
            // Joint 0 is the root (`skinning[0]` above): its local transform is its world one.
            origin.extend(pose[0].translation.iter().copied());
            let local: Vec<_> = pose.iter().map(|t| t.rotation).collect();
            rotations.extend(pose_features(&joints, &local));
        }
        let j = joints.len() as i64;
        let (f, s) = (poses.len() as i64, anchors.rest.len() as i64);
        let t = |v: Vec<f32>, d: &[i64]| Tensor::from_slice(&v).reshape(d).to_device(device);
        BodyFrames {
            anchors: t(b, &[f, s, 3]),
            transforms: t(m, &[f, s, 12]),
            normals: t(n, &[f, s, 3]),
            root: t(r, &[f, 3, 3]),
            origin: t(origin, &[f, 3]),
            rotations: t(rotations, &[f, j, PER_JOINT as i64]),
        }
    }

    /// Frames `idx` `[B]`.
    pub fn select(&self, idx: &Tensor) -> BodyFrames {
        BodyFrames {
            anchors: self.anchors.index_select(0, idx),
            transforms: self.transforms.index_select(0, idx),
            normals: self.normals.index_select(0, idx),
            root: self.root.index_select(0, idx),
            origin: self.origin.index_select(0, idx),
            rotations: self.rotations.index_select(0, idx),
        }
    }

    /// Frames of several clips, one after another.
    pub fn cat(parts: &[BodyFrames]) -> BodyFrames {
        let all = |f: fn(&BodyFrames) -> &Tensor| {
            Tensor::cat(&parts.iter().map(f).collect::<Vec<_>>(), 0)
        };
        BodyFrames {
            anchors: all(|p| &p.anchors),
            transforms: all(|p| &p.transforms),
            normals: all(|p| &p.normals),
            root: all(|p| &p.root),
            origin: all(|p| &p.origin),
            rotations: all(|p| &p.rotations),
        }
    }
}
