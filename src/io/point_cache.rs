//! Reading point caches back (PC2): a garment's vertices per frame, checked against the mesh
//! they belong to.

use anyhow::{bail, Context, Result};
use std::path::Path;

/// Every frame of a PC2 file whose point count must be `vertices` (the mesh it plays on).
pub fn read_pc2(path: &Path, vertices: usize) -> Result<Vec<Vec<[f32; 3]>>> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let (header, frames) =
        exporters::pc2::read(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if header.points != vertices {
        bail!(
            "{}: {} points per frame, the garment has {vertices} vertices (a cache of another mesh?)",
            path.display(),
            header.points
        );
    }
    if frames.is_empty() {
        bail!("{}: no frames", path.display());
    }
    if let Some(f) = frames
        .iter()
        .position(|x| x.iter().flatten().any(|c| !c.is_finite()))
    {
        bail!("{}: frame {f} has non-finite points", path.display());
    }
    Ok(frames)
}
