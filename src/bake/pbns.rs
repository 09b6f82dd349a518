//! Baking a PBNS model: `D` is a blend-shape set and `W` a skin, so the file replays
//! `LBS(T + Σ w_k B_k, θ, W)` exactly like the network, with `B` the (compressed) basis and `w`
//! the MLP output projected on it, one weight track per clip.

use super::compress::{
    active_columns, offset_matrix, spectrum_of, spectrum_of_product, unit_targets,
    weights_from_zero, FromZero,
};
use super::normals;
use super::replay::{distances, Played};
use super::{animation_asset, moved_by, skeleton_asset, skinned_mesh_asset, BODY_COLOR};
use crate::metrics::deviation::Deviation;
use crate::models::file::ModelFile;
use crate::models::pbns::flat;
use crate::models::pose_features::PoseBatch;
use crate::models::{predict_chunks, Pbns};
use crate::rig::{SkelAnimation, Skeleton, Skin};
use anyhow::{bail, Result};
use exporters::asset::{BakedAsset, BlendShape};
use tch::{Device, Kind, Tensor};

/// Garment colour in viewers.
pub const GARMENT_COLOR: [f32; 3] = [0.25, 0.45, 0.8];

pub use super::compress::Targets;

pub struct BakeOptions {
    pub targets: Targets,
    /// Joint influences per vertex in the file (None: the model's own).
    pub influences: Option<usize>,
    pub with_body: bool,
}

/// What the bake cost, per clip and overall, in metres (world space, after skinning).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BakeReport {
    pub targets: usize,
    /// Numerical rank of the offsets the clips use.
    pub used_rank: usize,
    pub influences: usize,
    pub clips: Vec<ClipError>,
    /// Wall seconds per phase of the bake: `network` (the MLP's coefficients and its forward
    /// pass for the replay check), `svd` (the offsets' compression), `normals` (the morph
    /// normals' fit), `replay` (the file's replay against the network), `asset` (the rest).
    #[serde(default)]
    pub phases: Vec<(String, f64)>,
}

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct ClipError {
    pub clip: String,
    /// The file's replay against the network.
    #[serde(flatten)]
    pub error: Deviation,
    /// With fewer influences than the network: the max error pruning alone would cost (before
    /// the corrective blend shapes compensate it), mm.
    pub pruning_error_mm: Option<f64>,
}

/// A clip as the network sees it: its pose batch (features and skinning matrices, built once)
/// and the MLP's output on it, from which both the file's weights and the network's forward pass
/// for the replay check are made.
struct ClipNetwork {
    batch: PoseBatch,
    /// Blend-shape weights `[frame, K (+ S)]` ([`Pbns::blend_weights`]).
    x: Tensor,
}

impl ClipNetwork {
    fn new(network: &Pbns, skeleton: &Skeleton, clip: &SkelAnimation, device: Device) -> Self {
        let poses: Vec<_> = (0..clip.frame_count())
            .map(|f| clip.local_pose(f))
            .collect();
        let batch = network.batch(skeleton, &poses, device);
        let x = predict_chunks(poses.len(), |s, n| {
            network.blend_weights(&batch.slice(s, n))
        });
        ClipNetwork { batch, x }
    }

    /// Network coefficients `X` for every frame, `[frame][k]`.
    fn coefficients(&self, network: &Pbns) -> Vec<Vec<f32>> {
        let x: Vec<f32> = flat(&self.x, Kind::Float);
        x.chunks_exact(network.blend_shape_count())
            .map(<[f32]>::to_vec)
            .collect()
    }
}

/// The network's blend shapes (the PSD basis `D`, and a swing's `E`) as offset sets.
fn basis(network: &Pbns) -> Vec<Vec<[f32; 3]>> {
    let d: Vec<f32> = flat(&network.blend_shapes(), Kind::Float);
    let n = network.shape.vertices;
    d.chunks_exact(3 * n)
        .map(|c| c.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
        .collect()
}

/// Bakes `model` over `clips` (already retargeted onto the model's skeleton).
pub fn bake(
    model: &ModelFile,
    clips: &[SkelAnimation],
    opts: &BakeOptions,
    device: Device,
) -> Result<(BakedAsset, BakeReport)> {
    let network = model.pbns()?;
    if network
        .swing
        .as_ref()
        .is_some_and(|s| !s.shape.bones.is_empty())
    {
        // The bones need extra joints with rotation tracks in the file's skin: not written yet.
        anyhow::bail!("this swing turns swing bones, which `bake` cannot write yet: eval it to a point cache (--out NAME.pc2/.abc/.usd) instead");
    }
    let mut clock = Phases::start();
    let inputs: Vec<ClipNetwork> = clips
        .iter()
        .map(|c| ClipNetwork::new(network, model.skeleton(), c, device))
        .collect();
    let per_clip: Vec<Vec<Vec<f32>>> = inputs.iter().map(|c| c.coefficients(network)).collect();
    clock.lap("network");
    let all: Vec<Vec<f32>> = per_clip.iter().flatten().cloned().collect();
    let network_skin = network.skin();
    let skin = file_skin(&network_skin, opts.influences)?;
    let pruned = skin.influences < network_skin.influences;
    // The offsets themselves (3N × frames, a 2.7 GFLOP product for the skirt's 256 shapes over
    // 1,247 frames) are needed only to add correctives to or to measure a tolerance against: a
    // plain count of targets takes the leading directions without them.
    let needs_reference = pruned || matches!(opts.targets, Targets::Tolerance(_));
    // The basis as offset sets: the file's targets with neither budget, else the reference's.
    let basis = if needs_reference || opts.targets == Targets::Full {
        basis(network)
    } else {
        Vec::new()
    };
    let mut reference = if needs_reference {
        offset_matrix(&basis, &all)
    } else {
        nalgebra::DMatrix::zeros(0, 0)
    };
    if pruned {
        add_skin_correctives(&mut reference, model, clips, &network_skin, &skin);
    }
    // Without correctives the offsets are X·D: the fast small-basis decomposition applies.
    let spectrum = if pruned {
        spectrum_of(&reference)
    } else {
        let x: Vec<&Tensor> = inputs.iter().map(|c| &c.x).collect();
        spectrum_of_product(&Tensor::cat(&x, 0), &network.blend_shapes())
    };
    let top = spectrum.singular_values.first().copied().unwrap_or(0.0);
    let used_rank = spectrum
        .singular_values
        .iter()
        .filter(|&&s| s > 1e-6 * top)
        .count();
    let (mut targets, mut weights) = match opts.targets {
        Targets::Full if !pruned => (basis.clone(), all.clone()),
        Targets::Full => {
            let c = spectrum.truncate(&reference, used_rank);
            (c.targets, c.weights)
        }
        Targets::Count(k) if !pruned => spectrum.leading(k),
        budget => {
            let c = spectrum.budget(&reference, budget, None);
            (c.targets, c.weights)
        }
    };
    // Unit targets with weights from 0 (the rest moves into the base mesh): the same offsets,
    // and readers that clamp weights (Blender, Godot) play them too.
    unit_targets(&mut targets, &mut weights, false);
    let FromZero { base, rest_weights } = weights_from_zero(&targets, &mut weights);
    let base = moved_by(&model.garment, &base);
    clock.lap("svd");
    // Global frame (clips in order) → its clip and frame, for the skinning the normals fit sees.
    let frames: Vec<(usize, usize)> = clips
        .iter()
        .enumerate()
        .flat_map(|(c, clip)| (0..clip.frame_count()).map(move |f| (c, f)))
        .collect();
    let skeleton = model.skeleton();
    let blended = |g: usize| {
        let (c, f) = frames[g];
        let skinning = skeleton.skinning_matrices(&clips[c].local_pose(f));
        (0..skin.vertex_count())
            .map(|v| skin.blended(v, &skinning))
            .collect()
    };
    let normals = normals::fit(
        &base.positions,
        &base.triangles,
        &targets,
        &weights,
        &rest_weights,
        &blended,
    );
    clock.lap("normals");
    let mut garment =
        skinned_mesh_asset("garment", &base, Some(&normals.base), &skin, GARMENT_COLOR);
    let pick = |t: &[[f32; 3]]| -> Vec<[f32; 3]> {
        garment
            .source_vertex
            .iter()
            .map(|&v| t[v as usize])
            .collect()
    };
    garment.blend_shapes = targets
        .iter()
        .zip(&normals.deltas)
        .enumerate()
        .map(|(k, (t, n))| BlendShape {
            name: format!("psd_{k:03}"),
            offsets: pick(t),
            normal_offsets: Some(pick(n)),
        })
        .collect();
    garment.rest_weights = rest_weights;
    let mut asset = BakedAsset {
        skeleton: skeleton_asset(model.skeleton()),
        meshes: vec![garment],
        ..Default::default()
    };
    if opts.with_body {
        let body = &model.body;
        asset.meshes.push(skinned_mesh_asset(
            "body",
            body.mesh(),
            Some(&body.normals),
            &body.skin,
            BODY_COLOR,
        ));
    }
    let mut report = BakeReport {
        targets: targets.len(),
        used_rank,
        influences: skin.influences,
        clips: Vec::new(),
        phases: Vec::new(),
    };
    clock.lap("asset");
    // The network's side of the replay check: its template, its basis and its slot skin, on
    // the MLP's coefficients (the units that fire on some frame: the others add exact zeros).
    let x_all: Vec<&Tensor> = inputs.iter().map(|c| &c.x).collect();
    let active = Tensor::from_slice(&active_columns(&Tensor::cat(&x_all, 0)));
    let cpu = |t: &Tensor| t.to_device(Device::Cpu).to_kind(Kind::Float).contiguous();
    let network_shapes = cpu(&network.blend_shapes().index_select(0, &active));
    let template: Vec<f32> = flat(&network.template, Kind::Float);
    let slots = network.slots();
    let slot_joints: Vec<usize> = slots.joints.iter().map(|&j| j as usize).collect();
    // The file's side: its base, targets, weights and skin.
    let file_rest: Vec<f32> = base.positions.iter().flatten().copied().collect();
    let file_shapes = Tensor::from_slice(&targets.concat().concat())
        .view([targets.len() as i64, file_rest.len() as i64]);
    let file_joints: Vec<usize> = skin.joint_indices.iter().map(|&j| j as usize).collect();
    let mut start = 0;
    for ((clip, x), input) in clips.iter().zip(&per_clip).zip(&inputs) {
        let w = &weights[start..start + x.len()];
        start += x.len();
        let mut anim = animation_asset(clip);
        anim.blend_shape_weights = vec![(0, w.iter().flatten().copied().collect())];
        asset.animations.push(anim);
        clock.lap("asset");
        // The network's own forward pass, not the basis and skin the bake was made from: a
        // fault in reading those out of the network would be on both sides of the comparison.
        let frames = x.len();
        let network_x = cpu(&input.x.index_select(1, &active));
        let network_rows: Vec<f32> = flat(&input.batch.skinning, Kind::Float);
        let played_by_network = Played {
            rest: &template,
            shapes: &network_shapes,
            weights: &network_x,
            skinning: &network_rows,
            joints: &slot_joints,
            slot_weights: &slots.weights,
            influences: slots.influences,
        };
        // The file's skinning from the rig's own joint matrices.
        let file_rows = rig_skinning_rows(model.skeleton(), clip);
        let file_weights =
            Tensor::from_slice(&w.concat()).view([frames as i64, targets.len() as i64]);
        let played_by_file = Played {
            rest: &file_rest,
            shapes: &file_shapes,
            weights: &file_weights,
            skinning: &file_rows,
            joints: &file_joints,
            slot_weights: &skin.joint_weights,
            influences: skin.influences,
        };
        let mut error = clip_error(clip, &distances(&played_by_file, &played_by_network));
        if pruned {
            // The network's basis and coefficients on the pruned skin, uncorrected.
            let garment_rest: Vec<f32> =
                model.garment.positions.iter().flatten().copied().collect();
            let uncorrected = Played {
                rest: &garment_rest,
                ..played_by_file
            };
            let uncorrected = Played {
                shapes: &network_shapes,
                weights: &network_x,
                ..uncorrected
            };
            error.pruning_error_mm = Some(
                clip_error(clip, &distances(&uncorrected, &played_by_network))
                    .error
                    .max_mm,
            );
        }
        report.clips.push(error);
        clock.lap("replay");
    }
    report.phases = clock.phases;
    asset
        .provenance
        .push(("generator".into(), "garmentbake bake (PBNS)".into()));
    Ok((asset, report))
}

/// Wall time per named phase, summed over the laps that name it, in order of first use.
struct Phases {
    last: std::time::Instant,
    phases: Vec<(String, f64)>,
}

impl Phases {
    fn start() -> Phases {
        Phases {
            last: std::time::Instant::now(),
            phases: Vec::new(),
        }
    }

    /// Counts the time since the last lap to `name`.
    fn lap(&mut self, name: &str) {
        let now = std::time::Instant::now();
        let s = (now - self.last).as_secs_f64();
        self.last = now;
        match self.phases.iter_mut().find(|p| p.0 == name) {
            Some(p) => p.1 += s,
            None => self.phases.push((name.to_string(), s)),
        }
    }
}

/// The skin written to the file: the model's own, or pruned to fewer influences.
fn file_skin(model_skin: &Skin, influences: Option<usize>) -> Result<Skin> {
    match influences {
        None => Ok(model_skin.clone()),
        Some(k) if k == 0 || k > 8 => bail!("--influences must be between 1 and 8, got {k}"),
        Some(k) => {
            let per_vertex: Vec<Vec<(u16, f32)>> = (0..model_skin.vertex_count())
                .map(|v| model_skin.vertex(v).map(|(j, w)| (j as u16, w)).collect())
                .collect();
            Ok(Skin::from_sparse(&per_vertex, k, 0))
        }
    }
}

/// Skinning correctives: with fewer influences than the network, the rest-space offsets that make
/// the pruned skin land exactly where the full skin puts the garment, per frame:
/// `x' = A⁻¹ (p − b)` with `A`, `b` the pruned skin's blended matrix; added to `offsets`
/// (3N × frames, clips in order) so the compression learns them as extra blend-shape content.
fn add_skin_correctives(
    offsets: &mut nalgebra::DMatrix<f32>,
    model: &ModelFile,
    clips: &[SkelAnimation],
    full: &Skin,
    pruned: &Skin,
) {
    use nalgebra::{Point3, Vector3};
    use rayon::prelude::*;
    let rest = &model.garment.positions;
    let poses: Vec<_> = clips
        .iter()
        .flat_map(|c| (0..c.frame_count()).map(move |f| c.local_pose(f)))
        .collect();
    let skeleton = model.skeleton();
    let columns: Vec<Vec<f32>> = poses
        .par_iter()
        .enumerate()
        .map(|(f, pose)| {
            let skinning = skeleton.skinning_matrices(pose);
            let column = offsets.column(f);
            let mut out = column.as_slice().to_vec();
            for (v, p) in rest.iter().enumerate() {
                let x = Point3::new(
                    p[0] + out[3 * v],
                    p[1] + out[3 * v + 1],
                    p[2] + out[3 * v + 2],
                );
                let target = full.blended(v, &skinning).transform_point(&x);
                let m = pruned.blended(v, &skinning);
                let a = m.fixed_view::<3, 3>(0, 0).into_owned();
                let b: Vector3<f32> = m.fixed_view::<3, 1>(0, 3).into_owned();
                if let Some(inv) = a.try_inverse() {
                    let fixed = inv * (target.coords - b);
                    for axis in 0..3 {
                        out[3 * v + axis] = fixed[axis] - p[axis];
                    }
                }
            }
            out
        })
        .collect();
    for (f, column) in columns.into_iter().enumerate() {
        offsets.column_mut(f).copy_from_slice(&column);
    }
}

/// Skinning matrices of every frame of `clip` from the rig (row-major 3 × 4), `[frame][J][12]`.
fn rig_skinning_rows(skeleton: &Skeleton, clip: &SkelAnimation) -> Vec<f32> {
    use rayon::prelude::*;
    let frames: Vec<Vec<f32>> = (0..clip.frame_count())
        .into_par_iter()
        .map(|f| {
            skeleton
                .skinning_matrices(&clip.local_pose(f))
                .iter()
                .flat_map(|m| (0..3).flat_map(move |r| (0..4).map(move |c| m[(r, c)])))
                .collect()
        })
        .collect();
    frames.concat()
}

/// A clip's replay error from its per-frame largest and mean distances (m).
fn clip_error(clip: &SkelAnimation, per_frame: &[(f32, f32)]) -> ClipError {
    let mm: Vec<(f64, f64)> = per_frame
        .iter()
        .map(|&(max, mean)| (1e3 * max as f64, 1e3 * mean as f64))
        .collect();
    ClipError {
        clip: clip.name.clone(),
        error: Deviation::of_largest_and_mean(&mm),
        pruning_error_mm: None,
    }
}
