//! Point caches of our meshes: written through `exporters` (a mesh's frames in the format the
//! file's extension names) and read back (PC2), checked against the mesh they belong to.

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

/// A per-frame point cache of `mesh`'s vertices, in the format the extension names.
pub fn write_cache(
    path: &Path,
    mesh: &crate::geometry::TriMesh,
    frames: &[Vec<[f32; 3]>],
    fps: f32,
) -> Result<()> {
    let name = path
        .file_stem()
        .map_or("cache".into(), |s| s.to_string_lossy().into_owned());
    write_caches(path, &[(&name, mesh, frames)], fps)
}

/// A named mesh and its frames, one entry of [`write_caches`].
pub type NamedFrames<'a> = (&'a str, &'a crate::geometry::TriMesh, &'a [Vec<[f32; 3]>]);

/// Several meshes' frames of one shot (a garment and the body it moves on), each named, in one
/// file: a USD stage (one mesh: any point-cache format).
pub fn write_caches(path: &Path, meshes: &[NamedFrames], fps: f32) -> Result<()> {
    let caches: Vec<exporters::PointCache> = meshes
        .iter()
        .map(|&(name, mesh, frames)| exporters::PointCache {
            name: name.into(),
            fps,
            triangles: mesh.triangles.clone(),
            uvs: None,
            point_count: mesh.vertex_count(),
            points: frames.iter().flatten().copied().collect(),
        })
        .collect();
    match caches.as_slice() {
        [one] => exporters::write_point_cache(one, path),
        all => exporters::write_point_caches(all, path),
    }
    .with_context(|| format!("writing {}", path.display()))
}
