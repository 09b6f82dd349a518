//! Writers that turn a [`asset::BakedAsset`] into files.
//!
//! The baked asset is plain data (gltfpack style): everything a format needs, nothing about how it
//! was produced. It lives here rather than in the core crate because the core's CLI calls the
//! exporters, and Cargo forbids the cycle; data still flows one way: model → asset → exporter → file.

pub mod asset;
pub mod atomic;
pub mod gltf;
pub mod pc2;
#[cfg(feature = "usd")]
pub mod usd;

pub use asset::{BakedAsset, PointCache};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Gltf(#[from] gltf::GltfError),
    #[cfg(feature = "usd")]
    #[error(transparent)]
    Usd(#[from] usd::UsdError),
    #[error("cannot write {path}: {what}")]
    Unsupported { path: String, what: String },
}

/// The file formats chosen by output extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// `.glb` / `.gltf`
    Gltf,
    /// `.usda` / `.usdc` / `.usdz`
    Usd,
}

impl Format {
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_string_lossy().to_ascii_lowercase();
        match ext.as_str() {
            "glb" | "gltf" => Some(Format::Gltf),
            "usda" | "usdc" | "usdz" => Some(Format::Usd),
            _ => None,
        }
    }
}

/// Writes a skinned asset in the format its extension names.
pub fn write(asset: &BakedAsset, path: &Path) -> Result<(), ExportError> {
    match Format::from_path(path) {
        Some(Format::Gltf) => Ok(gltf::write(asset, path)?),
        Some(Format::Usd) => write_usd(asset, path),
        None => Err(unsupported(
            path,
            "unknown extension; use .glb, .gltf, .usda, .usdc or .usdz",
        )),
    }
}

/// Writes a per-frame point cache in the format its extension names.
pub fn write_point_cache(cache: &PointCache, path: &Path) -> Result<(), ExportError> {
    match Format::from_path(path) {
        Some(Format::Usd) => write_usd_cache(cache, path),
        _ => Err(unsupported(
            path,
            "unknown point-cache extension; use .usda, .usdc or .usdz",
        )),
    }
}

fn unsupported(path: &Path, what: &str) -> ExportError {
    ExportError::Unsupported {
        path: path.display().to_string(),
        what: what.into(),
    }
}

#[cfg(feature = "usd")]
fn write_usd(asset: &BakedAsset, path: &Path) -> Result<(), ExportError> {
    Ok(usd::write(asset, path)?)
}

#[cfg(feature = "usd")]
fn write_usd_cache(cache: &PointCache, path: &Path) -> Result<(), ExportError> {
    Ok(usd::write_point_cache(cache, path)?)
}

#[cfg(not(feature = "usd"))]
const NO_USD: &str = "this garmentbake was built without USD support (cargo feature `usd`); rebuild with default features";

#[cfg(not(feature = "usd"))]
fn write_usd(_: &BakedAsset, path: &Path) -> Result<(), ExportError> {
    Err(unsupported(path, NO_USD))
}

#[cfg(not(feature = "usd"))]
fn write_usd_cache(_: &PointCache, path: &Path) -> Result<(), ExportError> {
    Err(unsupported(path, NO_USD))
}
