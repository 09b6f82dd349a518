//! Neural garment models: the PBNS static (pose-driven) model, its inputs and its file format.

pub mod file;
pub mod pbns;
pub mod pose_features;

pub use pbns::{Pbns, PbnsShape};
