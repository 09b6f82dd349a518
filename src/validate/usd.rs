//! USD files, checked by usd-core through python_bridge: its UsdValidation validators and our
//! UsdSkel binding rules (python_bridge/src/usd_validator.py). A garbled file is an error here.
//! The replay plays the garment through UsdSkel itself (python_bridge/src/usd_replay.py), never
//! through our own evaluator, and compares it with the model like the glTF replay.

use super::replay::{Reference, ReplayError};
use super::Problems;
use anyhow::Result;
use std::path::Path;

#[cfg(feature = "usd")]
pub fn check_usd(path: &Path, p: &mut Problems) -> Result<()> {
    for (severity, at, message) in python_bridge::validate_usd(path)? {
        match severity.as_str() {
            "error" => p.error(at, message),
            _ => p.warning(at, message),
        }
    }
    Ok(())
}

/// The garment (the mesh with the bake's seam-split vertex count, or the model's own for a
/// point cache such as `eval`'s) played by usd-core at every frame of the clip (the `clip`
/// variant named after it), against the model. Errors say why it cannot be played.
#[cfg(feature = "usd")]
pub fn replay_usd(
    path: &Path,
    reference: &Reference,
    tolerance_mm: f64,
) -> Result<ReplayError, String> {
    use super::replay::compare;
    let (baked, model) = (reference.baked_vertex.len(), reference.vertex_count());
    let frames = reference.frames.len();
    let clip = exporters::usd::identifier(&reference.clip);
    let played = python_bridge::replay_usd(
        path,
        &[baked, model],
        &clip,
        reference.frames.fps as f64,
        frames,
    )
    .map_err(|e| e.to_string())??;
    if played.samples != frames {
        return Err(format!(
            "{} has {} time samples, the clip {frames} frames (another --fps?)",
            played.mesh, played.samples
        ));
    }
    // A skinned garment is the bake's (split at UV seams); a point cache keeps the model's order.
    let identity: Vec<u32>;
    let map = if played.skinned && played.frames[0].len() == baked {
        &reference.baked_vertex
    } else {
        identity = (0..model as u32).collect();
        &identity
    };
    if played.frames.iter().any(|f| f.len() != map.len()) {
        return Err(format!(
            "{} changes its point count over the clip",
            played.mesh
        ));
    }
    Ok(compare(reference, map, tolerance_mm, |f| {
        played.frames[f].iter().map(|q| q.map(f64::from)).collect()
    }))
}

#[cfg(not(feature = "usd"))]
pub fn check_usd(path: &Path, _: &mut Problems) -> Result<()> {
    anyhow::bail!(
        "{}: this garmentbake was built without USD support (cargo feature `usd`)",
        path.display()
    )
}

#[cfg(not(feature = "usd"))]
pub fn replay_usd(_: &Path, _: &Reference, _: f64) -> Result<ReplayError, String> {
    Err("this garmentbake was built without USD support (cargo feature `usd`)".into())
}
