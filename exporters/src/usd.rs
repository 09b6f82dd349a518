//! USD writer (UsdSkel) through `python_bridge` and Pixar's usd-core.
//!
//! A [`BakedAsset`] becomes a `SkelRoot` holding a `Skeleton` (joint paths, bind and rest
//! transforms), one `SkelAnimation` per clip (translations, rotations, scales, time-sampled
//! `blendShapeWeights`; with several clips a variant set `clip` switches `skel:animationSource`),
//! and each mesh bound with `SkelBindingAPI` with one `BlendShape` prim per target. UsdSkel applies
//! blend shapes before skinning, so the file replays `LBS(T + Σ w_k D_k)` like the glTF.
//! A [`PointCache`] becomes a `Mesh` with time-sampled `points` and `extent`.
//!
//! Every decision and all arithmetic (names, matrices, sparsity, times) happen here in Rust; the
//! embedded Python (`python_bridge/src/usd_writer.py`) only maps plain buffers onto schemas.
//! `.usda` is text, `.usdc` binary (crate), `.usdz` a zip around a `.usdc`.

use crate::asset::{extent, unit_quat, BakedAsset, CacheSpace, Mesh, PointCache, SkelAnimation};
use crate::atomic::replace_via;
use nalgebra::{Matrix4, Quaternion, Translation3, UnitQuaternion};
use python_bridge::{BridgeError, Value};
use std::borrow::Cow;
use std::collections::HashSet;
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum UsdError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("cannot write {path}: {reason}")]
    Invalid { path: String, reason: String },
    #[error("cannot write {path}: {source}")]
    Bridge { path: String, source: BridgeError },
}

/// Rate of the stage's time codes when nothing is animated (USD's own default).
const STATIC_FPS: f64 = 24.0;

/// Writes a skinned asset to `.usda`, `.usdc` or `.usdz` (the extension picks the format).
pub fn write(asset: &BakedAsset, path: &Path) -> Result<(), UsdError> {
    check_extension(path)
        .and_then(|()| asset.check())
        .and_then(|()| skel_spec(asset, &root_name(path)))
        .map_err(invalid(path))
        .and_then(|spec| author("write_skel", &spec, path))
}

/// Writes point caches of one shot with `points` and `extent` sampled at every frame: one cache
/// is the stage's root `Mesh` (named after the file); several (a garment and the posed body) are
/// `Mesh` prims named after their caches under a root `Xform`, on one timeline.
pub fn write_point_caches(caches: &[PointCache], path: &Path) -> Result<(), UsdError> {
    write_point_caches_in(caches, path, CacheSpace::NATIVE)
}

/// [`write_point_caches`] of points in `space`: the stage's `metersPerUnit` and `upAxis` say it.
pub fn write_point_caches_in(
    caches: &[PointCache],
    path: &Path,
    space: CacheSpace,
) -> Result<(), UsdError> {
    check_extension(path)
        .and_then(|()| PointCache::same_timeline(caches))
        .and_then(|()| caches.iter().try_for_each(PointCache::check))
        .map_err(invalid(path))?;
    author(
        "write_point_cache",
        &point_caches_spec(caches, &root_name(path), space),
        path,
    )
}

/// A reason the input cannot be written to `path`, as the error.
fn invalid(path: &Path) -> impl Fn(String) -> UsdError + '_ {
    move |reason| UsdError::Invalid {
        path: path.display().to_string(),
        reason,
    }
}

/// usd-core picks the format from the extension: anything but a written USD extension is
/// refused before Python starts.
fn check_extension(path: &Path) -> Result<(), String> {
    match crate::FileKind::written(path) {
        Some(crate::FileKind::Usd) => Ok(()),
        _ => Err(format!(
            "a USD file must end in {}",
            crate::FileKind::extension_list(&[crate::FileKind::Usd], true)
        )),
    }
}

/// Runs the embedded writer into a temporary sibling (same extension, so usd-core picks the same
/// format), then renames it: a failed export never leaves a half-written file.
fn author(function: &str, spec: &Value<'_>, path: &Path) -> Result<(), UsdError> {
    replace_via(path, |tmp| {
        python_bridge::write_usd(function, spec, tmp).map_err(|source| UsdError::Bridge {
            path: path.display().to_string(),
            source,
        })
    })
}

/// The `defaultPrim` is named after the file (`skirt.usdc` → `/skirt`): readable when the file is
/// referenced into a bigger scene.
fn root_name(path: &Path) -> String {
    identifier(&path.file_stem().unwrap_or_default().to_string_lossy())
}

/// A valid USD prim name: letters, digits and `_`, not starting with a digit.
pub fn identifier(name: &str) -> String {
    let mut out: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if !out.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
        out.insert(0, '_');
    }
    out
}

/// `identifier(name)`, made unique against `taken` by a numeric suffix (deterministic: first come,
/// first served).
fn unique(name: &str, taken: &mut HashSet<String>) -> String {
    let base = identifier(name);
    let mut candidate = base.clone();
    let mut k = 1;
    while !taken.insert(candidate.clone()) {
        k += 1;
        candidate = format!("{base}_{k}");
    }
    candidate
}

fn f32s<const N: usize>(v: &[[f32; N]]) -> Value<'_> {
    Value::F32(Cow::Borrowed(v.as_flattened()))
}

fn i32s(v: impl Iterator<Item = i32>) -> Value<'static> {
    Value::I32(Cow::Owned(v.collect()))
}

fn strings(v: impl IntoIterator<Item = String>) -> Value<'static> {
    Value::List(v.into_iter().map(Value::from).collect())
}

fn triangles(t: &[[u32; 3]]) -> Value<'static> {
    // `check` bounds every index by the vertex count, which is far below i32::MAX.
    i32s(t.iter().flatten().map(|&i| i as i32))
}

fn color(c: [f32; 3]) -> Value<'static> {
    Value::List(c.iter().map(|&x| Value::Float(x as f64)).collect())
}

fn provenance(p: &[(String, String)]) -> Value<'_> {
    Value::List(
        p.iter()
            .map(|(k, v)| Value::List(vec![k.as_str().into(), v.as_str().into()]))
            .collect(),
    )
}

/// Column-major f32 → f64 matrix.
fn matrix(m: &[f32; 16]) -> Matrix4<f64> {
    Matrix4::from_column_slice(m).cast()
}

/// USD matrices are row-major for row vectors (`p' = p M`), i.e. the transpose of our column-vector
/// matrices; the transpose stored row-major is exactly the column-major storage, so no shuffling.
fn usd_matrices(ms: impl Iterator<Item = Matrix4<f64>>) -> Value<'static> {
    Value::F64(Cow::Owned(ms.flat_map(|m| m.as_slice().to_vec()).collect()))
}

fn skel_spec<'a>(asset: &'a BakedAsset, root: &str) -> Result<Value<'a>, String> {
    let sk = &asset.skeleton;
    // Joint paths ("Hips/Spine/Chest"): UsdSkel's topology; names unique among siblings.
    let mut paths: Vec<String> = Vec::with_capacity(sk.joint_count());
    let mut siblings: Vec<HashSet<String>> = vec![HashSet::new(); sk.joint_count() + 1];
    for (j, name) in sk.joint_names.iter().enumerate() {
        let parent = sk.parents[j];
        let leaf = unique(name, &mut siblings[parent.map_or(0, |p| p + 1)]);
        paths.push(match parent {
            Some(p) => format!("{}/{leaf}", paths[p]),
            None => leaf,
        });
    }
    // bindTransforms are joint → world at bind time, the inverse of glTF's inverse bind matrices;
    // inverted in f64 so the round trip stays far below the 0.5 mm budget.
    let mut bind = Vec::with_capacity(sk.joint_count());
    for (j, ibm) in sk.inverse_bind_matrices.iter().enumerate() {
        bind.push(matrix(ibm).try_inverse().ok_or_else(|| {
            format!(
                "joint '{}': the inverse bind matrix is singular",
                sk.joint_names[j]
            )
        })?);
    }
    let rest = sk
        .rest_translations
        .iter()
        .zip(&sk.rest_rotations)
        .map(|(t, q)| trs(*t, *q));

    let mut top = HashSet::from(["Skeleton".to_string(), "Animations".to_string()]);
    // Blend-shape channel names are shared by a mesh's skel:blendShapes and the SkelAnimation's
    // blendShapes, so they must be unique across the asset, not only within one mesh.
    let mut channel_names = HashSet::new();
    let channels: Vec<Vec<String>> = asset
        .meshes
        .iter()
        .map(|m| {
            m.blend_shapes
                .iter()
                .map(|b| unique(&b.name, &mut channel_names))
                .collect()
        })
        .collect();
    let meshes = asset
        .meshes
        .iter()
        .zip(&channels)
        .map(|(m, ch)| mesh_spec(m, &unique(&m.name, &mut top), ch))
        .collect();
    let mut clip_names = HashSet::new();
    let animations: Vec<Value> = asset
        .animations
        .iter()
        .map(|a| animation_spec(a, &unique(&a.name, &mut clip_names), &channels, asset))
        .collect();

    let fps = asset
        .animations
        .first()
        .map_or(STATIC_FPS, |a| a.fps as f64);
    let end = asset
        .animations
        .iter()
        .map(|a| time_code(a.frame_count - 1, a, fps))
        .fold(0.0, f64::max);
    Ok(Value::Dict(vec![
        ("root", root.to_string().into()),
        ("fps", Value::Float(fps)),
        ("start", Value::Float(0.0)),
        ("end", Value::Float(end)),
        ("provenance", provenance(&asset.provenance)),
        (
            "skeleton",
            Value::Dict(vec![
                ("prim", "Skeleton".into()),
                ("joints", strings(paths)),
                ("joint_names", strings(sk.joint_names.iter().cloned())),
                ("bind", usd_matrices(bind.into_iter())),
                ("rest", usd_matrices(rest)),
            ]),
        ),
        ("meshes", Value::List(meshes)),
        ("animations_scope", "Animations".into()),
        ("animations", Value::List(animations)),
    ]))
}

fn trs(t: [f32; 3], q: [f32; 4]) -> Matrix4<f64> {
    let [x, y, z, w] = q.map(|c| c as f64);
    let rotation = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
    let translation = Translation3::new(t[0] as f64, t[1] as f64, t[2] as f64);
    translation.to_homogeneous() * rotation.to_homogeneous()
}

/// Stage time code of a clip frame: frames are time codes when the clip runs at the stage rate.
fn time_code(frame: usize, anim: &SkelAnimation, stage_fps: f64) -> f64 {
    frame as f64 * stage_fps / anim.fps as f64
}

/// A blend shape stores `pointIndices` when that is smaller than the dense offsets: 4 bytes of
/// index per kept point against 12 (or 24 with normal offsets) bytes per dropped point.
fn sparse_points(shape: &crate::asset::BlendShape) -> Option<Vec<usize>> {
    let zero = |v: &[f32; 3]| *v == [0.0; 3];
    let kept: Vec<usize> = (0..shape.offsets.len())
        .filter(|&i| {
            !zero(&shape.offsets[i]) || shape.normal_offsets.as_ref().is_some_and(|n| !zero(&n[i]))
        })
        .collect();
    let per_point = if shape.normal_offsets.is_some() {
        24
    } else {
        12
    };
    let dense = shape.offsets.len() * per_point;
    (kept.len() * (per_point + 4) < dense).then_some(kept)
}

fn mesh_spec<'a>(mesh: &'a Mesh, prim: &str, channels: &[String]) -> Value<'a> {
    let skin = mesh.skin.as_ref().map_or(Value::None, |s| {
        Value::Dict(vec![
            ("influences", Value::Int(s.influences as i64)),
            ("indices", i32s(s.joint_indices.iter().map(|&j| j as i32))),
            ("weights", Value::F32(Cow::Borrowed(&s.joint_weights))),
        ])
    });
    let shapes = mesh
        .blend_shapes
        .iter()
        .zip(channels)
        .map(|(b, channel)| {
            let (offsets, normals, indices) = match sparse_points(b) {
                Some(kept) => {
                    let pick = |v: &[[f32; 3]]| {
                        Value::F32(Cow::Owned(kept.iter().flat_map(|&i| v[i]).collect()))
                    };
                    (
                        pick(&b.offsets),
                        b.normal_offsets.as_deref().map_or(Value::None, pick),
                        i32s(kept.iter().map(|&i| i as i32)),
                    )
                }
                None => (
                    f32s(&b.offsets),
                    b.normal_offsets.as_deref().map_or(Value::None, f32s),
                    Value::None,
                ),
            };
            Value::Dict(vec![
                ("prim", channel.clone().into()),
                ("channel", channel.clone().into()),
                ("offsets", offsets),
                ("normal_offsets", normals),
                ("point_indices", indices),
            ])
        })
        .collect();
    let [lo, hi] = extent(&mesh.points);
    Value::Dict(vec![
        ("prim", prim.to_string().into()),
        ("points", f32s(&mesh.points)),
        (
            "extent",
            Value::F32(Cow::Owned(lo.into_iter().chain(hi).collect())),
        ),
        ("normals", mesh.normals.as_deref().map_or(Value::None, f32s)),
        ("uvs", mesh.uvs.as_deref().map_or(Value::None, f32s)),
        ("face_indices", triangles(&mesh.triangles)),
        ("color", color(mesh.color)),
        ("skin", skin),
        ("blend_shapes", Value::List(shapes)),
    ])
}

fn animation_spec<'a>(
    anim: &'a SkelAnimation,
    prim: &str,
    channels: &[Vec<String>],
    asset: &BakedAsset,
) -> Value<'a> {
    let stage_fps = asset.animations[0].fps as f64;
    let times = (0..anim.frame_count)
        .map(|f| Value::Float(time_code(f, anim, stage_fps)))
        .collect();
    // One weight vector per frame over all animated meshes' channels, in the order listed.
    let names: Vec<String> = anim
        .blend_shape_weights
        .iter()
        .flat_map(|(m, _)| channels[*m].iter().cloned())
        .collect();
    let weights: Vec<f32> = (0..anim.frame_count)
        .flat_map(|f| {
            anim.blend_shape_weights.iter().flat_map(move |(m, w)| {
                let k = asset.meshes[*m].blend_shapes.len();
                w[f * k..(f + 1) * k].iter().copied()
            })
        })
        .collect();
    Value::Dict(vec![
        ("prim", prim.to_string().into()),
        ("times", Value::List(times)),
        ("translations", f32s(&anim.translations)),
        (
            "rotations",
            Value::F32(Cow::Owned(
                anim.rotations.iter().flat_map(|q| unit_quat(*q)).collect(),
            )),
        ),
        ("channels", strings(names)),
        ("weights", Value::F32(Cow::Owned(weights))),
    ])
}

fn point_caches_spec<'a>(caches: &'a [PointCache], root: &str, space: CacheSpace) -> Value<'a> {
    let frames = caches[0].frame_count();
    let start = caches[0].start;
    let mut taken = HashSet::from([root.to_string()]);
    let meshes = caches
        .iter()
        .map(|c| mesh_cache_spec(c, &unique(&c.name, &mut taken)))
        .collect();
    Value::Dict(vec![
        // One cache keeps its own name as the root (as a lone PC2's mesh would be named).
        (
            "root",
            match caches {
                [one] => identifier(&one.name).into(),
                _ => root.to_string().into(),
            },
        ),
        ("fps", Value::Float(caches[0].fps as f64)),
        ("start", Value::Float(start as f64)),
        (
            "end",
            Value::Float((start + frames).saturating_sub(1) as f64),
        ),
        ("meters_per_unit", Value::Float(space.meters_per_unit())),
        ("up_axis", space.up_axis().to_string().into()),
        ("provenance", Value::List(Vec::new())),
        (
            "times",
            Value::List(
                (start..start + frames)
                    .map(|f| Value::Float(f as f64))
                    .collect(),
            ),
        ),
        ("meshes", Value::List(meshes)),
    ])
}

fn mesh_cache_spec<'a>(cache: &'a PointCache, name: &str) -> Value<'a> {
    let extents: Vec<f32> = (0..cache.frame_count())
        .flat_map(|f| extent(cache.frame(f)).into_iter().flatten())
        .collect();
    Value::Dict(vec![
        ("name", name.to_string().into()),
        ("point_count", Value::Int(cache.point_count as i64)),
        ("points", f32s(&cache.points)),
        ("extents", Value::F32(Cow::Owned(extents))),
        ("face_indices", triangles(&cache.triangles)),
        (
            "uvs",
            cache
                .uvs
                .as_ref()
                .map_or(Value::None, |uv| f32s(&uv.coords)),
        ),
        (
            "uv_indices",
            cache
                .uvs
                .as_ref()
                .map_or(Value::None, |uv| triangles(&uv.triangles)),
        ),
        ("color", Value::None),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identifiers_are_valid_and_unique() {
        assert_eq!(identifier("131_01"), "_131_01");
        assert_eq!(identifier("left hand.001"), "left_hand_001");
        let mut taken = HashSet::new();
        assert_eq!(unique("a b", &mut taken), "a_b");
        assert_eq!(unique("a.b", &mut taken), "a_b_2");
    }

    #[test]
    fn sparse_indices_only_where_they_pay() {
        let mut shape = crate::asset::BlendShape {
            offsets: vec![[0.0; 3]; 10],
            ..Default::default()
        };
        shape.offsets[3] = [1.0, 0.0, 0.0];
        assert_eq!(sparse_points(&shape), Some(vec![3]));
        shape.offsets = vec![[1.0; 3]; 10];
        assert_eq!(sparse_points(&shape), None);
    }

    #[test]
    fn temp_name_keeps_the_extension_usd_core_reads() {
        assert_eq!(
            crate::atomic::temp_path_keeping_extension(Path::new("out/skirt.usdc")),
            Path::new("out/.skirt.partial.usdc")
        );
    }
}
