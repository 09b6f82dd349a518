//! The model file: one `.safetensors` with the weights (MLP, PSD basis `D`, blend weights `W`)
//! and the arrays needed to use the model without the training inputs (rest garment, the
//! proximity skin for the LBS baseline, the body mesh and skin for collision metrics), plus a
//! `__metadata__` entry `garmentbake` holding the JSON description: skeleton (names, parents,
//! rest transforms, inverse binds), garment topology (faces, UVs) and a hash of its rest
//! positions, fabric, training settings and metric history.
//!
//! Deterministic bytes: safetensors sorts tensors by name, the metadata is one key (a
//! `HashMap` with several would serialise in random order) and the JSON has sorted keys and no
//! timestamps or absolute paths. Checkpoints are the same format plus the Adam state.

use super::pbns::{flat, Pbns, PbnsShape};
use crate::eval::Metrics;
use crate::geometry::{FaceVaryingUv, TriMesh};
use crate::io::gltf_body::Body;
use crate::rig::{JointTransform, Skeleton, Skin};
use crate::train::fabric::Fabric;
use anyhow::{bail, Context, Result};
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3};
use safetensors::{tensor::TensorView, Dtype, SafeTensors, View};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::collections::HashMap;
use std::path::Path;
use tch::{Device, Kind, Tensor};

pub const FORMAT: &str = "garmentbake.pbns";
pub const VERSION: u32 = 1;
/// The one `__metadata__` key.
pub const METADATA_KEY: &str = "garmentbake";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    pub format: String,
    pub version: u32,
    pub shape: PbnsShape,
    pub skeleton: SkeletonInfo,
    pub garment: GarmentInfo,
    pub body: BodyInfo,
    pub fabric: Fabric,
    pub training: TrainingInfo,
    pub history: Vec<EpochRecord>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SkeletonInfo {
    pub joint_names: Vec<String>,
    pub parents: Vec<Option<usize>>,
    pub rest_translations: Vec<[f32; 3]>,
    /// Quaternions `[x, y, z, w]`.
    pub rest_rotations: Vec<[f32; 4]>,
    /// Column-major 4×4.
    pub inverse_bind_matrices: Vec<[f32; 16]>,
    /// Joints whose rotations feed the MLP (6 values each): those that move the garment.
    pub feature_joints: Vec<usize>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GarmentInfo {
    pub name: String,
    pub vertices: usize,
    pub faces: Vec<[u32; 3]>,
    pub uv: Option<UvInfo>,
    pub pinned: Vec<u32>,
    /// FNV-1a 64 of the rest positions (f32 little-endian), to recognise the garment.
    pub rest_hash: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UvInfo {
    pub coords: Vec<[f32; 2]>,
    pub triangles: Vec<[u32; 3]>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BodyInfo {
    pub name: String,
    pub vertices: usize,
    pub rest_hash: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingInfo {
    pub seed: u64,
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f64,
    pub train_weights: bool,
    /// Clip file names (no directories: the bytes must not depend on where files live).
    pub motions: Vec<String>,
    pub pose_threshold: f32,
    pub poses_train: usize,
    pub poses_validation: usize,
    /// Training poses made by recombining limb chains of real frames (part of `poses_train`).
    #[serde(default)]
    pub poses_recombined: usize,
    /// Initial weights were inpainted beyond this distance from the body (metres).
    pub inpaint_beyond: Option<f32>,
    /// Vertices whose initial weights were inpainted.
    pub inpainted: usize,
}

/// One epoch of the metric history.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    pub epoch: usize,
    pub loss: f64,
    /// Mean weighted loss terms: edge, bend, collision, gravity, pin.
    pub terms: [f64; 5],
    /// Training-step metrics (candidate nearest neighbours).
    pub train: Metrics,
    /// Exact metrics on the validation poses (every few epochs, and the last).
    pub validation: Option<Metrics>,
}

/// Everything a model file holds.
pub struct ModelFile {
    pub model: Pbns,
    pub info: ModelInfo,
    /// The proximity skin (the plain-LBS baseline and the model's starting point).
    pub lbs: Skin,
    pub garment: TriMesh,
    pub body: Body,
    /// Extra tensors (a checkpoint's optimizer state), by name.
    pub extra: Vec<(String, Tensor)>,
}

impl ModelFile {
    pub fn skeleton(&self) -> &Skeleton {
        &self.body.skeleton
    }
}

/// Writes `file` atomically (with `extra` tensors, e.g. optimizer state).
pub fn save(path: &Path, file: &ModelFile) -> Result<()> {
    let bytes = to_bytes(file)?;
    exporters::atomic::write_atomic(path, &bytes)?;
    Ok(())
}

pub fn to_bytes(file: &ModelFile) -> Result<Vec<u8>> {
    let m = &file.model;
    let mut blobs: Vec<(String, Blob)> = Vec::new();
    for (name, t) in m.parameters(true) {
        blobs.push((name, Blob::float(t)));
    }
    blobs.push(("W.joints".into(), Blob::int(&m.joints)));
    blobs.push(("W.weights".into(), Blob::float(&m.weights())));
    blobs.push(("garment.rest".into(), Blob::float(&m.template)));
    let k = file.lbs.influences;
    blobs.push(("lbs.joints".into(), Blob::ints(&file.lbs.joint_indices, k)));
    blobs.push((
        "lbs.weights".into(),
        Blob::floats(&file.lbs.joint_weights, k),
    ));
    let b = &file.body;
    blobs.push(("body.points".into(), Blob::points(&b.mesh.positions)));
    blobs.push(("body.normals".into(), Blob::points(&b.normals)));
    let tri: Vec<u32> = b.mesh.triangles.iter().flatten().copied().collect();
    blobs.push(("body.triangles".into(), Blob::ints(&tri, 3)));
    blobs.push((
        "body.joints".into(),
        Blob::ints(&b.skin.joint_indices, b.skin.influences),
    ));
    blobs.push((
        "body.weights".into(),
        Blob::floats(&b.skin.joint_weights, b.skin.influences),
    ));
    for (name, t) in &file.extra {
        blobs.push((name.clone(), Blob::float(t)));
    }
    let json = serde_json::to_string(&file.info)?;
    let meta = HashMap::from([(METADATA_KEY.to_string(), json)]);
    Ok(safetensors::serialize(blobs, Some(meta))?)
}

/// Reads only the description (for `inspect`).
/// A stored tensor's name, shape and type.
pub type TensorSummary = (String, Vec<usize>, String);

/// The description and the tensor list of a model file.
pub fn read_info(path: &Path) -> Result<(ModelInfo, Vec<TensorSummary>)> {
    let bytes = read_bytes(path)?;
    let st = parse(path, &bytes)?;
    let info = info_of(path, &bytes)?;
    let mut tensors: Vec<_> = st
        .tensors()
        .into_iter()
        .map(|(n, t)| (n, t.shape().to_vec(), format!("{:?}", t.dtype())))
        .collect();
    tensors.sort_by(|a, b| a.0.cmp(&b.0));
    Ok((info, tensors))
}

/// Loads a model file (or checkpoint) onto `device`.
pub fn load(path: &Path, device: Device) -> Result<ModelFile> {
    let bytes = read_bytes(path)?;
    let st = parse(path, &bytes)?;
    let info = info_of(path, &bytes)?;
    let fail = |what: String| anyhow::anyhow!("{}: {what}", path.display());
    let get = |name: &str| -> Result<TensorView> {
        st.tensor(name)
            .map_err(|_| fail(format!("missing tensor '{name}'")))
    };
    let shape = info.shape;
    let (n, k) = (shape.vertices, shape.influences);
    let mut mlp = Vec::new();
    for i in 0..shape.layers {
        let w = tensor(&get(&format!("mlp.{i}.weight"))?, device)?;
        let b = tensor(&get(&format!("mlp.{i}.bias"))?, device)?;
        mlp.push((w, b));
    }
    let expect = |t: Tensor, dims: &[usize], name: &str| -> Result<Tensor> {
        let want: Vec<i64> = dims.iter().map(|&d| d as i64).collect();
        if t.size() != want {
            return Err(fail(format!(
                "tensor '{name}' has shape {:?}, expected {want:?}",
                t.size()
            )));
        }
        Ok(t)
    };
    let joints = &info.skeleton.feature_joints;
    if shape.features != 6 * joints.len() || joints.iter().any(|&j| j >= shape.joints) {
        return Err(fail(format!(
            "{} MLP inputs do not match the {} feature joints",
            shape.features,
            joints.len()
        )));
    }
    let model = Pbns {
        shape,
        feature_joints: joints.clone(),
        mlp,
        psd: expect(tensor(&get("psd")?, device)?, &[shape.width, 3 * n], "psd")?,
        template: expect(
            tensor(&get("garment.rest")?, device)?,
            &[n, 3],
            "garment.rest",
        )?,
        joints: expect(
            tensor(&get("W.joints")?, device)?.to_kind(Kind::Int64),
            &[n, k],
            "W.joints",
        )?,
        logits: expect(tensor(&get("W.logits")?, device)?, &[n, k], "W.logits")?,
    };
    let lbs = skin_of(&get("lbs.joints")?, &get("lbs.weights")?)?;
    let skeleton = info
        .skeleton
        .to_skeleton()
        .map_err(|e| fail(e.to_string()))?;
    let body = Body {
        name: info.body.name.clone(),
        mesh: TriMesh::new(
            points(&get("body.points")?)?,
            triangles(&get("body.triangles")?)?,
        ),
        normals: points(&get("body.normals")?)?,
        skeleton,
        skin: skin_of(&get("body.joints")?, &get("body.weights")?)?,
    };
    let garment = TriMesh {
        positions: points(&get("garment.rest")?)?,
        triangles: info.garment.faces.clone(),
        uv: info.garment.uv.as_ref().map(|uv| FaceVaryingUv {
            coords: uv.coords.clone(),
            triangles: uv.triangles.clone(),
        }),
    };
    garment
        .validate()
        .map_err(|e| fail(format!("garment: {e}")))?;
    body.mesh
        .validate()
        .map_err(|e| fail(format!("body: {e}")))?;
    let known = |name: &str| {
        name.starts_with("mlp.")
            || name.starts_with("W.")
            || name.starts_with("lbs.")
            || name.starts_with("body.")
            || ["psd", "garment.rest"].contains(&name)
    };
    let mut extra = Vec::new();
    for name in st.names() {
        if !known(name) {
            extra.push((name.to_string(), tensor(&st.tensor(name)?, device)?));
        }
    }
    extra.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(ModelFile {
        model,
        info,
        lbs,
        garment,
        body,
        extra,
    })
}

fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("cannot read model {}", path.display()))
}

fn parse<'a>(path: &Path, bytes: &'a [u8]) -> Result<SafeTensors<'a>> {
    SafeTensors::deserialize(bytes)
        .map_err(|e| anyhow::anyhow!("{}: not a safetensors file ({e:?})", path.display()))
}

fn info_of(path: &Path, bytes: &[u8]) -> Result<ModelInfo> {
    let (_, meta) = SafeTensors::read_metadata(bytes)
        .map_err(|e| anyhow::anyhow!("{}: unreadable header ({e:?})", path.display()))?;
    let json = meta
        .metadata()
        .as_ref()
        .and_then(|m| m.get(METADATA_KEY))
        .ok_or_else(|| {
            anyhow::anyhow!(
                "{}: no '{METADATA_KEY}' metadata: not a garmentbake model",
                path.display()
            )
        })?;
    let info: ModelInfo = serde_json::from_str(json)
        .with_context(|| format!("{}: invalid model description", path.display()))?;
    if info.format != FORMAT || info.version != VERSION {
        bail!(
            "{}: model format {} v{}, this build reads {FORMAT} v{VERSION}",
            path.display(),
            info.format,
            info.version
        );
    }
    Ok(info)
}

/// A tensor's bytes for safetensors (little-endian, as the format requires).
struct Blob {
    dtype: Dtype,
    shape: Vec<usize>,
    data: Vec<u8>,
}

impl Blob {
    fn float(t: &Tensor) -> Blob {
        let shape = t.size().iter().map(|&d| d as usize).collect();
        let v: Vec<f32> = flat(t, Kind::Float);
        Blob {
            dtype: Dtype::F32,
            shape,
            data: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }

    fn int(t: &Tensor) -> Blob {
        let shape = t.size().iter().map(|&d| d as usize).collect();
        let v: Vec<i32> = flat(t, Kind::Int);
        Blob {
            dtype: Dtype::I32,
            shape,
            data: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }

    fn floats(v: &[f32], columns: usize) -> Blob {
        Blob {
            dtype: Dtype::F32,
            shape: vec![v.len() / columns, columns],
            data: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }

    fn ints<T: Copy + Into<u32>>(v: &[T], columns: usize) -> Blob {
        Blob {
            dtype: Dtype::I32,
            shape: vec![v.len() / columns, columns],
            data: v
                .iter()
                .flat_map(|&x| (x.into() as i32).to_le_bytes())
                .collect(),
        }
    }

    fn points(p: &[[f32; 3]]) -> Blob {
        let v: Vec<f32> = p.iter().flatten().copied().collect();
        Blob::floats(&v, 3)
    }
}

impl View for Blob {
    fn dtype(&self) -> Dtype {
        self.dtype
    }
    fn shape(&self) -> &[usize] {
        &self.shape
    }
    fn data(&self) -> Cow<'_, [u8]> {
        Cow::Borrowed(&self.data)
    }
    fn data_len(&self) -> usize {
        self.data.len()
    }
}

fn f32s(view: &TensorView) -> Result<Vec<f32>> {
    if view.dtype() != Dtype::F32 {
        bail!("expected F32 data, found {:?}", view.dtype());
    }
    Ok(view
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

fn i32s(view: &TensorView) -> Result<Vec<i32>> {
    if view.dtype() != Dtype::I32 {
        bail!("expected I32 data, found {:?}", view.dtype());
    }
    Ok(view
        .data()
        .chunks_exact(4)
        .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

fn tensor(view: &TensorView, device: Device) -> Result<Tensor> {
    let shape: Vec<i64> = view.shape().iter().map(|&d| d as i64).collect();
    let t = match view.dtype() {
        Dtype::F32 => Tensor::from_slice(&f32s(view)?),
        Dtype::I32 => Tensor::from_slice(&i32s(view)?),
        other => bail!("unsupported tensor type {other:?}"),
    };
    Ok(t.view(shape.as_slice()).to_device(device))
}

fn points(view: &TensorView) -> Result<Vec<[f32; 3]>> {
    Ok(f32s(view)?
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect())
}

fn triangles(view: &TensorView) -> Result<Vec<[u32; 3]>> {
    Ok(i32s(view)?
        .chunks_exact(3)
        .map(|c| [c[0] as u32, c[1] as u32, c[2] as u32])
        .collect())
}

fn skin_of(joints: &TensorView, weights: &TensorView) -> Result<Skin> {
    let influences = *joints.shape().get(1).unwrap_or(&1);
    Ok(Skin {
        influences,
        joint_indices: i32s(joints)?.iter().map(|&j| j as u16).collect(),
        joint_weights: f32s(weights)?,
    })
}

/// FNV-1a 64 of points as f32 little-endian bytes, in hex.
pub fn points_hash(points: &[[f32; 3]]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in points.iter().flatten().flat_map(|x| x.to_le_bytes()) {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{h:016x}")
}

impl SkeletonInfo {
    pub fn new(skeleton: &Skeleton, feature_joints: Vec<usize>) -> SkeletonInfo {
        // The same plain arrays the exporters get.
        let plain = crate::bake::skeleton_asset(skeleton);
        SkeletonInfo {
            joint_names: plain.joint_names,
            parents: plain.parents,
            rest_translations: plain.rest_translations,
            rest_rotations: plain.rest_rotations,
            inverse_bind_matrices: plain.inverse_bind_matrices,
            feature_joints,
        }
    }

    pub fn to_skeleton(&self) -> Result<Skeleton> {
        let rest = self
            .rest_translations
            .iter()
            .zip(&self.rest_rotations)
            .map(|(t, r)| JointTransform {
                translation: Vector3::from(*t),
                rotation: UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2])),
                scale: Vector3::repeat(1.0),
            })
            .collect();
        let ibm = self
            .inverse_bind_matrices
            .iter()
            .map(|m| Matrix4::from_column_slice(m))
            .collect();
        Ok(Skeleton::new(
            self.joint_names.clone(),
            self.parents.clone(),
            rest,
            ibm,
        )?)
    }
}

/// Fails unless `body` has the model's skeleton: same joints, parents, rest and binding.
pub fn check_skeleton(model: &Skeleton, body: &Skeleton, body_name: &str) -> Result<()> {
    let differs = |why: String| {
        anyhow::anyhow!("{body_name}: the body's skeleton differs from the model's ({why}); use the body the model was trained with")
    };
    if model.joint_count() != body.joint_count() {
        return Err(differs(format!(
            "{} joints, the model has {}",
            body.joint_count(),
            model.joint_count()
        )));
    }
    for j in 0..model.joint_count() {
        if model.joint_names[j] != body.joint_names[j] {
            return Err(differs(format!(
                "joint {j} is '{}', the model's is '{}'",
                body.joint_names[j], model.joint_names[j]
            )));
        }
        if model.parents[j] != body.parents[j] {
            return Err(differs(format!(
                "joint '{}' has another parent",
                body.joint_names[j]
            )));
        }
        let moved = (model.rest[j].translation - body.rest[j].translation).norm() > 1e-4
            || model.rest[j].rotation.angle_to(&body.rest[j].rotation) > 1e-3
            || (model.inverse_bind[j] - body.inverse_bind[j]).amax() > 1e-4;
        if moved {
            return Err(differs(format!(
                "joint '{}' has another rest transform or bind",
                body.joint_names[j]
            )));
        }
    }
    Ok(())
}
