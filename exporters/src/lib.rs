//! Writers that turn a [`asset::BakedAsset`] into files.
//!
//! The baked asset is plain data (gltfpack style): everything a format needs, nothing about how it
//! was produced. It lives here rather than in the core crate because the core's CLI calls the
//! exporters, and Cargo forbids the cycle; data still flows one way: model → asset → exporter → file.

pub mod asset;
pub mod atomic;
pub mod gltf;
pub mod pc2;

pub use asset::BakedAsset;
