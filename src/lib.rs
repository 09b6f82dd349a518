//! garmentbake: train neural garment deformers and bake them into standard files.
//!
//! Data flows one way: inputs (`io`) → rig / geometry → models → baked asset → exporters → files.

pub mod bake;
pub mod cli;
pub mod eval;
pub mod garment;
pub mod geometry;
pub mod io;
pub mod models;
pub mod motion;
pub mod preview;
pub mod rig;
pub mod train;
