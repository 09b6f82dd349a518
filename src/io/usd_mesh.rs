//! Garment meshes from USD (.usd, .usda, .usdc, .usdz), read by usd-core through python_bridge:
//! world space, converted to metres and Y-up, polygons fan-triangulated. UVs are not read.

use crate::geometry::TriMesh;
use anyhow::{bail, Result};
use std::path::Path;

/// Whether usd-core opens `path` (by extension).
pub fn is_usd(path: &Path) -> bool {
    exporters::FileKind::of(path) == Some(exporters::FileKind::Usd)
}

/// The stage's one Mesh prim as a triangle mesh (a garment file holds one garment).
#[cfg(feature = "usd")]
pub fn read_usd_mesh(path: &Path) -> Result<TriMesh> {
    use anyhow::Context;
    if !path.exists() {
        bail!("cannot read {}: no such file", path.display());
    }
    let meshes = python_bridge::read_usd_meshes(path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let mesh = match meshes.as_slice() {
        [one] => one,
        [] => bail!("{}: the stage has no Mesh prim", path.display()),
        many => bail!(
            "{}: the stage has {} Mesh prims ({}); a garment file must hold exactly one",
            path.display(),
            many.len(),
            many.iter()
                .map(|m| m.path.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    TriMesh::from_polygons(mesh.points.clone(), &mesh.face_counts, &mesh.face_indices)
        .with_context(|| format!("{}: Mesh {}", path.display(), mesh.path))
}

#[cfg(not(feature = "usd"))]
pub fn read_usd_mesh(path: &Path) -> Result<TriMesh> {
    bail!(
        "{}: this garmentbake was built without USD support (feature `usd`); convert the garment to OBJ",
        path.display()
    )
}
