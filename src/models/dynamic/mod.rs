//! The motion-guided dynamic garment model (Zhang et al., "Motion Guided Deep Dynamic 3D
//! Garments"), stage 1: the generative space of garment deformations. A garment frame, measured
//! relative to body seed points and laid out in its UV map, is encoded to a latent `Z`; the
//! decoder gives per-vertex displacements in each vertex's rest frame and the garment is skinned
//! by the seeds with distance-based weights whose kernel radius is learnt per body part.

pub mod seeds;
pub mod space;
pub mod uv;

pub use seeds::Seeds;
pub use space::{Space, SpaceShape};
pub use uv::UvRaster;
