//! Alembic (`.abc`, Ogawa) point caches through `python_bridge` and PyPI's `alembic3d`
//! (PyAlembic): the cache Unreal (Geometry Cache, ML Deformer), Houdini, Maya and Marvelous
//! Designer import, where PC2 / MDD are not read.
//!
//! One `Xform` + `PolyMesh` per cache, time-sampled positions and bounds at the cache's rate,
//! topology and face-varying UVs (when the mesh has them) once. Decisions are made here, as for
//! USD: names, the clockwise face order Alembic stores (its readers reverse it back), the bounds;
//! the embedded Python (`python_bridge/src/abc_writer.py`) maps plain buffers onto schemas.
//! Units metres, Y-up (Alembic's convention), said in the Xform's user properties.

use crate::asset::{extent, CacheSpace, PointCache};
use crate::atomic::replace_via;
use python_bridge::{BridgeError, Value};
use std::borrow::Cow;
use std::collections::HashSet;
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum AbcError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("cannot write {path}: {reason}")]
    Invalid { path: String, reason: String },
    #[error("cannot write {path}: {source}")]
    Bridge { path: String, source: BridgeError },
}

/// Writes `caches` (one shot: the same rate and frame count) to one archive, a mesh each.
pub fn write_point_caches(caches: &[PointCache], path: &Path) -> Result<(), AbcError> {
    write_point_caches_in(caches, path, CacheSpace::NATIVE)
}

/// [`write_point_caches`] of points in `space`: Alembic has no field for units or up axis, so
/// the Xforms' user properties say them (`units`, `upAxis`).
pub fn write_point_caches_in(
    caches: &[PointCache],
    path: &Path,
    space: CacheSpace,
) -> Result<(), AbcError> {
    let invalid = |reason: String| AbcError::Invalid {
        path: path.display().to_string(),
        reason,
    };
    caches
        .iter()
        .try_for_each(PointCache::check)
        .and_then(|()| PointCache::same_timeline(caches))
        .map_err(invalid)?;
    let spec = spec(caches, space);
    // Into a temporary sibling, renamed at the end: a failed export never leaves a half file.
    replace_via(path, |tmp| {
        python_bridge::write_alembic(&spec, tmp).map_err(|source| AbcError::Bridge {
            path: path.display().to_string(),
            source,
        })
    })
}

fn spec(caches: &[PointCache], space: CacheSpace) -> Value<'_> {
    let mut taken = HashSet::new();
    let meshes = caches
        .iter()
        .map(|c| {
            let extents: Vec<f32> = (0..c.frame_count())
                .flat_map(|f| extent(c.frame(f)).into_iter().flatten())
                .collect();
            // Alembic stores faces clockwise (seen from the front); readers reverse them.
            let faces: Vec<i32> = c
                .triangles
                .iter()
                .flat_map(|t| [t[0], t[2], t[1]])
                .map(|i| i as i32)
                .collect();
            Value::Dict(vec![
                ("name", unique(&c.name, &mut taken).into()),
                ("point_count", Value::Int(c.point_count as i64)),
                ("points", Value::F32(Cow::Owned(flat(&c.points)))),
                ("extents", Value::F32(Cow::Owned(extents))),
                ("face_indices", Value::I32(Cow::Owned(faces))),
                (
                    "uvs",
                    c.uvs
                        .as_ref()
                        .map_or(Value::None, |uv| Value::F32(Cow::Owned(flat(&uv.coords)))),
                ),
                // Each corner's UV, in the faces' (clockwise) corner order.
                (
                    "uv_indices",
                    c.uvs.as_ref().map_or(Value::None, |uv| {
                        Value::I32(Cow::Owned(
                            uv.triangles
                                .iter()
                                .flat_map(|t| [t[0], t[2], t[1]])
                                .map(|i| i as i32)
                                .collect(),
                        ))
                    }),
                ),
            ])
        })
        .collect();
    Value::Dict(vec![
        ("fps", Value::Float(caches[0].fps as f64)),
        ("start", Value::Int(caches[0].start as i64)),
        ("frames", Value::Int(caches[0].frame_count() as i64)),
        (
            "user_properties",
            Value::List(
                [("units", space.units()), ("upAxis", space.up_axis())]
                    .iter()
                    .map(|(k, v)| Value::List(vec![(*k).into(), (*v).into()]))
                    .collect(),
            ),
        ),
        ("meshes", Value::List(meshes)),
    ])
}

fn flat<const N: usize>(v: &[[f32; N]]) -> Vec<f32> {
    v.iter().flatten().copied().collect()
}

/// An Alembic object name: letters, digits and `_`, unique among its siblings.
fn unique(name: &str, taken: &mut HashSet<String>) -> String {
    let base = crate::usd::identifier(name);
    let mut candidate = base.clone();
    let mut k = 1;
    while !taken.insert(candidate.clone()) {
        k += 1;
        candidate = format!("{base}_{k}");
    }
    candidate
}
