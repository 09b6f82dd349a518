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
//!
//! Versions: the description carries its format version. This build reads every version from
//! [`OLDEST`] on, bringing an older description up to date as it loads ([`migrate`]: one step per
//! version, each saying what changed), and `garmentbake upgrade` rewrites an older file in the
//! current version with its tensors byte for byte. A file newer than this build, or older than
//! [`OLDEST`], is refused with a message that says which. tests/fixtures/models/ keeps a file
//! written by the previous version, read by the tests.

use super::coverage::Coverage;
use super::dynamic::space::Consts;
use super::dynamic::{
    BodyAnchors, Dynamic, MotionEncoder, MotionShape, Space, SpaceShape, UvRaster,
};
use super::pbns::{flat, Pbns, PbnsShape};
use super::swing::{Modes, Swing, SwingIntegrator, SwingShape};
use super::{Model, ModelKind};
use crate::body::Body;
use crate::fabric::Fabric;
use crate::geometry::{FaceVaryingUv, TriMesh};
use crate::metrics::Metrics;
use crate::rig::{PlainSkeleton, Skeleton, Skin};
use anyhow::{bail, Context, Result};
use safetensors::{tensor::TensorView, Dtype, SafeTensors, View};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::collections::HashMap;
use std::path::Path;
use tch::{Device, Kind, Tensor};

/// One format for every model kind; the kind is in the metadata (`model.kind`).
pub const FORMAT: &str = "garmentbake.model";
/// The version written. v3: the description names the build that trained the model
/// (`written_by`).
pub const VERSION: u32 = 3;
/// The oldest version read (v2: PBNS and dynamic models in one format, the kind in `model.kind`).
pub const OLDEST: u32 = 2;
/// The one `__metadata__` key.
pub const METADATA_KEY: &str = "garmentbake";

/// The description every model file carries, whatever its kind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    pub format: String,
    /// The file's version as read (an older file keeps its number until rewritten); files are
    /// always written in [`VERSION`].
    pub version: u32,
    /// The build that last wrote the model's weights; none in a file from before v3 (unknown).
    pub written_by: Option<WrittenBy>,
    pub skeleton: PlainSkeleton,
    pub garment: GarmentInfo,
    pub body: BodyInfo,
    pub fabric: Fabric,
    /// The model kind (`"kind"`) and what only that kind describes.
    pub model: KindInfo,
}

/// A garmentbake build: its package version (for people) and [`crate::build_id`] (exact).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WrittenBy {
    pub version: String,
    pub build: String,
}

impl WrittenBy {
    /// This build.
    pub fn this() -> WrittenBy {
        WrittenBy {
            version: env!("CARGO_PKG_VERSION").into(),
            build: crate::build_id::id().into(),
        }
    }
}

/// What a model kind adds to the description; the tag chooses how the tensors are read.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
// One description per model file: the PBNS variant's inline size costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
pub enum KindInfo {
    Pbns(PbnsInfo),
    /// Boxed: its anchors, ranges and two histories make it far larger than PBNS's description.
    Dynamic(Box<DynamicInfo>),
}

impl KindInfo {
    pub fn kind(&self) -> ModelKind {
        match self {
            KindInfo::Pbns(_) => ModelKind::Pbns,
            KindInfo::Dynamic(_) => ModelKind::Dynamic,
        }
    }
}

/// A dynamic model's sizes, anchors, training and history (stage 1: the generative space).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DynamicInfo {
    pub shape: SpaceShape,
    /// Body vertices used as anchor points, and each one's part (index into `parts`).
    /// (Keys `seeds` and `seed_parts` in the model file.)
    #[serde(rename = "seeds")]
    pub anchors: Vec<u32>,
    #[serde(rename = "seed_parts")]
    pub anchor_parts: Vec<usize>,
    pub parts: Vec<String>,
    /// Learnt kernel radius per part (metres), for reading; the tensor is authoritative.
    pub radii: Vec<f64>,
    /// The frame rate of the simulations it learnt from.
    pub fps: f32,
    pub training: DynamicTraining,
    pub history: Vec<DynamicEpoch>,
    /// Stage 2, once trained: the motion encoder's sizes and its training.
    #[serde(default)]
    pub motion: Option<MotionInfo>,
}

/// The dynamic-aware encoder's sizes, training settings and per-epoch history.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MotionInfo {
    pub shape: MotionShape,
    pub seed: u64,
    pub batch: usize,
    pub learning_rate: f64,
    /// Clip file names and their frame counts.
    pub motions: Vec<String>,
    pub frames: usize,
    /// Ridge pull of the fitted linear path towards keeping the previous latent.
    pub ridge: f64,
    /// Ridge penalty on the body drive's weights (relative to each drive column's square).
    #[serde(default)]
    pub drive_ridge: f64,
    /// Per latent dimension, the range of the training frames' latents widened by a tenth on
    /// each side: roll-outs are held inside it (a garment the space never saw is not one it
    /// can decode plausibly).
    pub latent_min: Vec<f32>,
    pub latent_max: Vec<f32>,
    pub history: Vec<MotionEpoch>,
    /// The roll-out-aware fit's rounds (`train-dynamic --rollout-rounds`).
    #[serde(default)]
    pub rollout_rounds: Vec<RolloutRound>,
    /// Settling towards the pose's garment (`train-dynamic --pose-settle`); none: the
    /// integrator alone (models from before it, `--no-pose-settle`).
    #[serde(default)]
    pub settle: Option<Settled>,
    /// The learnt latent dynamics' fit through roll-outs (`train-dynamic --dynamics-epochs`);
    /// none: the linear path alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dynamics: Option<crate::models::dynamic::learned::DynamicsFit>,
}

/// How a motion encoder was settled towards the pose (`models::dynamic::settle`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Settled {
    /// A deviation from the pose's garment fades to 1/e in this time (s).
    pub seconds: f64,
    /// The pose regression's relative ridge, chosen by leave-one-clip-out error.
    pub pose_ridge: f64,
    /// How much of the latents' spread the pose regression explains on training clips left
    /// out of its fit (%; models from before it: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_explained_pct: Option<f64>,
}

impl Settled {
    /// In a few words, as `inspect` prints it.
    pub fn summary(&self) -> String {
        format!(
            "settled towards the pose in {} s (pose ridge {}{})",
            self.seconds,
            self.pose_ridge,
            self.pose_explained_pct
                .map_or(String::new(), |p| format!(", explaining {p:.1} % left out"))
        )
    }
}

/// One round of the roll-out-aware fit: the regression's rows after it and the mean vertex
/// error of the round's roll-outs of the training clips (before its refit).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RolloutRound {
    pub round: usize,
    pub rows: usize,
    pub train_rollout_mean_mm: f64,
}

/// The dynamic stage's loss terms (mean over an epoch's steps): `L_geo` and `L_Z` for the frame
/// and the virtual sample `E_t = 0`, and `λ2·L_reg`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MotionTerms {
    pub geometry: f64,
    pub virtual_geometry: f64,
    pub latent: f64,
    pub virtual_latent: f64,
    pub regulariser: f64,
}

impl MotionTerms {
    pub fn total(&self) -> f64 {
        self.geometry + self.virtual_geometry + self.latent + self.virtual_latent + self.regulariser
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MotionEpoch {
    pub epoch: usize,
    pub loss: f64,
    pub terms: MotionTerms,
    pub learning_rate: f64,
    /// Mean vertex distance (mm) of the one-step predictions of the epoch's training frames.
    pub train_mean_mm: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DynamicTraining {
    /// The stages trained so far ("space").
    pub stages: Vec<String>,
    pub seed: u64,
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f64,
    /// Clip file names and their frame counts.
    pub motions: Vec<String>,
    pub frames: usize,
}

/// The generative space's loss terms, weighted (mean over an epoch's steps).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SpaceTerms {
    pub positions: f64,
    pub laplacian: f64,
    pub random_edges: f64,
    pub sdf: f64,
    pub latent: f64,
}

impl SpaceTerms {
    pub fn total(&self) -> f64 {
        self.positions + self.laplacian + self.random_edges + self.sdf + self.latent
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DynamicEpoch {
    pub epoch: usize,
    pub loss: f64,
    pub terms: SpaceTerms,
    pub learning_rate: f64,
    /// Mean vertex distance (mm) of the reconstructions of the epoch's training frames.
    pub train_mean_mm: f64,
}

/// A PBNS model's sizes, inputs, training settings and metric history.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PbnsInfo {
    pub shape: PbnsShape,
    /// Joints whose rotations feed the MLP (6 values each): those that move the garment.
    pub feature_joints: Vec<usize>,
    pub training: TrainingInfo,
    pub history: Vec<EpochRecord>,
    /// The swing learnt on top (`train-swing`), when there is one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub swing: Option<SwingInfo>,
}

/// A swing's sizes, training settings and per-epoch history.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SwingInfo {
    pub shape: SwingShape,
    pub training: SwingTraining,
    pub history: Vec<SwingEpoch>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SwingTraining {
    pub seed: u64,
    pub epochs: usize,
    /// Sequences per step and frames unrolled in each.
    pub batch: usize,
    pub unroll: usize,
    pub learning_rate: f64,
    /// Weight of the inertia term (1: the physical `Σ m/(2Δt²)|x_t − 2x_{t−1} + x_{t−2}|²`).
    pub inertia: f32,
    /// Clip file names and their frames at the swing's rate.
    pub motions: Vec<String>,
    pub frames: usize,
}

/// One epoch of a swing's training (means over its steps).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SwingEpoch {
    pub epoch: usize,
    pub loss: f64,
    pub terms: LossTerms,
    pub inertia: f64,
    /// Fraction of garment vertices nearer than the margin inside the body (candidate proxy).
    pub collided: f64,
    /// RMS of the swing's displacement over the training frames (mm), after the epoch.
    pub swing_rms_mm: f64,
    pub seconds: f64,
}

impl GarmentInfo {
    pub fn of(garment: &crate::garment::Garment, pinned: &[u32]) -> GarmentInfo {
        let rest = &garment.mesh.positions;
        GarmentInfo {
            name: garment.name.clone(),
            vertices: rest.len(),
            faces: garment.mesh.triangles.clone(),
            uv: garment.mesh.uv.as_ref().map(|uv| UvInfo {
                coords: uv.coords.clone(),
                triangles: uv.triangles.clone(),
            }),
            pinned: pinned.to_vec(),
            rest_hash: points_hash(rest),
        }
    }
}

impl BodyInfo {
    pub fn of(body: &Body) -> BodyInfo {
        BodyInfo {
            name: body.name.clone(),
            vertices: body.mesh().vertex_count(),
            rest_hash: points_hash(&body.mesh().positions),
        }
    }
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
    /// The balancing threshold (radians; see [`crate::models::coverage`]).
    pub pose_threshold: f32,
    /// The pose budget, recorded only when it thinned the balanced poses (files of fewer clips
    /// keep their bytes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_budget: Option<usize>,
    /// Frames at least this far from every training pose are beyond the trained range: the
    /// 95th percentile of the training clips' held-out distances (`train::poses::
    /// held_out_threshold`). Older files lack it and use `pose_threshold`.
    #[serde(default)]
    pub coverage_threshold: Option<f32>,
    pub poses_train: usize,
    pub poses_validation: usize,
    /// Training poses made by recombining limb chains of real frames (part of `poses_train`).
    #[serde(default)]
    pub poses_recombined: usize,
    /// Training poses whose garment joints were drawn across their widened ranges (part of
    /// `poses_train`).
    #[serde(default)]
    pub poses_sampled: usize,
    /// Initial weights were inpainted beyond this distance from the body (metres).
    pub inpaint_beyond: Option<f32>,
    /// Vertices whose initial weights were inpainted.
    pub inpainted: usize,
    /// With `--patience`: stop after this many epochs without a lower validation loss, and
    /// write the weights of the best validated epoch.
    #[serde(default)]
    pub patience: Option<usize>,
    /// The epoch whose weights the model holds when `--patience` kept the best one.
    #[serde(default)]
    pub best_epoch: Option<usize>,
}

impl TrainingInfo {
    /// The pose distance from which a frame is beyond the trained range.
    pub fn beyond_range(&self) -> f32 {
        self.coverage_threshold.unwrap_or(self.pose_threshold)
    }
}

/// The PBNS potential's weighted terms (mean over an epoch's steps).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LossTerms {
    pub edge: f64,
    pub bend: f64,
    pub collision: f64,
    pub gravity: f64,
    pub pin: f64,
}

impl LossTerms {
    pub fn total(&self) -> f64 {
        self.edge + self.bend + self.collision + self.gravity + self.pin
    }
}

/// One epoch of the metric history.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    pub epoch: usize,
    pub loss: f64,
    pub terms: LossTerms,
    /// Training-step metrics (candidate nearest neighbours).
    pub train: Metrics,
    /// Exact metrics on the validation poses (every few epochs, and the last).
    pub validation: Option<Metrics>,
    /// The training potential (the same weighted terms as `loss`) on the validation poses, with
    /// exact nearest body vertices: what `--patience` watches. Validated epochs only.
    #[serde(default)]
    pub validation_loss: Option<f64>,
}

/// Everything a model file holds.
pub struct ModelFile {
    pub model: Model,
    pub info: ModelInfo,
    /// The proximity skin (the plain-LBS baseline and the model's starting point).
    pub lbs: Skin,
    pub garment: TriMesh,
    pub body: Body,
    /// Extra tensors (a checkpoint's optimizer state), by name.
    pub extra: Vec<(String, Tensor)>,
    /// The training poses and blend-shape weight ranges (PBNS models trained since the
    /// coverage report; `None` in older files and dynamic models).
    pub coverage: Option<Coverage>,
}

impl ModelFile {
    pub fn skeleton(&self) -> &Skeleton {
        &self.body.skeleton
    }

    /// The PBNS network, or an error saying which kind the file holds instead.
    pub fn pbns(&self) -> Result<&Pbns> {
        match &self.model {
            Model::Pbns(m) => Ok(m),
            Model::Dynamic(_) => Err(not_kind("PBNS", "dynamic")),
        }
    }

    /// The dynamic model, or an error saying which kind the file holds.
    pub fn dynamic(&self) -> Result<&Dynamic> {
        match &self.model {
            Model::Dynamic(m) => Ok(m),
            Model::Pbns(_) => Err(not_kind("dynamic", "PBNS")),
        }
    }
}

impl ModelInfo {
    /// The PBNS description, or an error saying which kind the file holds instead.
    pub fn pbns(&self) -> Result<&PbnsInfo> {
        match &self.model {
            KindInfo::Pbns(p) => Ok(p),
            KindInfo::Dynamic(_) => Err(not_kind("PBNS", "dynamic")),
        }
    }

    pub fn dynamic(&self) -> Result<&DynamicInfo> {
        match &self.model {
            KindInfo::Dynamic(d) => Ok(d),
            KindInfo::Pbns(_) => Err(not_kind("dynamic", "PBNS")),
        }
    }
}

fn not_kind(wanted: &str, found: &str) -> anyhow::Error {
    anyhow::anyhow!("this is a {found} model; the command needs a {wanted} model (garmentbake inspect shows a file's kind)")
}

/// Writes `file` atomically (with `extra` tensors, e.g. optimizer state).
pub fn save(path: &Path, file: &ModelFile) -> Result<()> {
    let bytes = to_bytes(file)?;
    exporters::atomic::write_atomic(path, &bytes)?;
    Ok(())
}

pub fn to_bytes(file: &ModelFile) -> Result<Vec<u8>> {
    let mut blobs: Vec<(String, Blob)> = match &file.model {
        Model::Pbns(m) => pbns_blobs(m),
        Model::Dynamic(m) => m
            .space
            .parameters()
            .into_iter()
            .map(|(name, t)| (format!("space.{name}"), Blob::float(&t)))
            .chain(
                m.motion
                    .iter()
                    .flat_map(|e| e.parameters())
                    .map(|(name, t)| (name, Blob::float(&t))),
            )
            .collect(),
    };
    blobs.push(("garment.rest".into(), Blob::points(&file.garment.positions)));
    let k = file.lbs.influences;
    blobs.push(("lbs.joints".into(), Blob::ints(&file.lbs.joint_indices, k)));
    blobs.push((
        "lbs.weights".into(),
        Blob::floats(&file.lbs.joint_weights, k),
    ));
    let b = &file.body;
    blobs.push(("body.points".into(), Blob::points(&b.mesh().positions)));
    blobs.push(("body.normals".into(), Blob::points(&b.normals)));
    let tri: Vec<u32> = b.mesh().triangles.iter().flatten().copied().collect();
    blobs.push(("body.triangles".into(), Blob::ints(&tri, 3)));
    blobs.push((
        "body.joints".into(),
        Blob::ints(&b.skin.joint_indices, b.skin.influences),
    ));
    blobs.push((
        "body.weights".into(),
        Blob::floats(&b.skin.joint_weights, b.skin.influences),
    ));
    if let Some(c) = &file.coverage {
        blobs.extend(coverage_blobs(c));
    }
    for (name, t) in &file.extra {
        blobs.push((name.clone(), Blob::float(t)));
    }
    let info = ModelInfo {
        version: VERSION,
        written_by: Some(WrittenBy::this()),
        ..file.info.clone()
    };
    Ok(safetensors::serialize(blobs, Some(metadata(&info)?))?)
}

/// The one `__metadata__` entry holding `info`.
fn metadata(info: &ModelInfo) -> Result<HashMap<String, String>> {
    Ok(HashMap::from([(
        METADATA_KEY.to_string(),
        serde_json::to_string(info)?,
    )]))
}

/// What [`upgrade`] did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Upgraded {
    pub from_version: u32,
    pub to_version: u32,
    /// False when the file already was in the current version (then nothing is written).
    pub rewritten: bool,
    pub tensors: usize,
    pub bytes: u64,
}

/// Rewrites the model file (or checkpoint) `path` in the current version at `out` (atomically;
/// may be `path`): the description migrated, every tensor byte for byte, `written_by` kept (a
/// file from before v3 still does not say which build trained it).
pub fn upgrade(path: &Path, out: &Path) -> Result<Upgraded> {
    let bytes = read_bytes(path)?;
    let st = parse(path, &bytes)?;
    let info = info_of(path, &bytes)?;
    let from_version = info.version;
    let tensors = st.len();
    if from_version == VERSION && out == path {
        return Ok(Upgraded {
            from_version,
            to_version: VERSION,
            rewritten: false,
            tensors,
            bytes: bytes.len() as u64,
        });
    }
    let info = ModelInfo {
        version: VERSION,
        ..info
    };
    let upgraded = safetensors::serialize(st.tensors(), Some(metadata(&info)?))
        .map_err(|e| anyhow::anyhow!("{}: cannot rewrite ({e:?})", path.display()))?;
    exporters::atomic::write_atomic(out, &upgraded)?;
    Ok(Upgraded {
        from_version,
        to_version: VERSION,
        rewritten: true,
        tensors,
        bytes: upgraded.len() as u64,
    })
}

/// The PBNS network's tensors: MLP, PSD basis, the sparse skin's slots and weights.
fn pbns_blobs(m: &Pbns) -> Vec<(String, Blob)> {
    let mut blobs: Vec<(String, Blob)> = m
        .parameters(true)
        .into_iter()
        .chain(m.swing.iter().flat_map(|s| s.tensors()))
        .map(|(name, t)| (name, Blob::float(t)))
        .collect();
    blobs.push(("W.joints".into(), Blob::int(&m.joints)));
    blobs.push(("W.weights".into(), Blob::float(&m.weights())));
    blobs
}

/// Coverage tensors: the training poses' keys `[P, J·3]` and the weight range `[2, K]`.
fn coverage_blobs(c: &Coverage) -> Vec<(String, Blob)> {
    let joints = c.poses.first().map_or(0, Vec::len);
    let keys: Vec<f32> = c
        .poses
        .iter()
        .flat_map(|p| p.iter().flat_map(|v| [v.x, v.y, v.z]))
        .collect();
    let range: Vec<f32> = [c.weight_min.as_slice(), c.weight_max.as_slice()].concat();
    vec![
        (
            COVERAGE_POSES.into(),
            Blob::floats(&keys, 3 * joints.max(1)),
        ),
        (
            COVERAGE_WEIGHTS.into(),
            Blob::floats(&range, c.weight_min.len().max(1)),
        ),
    ]
}

const COVERAGE_POSES: &str = "coverage.poses";
const COVERAGE_WEIGHTS: &str = "coverage.weight_range";

/// The coverage tensors, when the file has them.
fn load_coverage(t: &Tensors, threshold: f32) -> Result<Option<Coverage>> {
    let names = t.st.names();
    if !names.contains(&COVERAGE_POSES) {
        return Ok(None);
    }
    let keys = f32s(&t.view(COVERAGE_POSES)?)?;
    let columns = t.view(COVERAGE_POSES)?.shape().get(1).copied().unwrap_or(0);
    let range = f32s(&t.view(COVERAGE_WEIGHTS)?)?;
    if columns == 0 || !columns.is_multiple_of(3) || range.len() % 2 != 0 {
        return Err(t.fail("malformed coverage tensors".into()));
    }
    let (lo, hi) = range.split_at(range.len() / 2);
    Ok(Some(Coverage {
        poses: keys
            .chunks_exact(columns)
            .map(|p| {
                p.chunks_exact(3)
                    .map(|v| nalgebra::Vector3::new(v[0], v[1], v[2]))
                    .collect()
            })
            .collect(),
        threshold,
        weight_min: lo.to_vec(),
        weight_max: hi.to_vec(),
    }))
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

/// A model file's tensors by name, with errors naming the file.
struct Tensors<'a> {
    path: &'a Path,
    st: SafeTensors<'a>,
    device: Device,
}

impl Tensors<'_> {
    fn fail(&self, what: String) -> anyhow::Error {
        anyhow::anyhow!("{}: {what}", self.path.display())
    }

    fn view(&self, name: &str) -> Result<TensorView<'_>> {
        self.st
            .tensor(name)
            .map_err(|_| self.fail(format!("missing tensor '{name}'")))
    }

    fn get(&self, name: &str) -> Result<Tensor> {
        tensor(&self.view(name)?, self.device)
    }

    /// The tensor `name`, which must have shape `dims`.
    fn shaped(&self, name: &str, dims: &[usize]) -> Result<Tensor> {
        let t = self.get(name)?;
        let want: Vec<i64> = dims.iter().map(|&d| d as i64).collect();
        if t.size() != want {
            return Err(self.fail(format!(
                "tensor '{name}' has shape {:?}, expected {want:?}",
                t.size()
            )));
        }
        Ok(t)
    }
}

/// Loads a model file (or checkpoint) onto `device`; its metadata says which kind of model.
pub fn load(path: &Path, device: Device) -> Result<ModelFile> {
    let bytes = read_bytes(path)?;
    let tensors = Tensors {
        path,
        st: parse(path, &bytes)?,
        device,
    };
    let info = info_of(path, &bytes)?;
    let lbs = skin_of(&tensors.view("lbs.joints")?, &tensors.view("lbs.weights")?)?;
    let skeleton = Skeleton::from_plain(&info.skeleton).map_err(|e| tensors.fail(e.to_string()))?;
    let body = Body::new(
        info.body.name.clone(),
        TriMesh::new(
            points(&tensors.view("body.points")?)?,
            triangles(&tensors.view("body.triangles")?)?,
        ),
        points(&tensors.view("body.normals")?)?,
        skeleton,
        skin_of(
            &tensors.view("body.joints")?,
            &tensors.view("body.weights")?,
        )?,
    );
    let garment = TriMesh {
        positions: points(&tensors.view("garment.rest")?)?,
        triangles: info.garment.faces.clone(),
        uv: info.garment.uv.as_ref().map(|uv| FaceVaryingUv {
            coords: uv.coords.clone(),
            triangles: uv.triangles.clone(),
        }),
    };
    garment
        .validate()
        .map_err(|e| tensors.fail(format!("garment: {e}")))?;
    body.mesh()
        .validate()
        .map_err(|e| tensors.fail(format!("body: {e}")))?;
    let (model, known): (Model, fn(&str) -> bool) = match &info.model {
        KindInfo::Pbns(p) => (Model::Pbns(load_pbns(&tensors, p)?), is_pbns_tensor),
        KindInfo::Dynamic(d) => (
            Model::Dynamic(Box::new(load_dynamic(&tensors, d, &garment, &body)?)),
            |n: &str| n.starts_with("space.") || n.starts_with("motion."),
        ),
    };
    let common = |name: &str| {
        name.starts_with("lbs.")
            || name.starts_with("body.")
            || name.starts_with("coverage.")
            || name == "garment.rest"
    };
    let coverage = match &info.model {
        KindInfo::Pbns(p) => load_coverage(&tensors, p.training.beyond_range())?,
        KindInfo::Dynamic(_) => None,
    };
    let mut extra = Vec::new();
    for name in tensors.st.names() {
        if !common(name) && !known(name) {
            extra.push((name.to_string(), tensors.get(name)?));
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
        coverage,
    })
}

fn is_pbns_tensor(name: &str) -> bool {
    name.starts_with("mlp.")
        || name.starts_with("W.")
        || name == "psd"
        || name.starts_with("swing.")
}

/// The generative space from its tensors: the network rebuilt from the description (anchors,
/// UV layout), then its parameters loaded.
fn load_space(t: &Tensors, info: &DynamicInfo, garment: &TriMesh, body: &Body) -> Result<Space> {
    let anchors = BodyAnchors::from_vertices(body, &info.anchors, &info.anchor_parts)
        .map_err(|e| t.fail(e.to_string()))?;
    let raster = UvRaster::new(garment, info.shape.map, &t.path.display().to_string())?;
    let consts = Consts::new(garment, &raster, &anchors, t.device);
    let mut space = Space::new(info.shape.clone(), consts, t.device)?;
    let stored: Vec<(String, Tensor)> =
        t.st.names()
            .into_iter()
            .filter_map(|n| {
                n.strip_prefix("space.")
                    .map(|s| (s.to_string(), n.to_string()))
            })
            .map(|(short, full)| Ok((short, t.get(&full)?)))
            .collect::<Result<_>>()?;
    space
        .load_parameters(&stored)
        .map_err(|e| t.fail(e.to_string()))?;
    Ok(space)
}

/// The space and, when the description has one, the motion encoder (tensors `motion.*`).
fn load_dynamic(
    t: &Tensors,
    info: &DynamicInfo,
    garment: &TriMesh,
    body: &Body,
) -> Result<Dynamic> {
    let mut space = load_space(t, info, garment, body)?;
    let motion = match &info.motion {
        Some(m) => {
            // A model with a motion stage has its space frozen for good.
            space.freeze();
            let mut encoder = MotionEncoder::new(m.shape.clone(), &space, t.device);
            let stored: Vec<(String, Tensor)> =
                t.st.names()
                    .into_iter()
                    .filter(|n| n.starts_with("motion."))
                    .map(|n| Ok((n.to_string(), t.get(n)?)))
                    .collect::<Result<_>>()?;
            encoder
                .load_parameters(&stored)
                .map_err(|e| t.fail(e.to_string()))?;
            Some(encoder)
        }
        None => None,
    };
    Ok(Dynamic { space, motion })
}

/// The PBNS network from its tensors, checked against its description.
fn load_pbns(t: &Tensors, info: &PbnsInfo) -> Result<Pbns> {
    let shape = info.shape;
    let (n, k) = (shape.vertices, shape.influences);
    let mut mlp = Vec::new();
    for i in 0..shape.layers {
        mlp.push((
            t.get(&format!("mlp.{i}.weight"))?,
            t.get(&format!("mlp.{i}.bias"))?,
        ));
    }
    let joints = &info.feature_joints;
    if shape.features != 6 * joints.len() || joints.iter().any(|&j| j >= shape.joints) {
        return Err(t.fail(format!(
            "{} MLP inputs do not match the {} feature joints",
            shape.features,
            joints.len()
        )));
    }
    Ok(Pbns {
        shape,
        feature_joints: joints.clone(),
        mlp,
        psd: t.shaped("psd", &[shape.width, 3 * n])?,
        template: t.shaped("garment.rest", &[n, 3])?,
        joints: t.shaped("W.joints", &[n, k])?.to_kind(Kind::Int64),
        logits: t.shaped("W.logits", &[n, k])?,
        clamp: None,
        swing: info
            .swing
            .as_ref()
            .map(|s| load_swing(t, s).map(Box::new))
            .transpose()?,
    })
}

/// A swing's network from its tensors, checked against its description.
fn load_swing(t: &Tensors, info: &SwingInfo) -> Result<Swing> {
    let shape = info.shape.clone();
    let mut mlp = Vec::new();
    for i in 0..=shape.layers {
        mlp.push((
            t.get(&format!("swing.mlp.{i}.weight"))?,
            t.get(&format!("swing.mlp.{i}.bias"))?,
        ));
    }
    let m = shape.motion_inputs();
    let s = shape.shapes;
    let modes = match shape.integrator {
        SwingIntegrator::Network => None,
        SwingIntegrator::Modal => Some(Modes {
            stiffness: t.shaped("swing.stiffness", &[s, s])?,
            damping: t.shaped("swing.damping", &[s, s])?,
        }),
    };
    let swing = Swing {
        basis: t.shaped("swing.basis", &[shape.shapes, 3 * shape.vertices])?,
        input_mean: t.shaped("swing.input_mean", &[m])?,
        input_scale: t.shaped("swing.input_scale", &[m])?,
        mlp,
        shape,
        modes,
    };
    swing.check().map_err(|e| t.fail(e.to_string()))?;
    Ok(swing)
}

fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("cannot read model {}", path.display()))
}

fn parse<'a>(path: &Path, bytes: &'a [u8]) -> Result<SafeTensors<'a>> {
    SafeTensors::deserialize(bytes)
        .map_err(|e| anyhow::anyhow!("{}: not a safetensors file ({e:?})", path.display()))
}

/// The first fields of every description, read before the rest so an older file gets a clear error.
#[derive(Deserialize)]
struct FormatHeader {
    format: String,
    version: u32,
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
    let invalid = || format!("{}: invalid model description", path.display());
    let header: FormatHeader = serde_json::from_str(json).with_context(invalid)?;
    let (name, version) = (path.display(), header.version);
    if header.format != FORMAT {
        bail!("{name}: format '{}', not {FORMAT}", header.format);
    }
    if version > VERSION {
        bail!("{name}: model format v{version} is newer than this build reads (v{OLDEST} to v{VERSION}): use a newer garmentbake");
    }
    if version < OLDEST {
        bail!("{name}: model format v{version} is older than this build reads (v{OLDEST} to v{VERSION}): retrain the model");
    }
    let description = serde_json::from_str(json).with_context(invalid)?;
    serde_json::from_value(migrate(version, description)).with_context(invalid)
}

/// A description of format `version` brought up to [`VERSION`], one step per version.
fn migrate(version: u32, mut description: serde_json::Value) -> serde_json::Value {
    if version < 3 {
        // v3 names the build that trained the model; a v2 file does not say.
        description["written_by"] = serde_json::Value::Null;
    }
    description
}

/// A tensor's bytes for safetensors (little-endian, as the format requires).
struct Blob {
    dtype: Dtype,
    shape: Vec<usize>,
    data: Vec<u8>,
}

impl Blob {
    fn float(t: &Tensor) -> Blob {
        Blob::tensor(t, Dtype::F32)
    }

    fn int(t: &Tensor) -> Blob {
        Blob::tensor(t, Dtype::I32)
    }

    /// A tensor stored as `dtype` (F32 or I32).
    fn tensor(t: &Tensor, dtype: Dtype) -> Blob {
        let data = match dtype {
            Dtype::I32 => le_bytes(flat::<i32>(t, Kind::Int), i32::to_le_bytes),
            _ => le_bytes(flat::<f32>(t, Kind::Float), f32::to_le_bytes),
        };
        Blob {
            dtype,
            shape: t.size().iter().map(|&d| d as usize).collect(),
            data,
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

fn le_bytes<T>(v: Vec<T>, bytes: fn(T) -> [u8; 4]) -> Vec<u8> {
    v.into_iter().flat_map(bytes).collect()
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

/// A view's little-endian 4-byte elements, which must be of type `dtype`.
fn words<T>(view: &TensorView, dtype: Dtype, from: fn([u8; 4]) -> T) -> Result<Vec<T>> {
    if view.dtype() != dtype {
        bail!("expected {dtype:?} data, found {:?}", view.dtype());
    }
    Ok(view
        .data()
        .chunks_exact(4)
        .map(|b| from([b[0], b[1], b[2], b[3]]))
        .collect())
}

fn f32s(view: &TensorView) -> Result<Vec<f32>> {
    words(view, Dtype::F32, f32::from_le_bytes)
}

fn i32s(view: &TensorView) -> Result<Vec<i32>> {
    words(view, Dtype::I32, i32::from_le_bytes)
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
