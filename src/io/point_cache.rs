//! Point caches of our meshes: written through `exporters` (a mesh's frames in the format the
//! file's extension names) and read back (PC2), checked against the mesh they belong to.

use crate::geometry::Frames;
use anyhow::{bail, Context, Result};
use exporters::CacheSpace;
use std::path::Path;

/// Every frame of a PC2 file whose point count must be `vertices` (the mesh it plays on), from
/// its start frame, at `fps` (PC2 has no rate: the clip it belongs to has).
pub fn read_pc2(path: &Path, vertices: usize, fps: f32) -> Result<Frames> {
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
    // A start frame that is not a whole frame (another tool's sub-frame cache) counts from the
    // frame it falls in.
    let start = header.start_frame.max(0.0).floor() as usize;
    Ok(Frames::new(frames, fps).starting_at(start))
}

/// A per-frame point cache of `mesh`'s vertices, in the format the extension names.
pub fn write_cache(path: &Path, mesh: &crate::geometry::TriMesh, frames: &Frames) -> Result<()> {
    write_cache_in(path, mesh, frames, CacheSpace::NATIVE)
}

/// [`write_cache`] in the units and up axis of `space` (`--out-units`, `--out-up`).
pub fn write_cache_in(
    path: &Path,
    mesh: &crate::geometry::TriMesh,
    frames: &Frames,
    space: CacheSpace,
) -> Result<()> {
    let name = path
        .file_stem()
        .map_or("cache".into(), |s| s.to_string_lossy().into_owned());
    write_caches_in(path, &[(&name, mesh, frames)], space)
}

/// A named mesh and its frames, one entry of [`write_caches`].
pub type NamedFrames<'a> = (&'a str, &'a crate::geometry::TriMesh, &'a Frames);

/// Several meshes' frames of one shot (a garment and the body it moves on), each named, in one
/// file: a USD stage or Alembic archive (one mesh: any point-cache format, a VAT included).
pub fn write_caches(path: &Path, meshes: &[NamedFrames]) -> Result<()> {
    write_caches_in(path, meshes, CacheSpace::NATIVE)
}

/// [`write_caches`] in the units and up axis of `space`: the points are turned here, the file
/// records it where its format has a place (USD, Alembic, a VAT's sidecar; PC2 and MDD have none).
pub fn write_caches_in(path: &Path, meshes: &[NamedFrames], space: CacheSpace) -> Result<()> {
    let result = match (exporters::FileKind::written(path), meshes) {
        (Some(exporters::FileKind::Vat), [(_, mesh, frames)]) => {
            write_vat(path, mesh, frames, space).map(|_| ())
        }
        (Some(exporters::FileKind::Vat), _) => Err(exporters::ExportError::Unsupported {
            path: path.display().to_string(),
            what: "a VAT holds one mesh (write the body with --body-out)".into(),
        }
        .into()),
        _ => {
            let caches: Vec<exporters::PointCache> = meshes
                .iter()
                .map(|&(name, mesh, frames)| exporters::PointCache {
                    name: name.into(),
                    fps: frames.fps,
                    start: frames.start,
                    triangles: mesh.triangles.clone(),
                    uvs: mesh.uv.as_ref().map(|uv| exporters::asset::CacheUvs {
                        coords: uv.coords.clone(),
                        triangles: uv.triangles.clone(),
                    }),
                    point_count: mesh.vertex_count(),
                    points: frames.iter().flatten().map(|&p| space.point(p)).collect(),
                })
                .collect();
            match caches.as_slice() {
                [one] => exporters::write_point_cache_in(one, path, space),
                all => exporters::write_point_caches_in(all, path, space),
            }
            .map_err(anyhow::Error::from)
        }
    };
    result.with_context(|| format!("writing {}", path.display()))
}

/// The vertex animation textures of `mesh`'s `frames` (`NAME.vat.exr` / `NAME.vat.png` and their
/// normals, sidecar and glb; `exporters::vat`): offsets from the mesh at rest, normals of each
/// frame from its welded faces, the glb split at UV seams with each copy on its vertex's column.
pub fn write_vat(
    path: &Path,
    mesh: &crate::geometry::TriMesh,
    frames: &Frames,
    space: CacheSpace,
) -> Result<exporters::vat::Sidecar> {
    use crate::geometry::normals::vertex_normals;
    let fps = frames.fps;
    let n = mesh.vertex_count();
    if let Some(f) = frames.iter().position(|f| f.len() != n) {
        bail!("frame {f} has {} points, the mesh {n}", frames[f].len());
    }
    let rest: Vec<[f32; 3]> = mesh.positions.iter().map(|&p| space.point(p)).collect();
    let points: Vec<[f32; 3]> = frames.iter().flatten().map(|&p| space.point(p)).collect();
    // Normals of the turned points: a rotation keeps them, a scale does not change unit normals.
    let normals: Vec<[f32; 3]> = points
        .chunks(n.max(1))
        .flat_map(|frame| vertex_normals(frame, &mesh.triangles))
        .collect();
    let rest_normals = vertex_normals(&rest, &mesh.triangles);
    let (source_vertex, uvs, triangles) = mesh.split_by_uv();
    let pick = |v: &[[f32; 3]]| -> Vec<[f32; 3]> {
        source_vertex.iter().map(|&s| v[s as usize]).collect()
    };
    let glb_mesh = exporters::asset::Mesh {
        name: path
            .file_name()
            .map_or("garment".into(), |s| s.to_string_lossy().into_owned())
            .split('.')
            .next()
            .unwrap_or("garment")
            .to_string(),
        points: pick(&rest),
        normals: Some(pick(&rest_normals)),
        uvs: (!uvs.is_empty()).then_some(uvs),
        triangles,
        source_vertex,
        color: [0.8, 0.8, 0.8],
        ..Default::default()
    };
    let vat = exporters::vat::VertexAnimation {
        fps,
        rest: &rest,
        points: &points,
        normals: &normals,
        mesh: glb_mesh,
        units: space.units(),
        up: space.up_axis(),
    };
    exporters::vat::write(path, &vat).map_err(anyhow::Error::from)
}
