//! The rig: Skeleton (joints, parents, rest, inverse binds), forward kinematics, linear blend
//! skinning, SkelAnimation clips, and retargeting of motion capture onto the body (feet grounded
//! by the skinned feet).

pub mod animation;
pub mod capture;
pub mod ground;
pub mod retarget;
pub mod skeleton;
pub mod skin;
pub mod weights;

pub use animation::SkelAnimation;
pub use skeleton::{JointTransform, PlainSkeleton, Skeleton};
pub use skin::Skin;

#[derive(Debug, thiserror::Error)]
pub enum RigError {
    #[error("{0}")]
    Invalid(String),
}
