//! Baking a garment given frame by frame (a dynamic roll-out, a simulation) into a skinned mesh
//! with blend shapes, so that any glTF viewer plays it with no neural runtime and at a fraction
//! of a point cache's size. The garment is skinned to the body's skeleton with fixed weights;
//! each frame's garment is un-skinned (every vertex's blended transform inverted), and the
//! rest-space residuals over the whole sequence are compressed by their singular directions
//! ([`super::compress::spectrum_of`]) into the fewest targets within a tolerance, their weights
//! animated per frame.

use super::compress::{spectrum_of, FromZero, Targets};
use super::normals;
use super::pbns::GARMENT_COLOR;
use super::{animation_asset, moved_by, skeleton_asset, skinned_mesh_asset};
use crate::geometry::TriMesh;
use crate::metrics::deviation::Deviation;
use crate::rig::{SkelAnimation, Skeleton, Skin};
use anyhow::{bail, Result};
use exporters::asset::{BakedAsset, BlendShape};
use nalgebra::{DMatrix, Matrix4, Point3};
use rayon::prelude::*;

/// What the compression kept and what it cost (world space, after skinning).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SequenceReport {
    pub targets: usize,
    /// Singular directions of the residuals above 1e-12 of the energy of the largest.
    pub rank: usize,
    /// The file's frames against the frames baked.
    #[serde(flatten)]
    pub error: Deviation,
    /// The largest animated weight (the smallest is 0): a target's largest displacement in
    /// metres, so under 1 for a garment, inside the range every reader keeps.
    pub max_weight: f32,
    /// The targets are 16-bit (KHR_mesh_quantization).
    pub quantized: bool,
    /// The count asked for (`--max-targets`), when a count and not a tolerance chose the
    /// targets: `error` is then what the budget costs.
    #[serde(default)]
    pub max_targets: Option<usize>,
}

/// Bakes `frames` (world positions, the garment's vertex order) played over `animation` (the
/// body's poses, one per frame) with `skin`, keeping the blend shapes `budget` asks for (a count,
/// or the fewest whose replay stays within a tolerance in metres of every frame). `quantize`: the
/// targets on the 16-bit grid a glTF stores under KHR_mesh_quantization (half the bytes; the
/// rounding counts in the tolerance and in the error reported).
pub fn bake_sequence(
    skeleton: &Skeleton,
    garment: &TriMesh,
    skin: &Skin,
    animation: &SkelAnimation,
    frames: &[Vec<[f32; 3]>],
    budget: Targets,
    quantize: bool,
) -> Result<(BakedAsset, SequenceReport)> {
    check_sizes(garment, animation, frames)?;
    let blended = blended_per_frame(skeleton, skin, animation);
    let residuals = rest_residuals(&garment.positions, &blended, frames)?;
    let spectrum = spectrum_of(&residuals);
    // Convex blends of rigid transforms never enlarge a rest-space error, so the rest-space
    // tolerance bounds the world-space one; the world error is measured below all the same.
    let mut kept = spectrum.budget(&residuals, budget, Some(quantize));
    // Weights from 0 up (the base mesh takes the rest): readers that clamp them play it too.
    let FromZero { base, rest_weights } = kept.weights_from_zero();
    let base = moved_by(garment, &base);
    let error = world_error(
        &base.positions,
        &blended,
        frames,
        &kept.targets,
        &kept.weights,
    );
    let normals = normals::fit(
        &base.positions,
        &base.triangles,
        &kept.targets,
        &kept.weights,
        &rest_weights,
        &|f| blended[f].clone(),
    );
    let mut mesh = skinned_mesh_asset("garment", &base, Some(&normals.base), skin, GARMENT_COLOR);
    mesh.quantized_blend_shapes = quantize;
    let pick = |t: &[[f32; 3]]| -> Vec<[f32; 3]> {
        mesh.source_vertex.iter().map(|&v| t[v as usize]).collect()
    };
    mesh.blend_shapes = kept
        .targets
        .iter()
        .zip(&normals.deltas)
        .enumerate()
        .map(|(k, (t, n))| BlendShape {
            name: format!("residual_{k:03}"),
            offsets: pick(t),
            normal_offsets: Some(pick(n)),
        })
        .collect();
    mesh.rest_weights = rest_weights;
    let mut anim = animation_asset(animation);
    anim.blend_shape_weights = vec![(0, kept.weights.iter().flatten().copied().collect())];
    let asset = BakedAsset {
        skeleton: skeleton_asset(skeleton),
        meshes: vec![mesh],
        animations: vec![anim],
        ..Default::default()
    };
    let report = SequenceReport {
        targets: kept.targets.len(),
        rank: spectrum.rank(),
        error,
        max_weight: kept.weights.iter().flatten().fold(0.0, |m, &w| m.max(w)),
        quantized: quantize,
        max_targets: match budget {
            Targets::Count(k) => Some(k),
            _ => None,
        },
    };
    Ok((asset, report))
}

fn check_sizes(
    garment: &TriMesh,
    animation: &SkelAnimation,
    frames: &[Vec<[f32; 3]>],
) -> Result<()> {
    if frames.is_empty() || frames.len() != animation.frame_count() {
        bail!(
            "{} garment frames for {} poses: a baked sequence needs one pose per frame",
            frames.len(),
            animation.frame_count()
        );
    }
    if let Some(f) = frames
        .iter()
        .position(|g| g.len() != garment.vertex_count())
    {
        bail!(
            "frame {f} has {} vertices, the garment {}",
            frames[f].len(),
            garment.vertex_count()
        );
    }
    Ok(())
}

/// Every vertex's blended skinning matrix at every frame, `[frame][vertex]`.
fn blended_per_frame(
    skeleton: &Skeleton,
    skin: &Skin,
    animation: &SkelAnimation,
) -> Vec<Vec<Matrix4<f32>>> {
    (0..animation.frame_count())
        .into_par_iter()
        .map(|f| {
            let skinning = skeleton.skinning_matrices(&animation.local_pose(f));
            (0..skin.vertex_count())
                .map(|v| skin.blended(v, &skinning))
                .collect()
        })
        .collect()
}

/// Each frame un-skinned, minus the rest garment: 3N × frames, one column per frame.
fn rest_residuals(
    rest: &[[f32; 3]],
    blended: &[Vec<Matrix4<f32>>],
    frames: &[Vec<[f32; 3]>],
) -> Result<DMatrix<f32>> {
    let columns: Vec<Result<Vec<f32>>> = frames
        .par_iter()
        .zip(blended)
        .enumerate()
        .map(|(f, (garment, matrices))| {
            let mut column = Vec::with_capacity(3 * rest.len());
            for (v, (p, m)) in garment.iter().zip(matrices).enumerate() {
                let Some(inverse) = m.try_inverse() else {
                    bail!("frame {f}: vertex {v}'s blended skinning transform is singular");
                };
                let local = inverse.transform_point(&Point3::from(*p));
                column.extend((0..3).map(|a| local[a] - rest[v][a]));
            }
            Ok(column)
        })
        .collect();
    let columns = columns.into_iter().collect::<Result<Vec<_>>>()?;
    Ok(DMatrix::from_vec(
        3 * rest.len(),
        frames.len(),
        columns.concat(),
    ))
}

/// Distance between the baked replay (`LBS(rest + Σ w_k T_k)`) and the frames, per frame.
fn world_error(
    rest: &[[f32; 3]],
    blended: &[Vec<Matrix4<f32>>],
    frames: &[Vec<[f32; 3]>],
    targets: &[Vec<[f32; 3]>],
    weights: &[Vec<f32>],
) -> Deviation {
    let per_frame: Vec<(f64, f64)> = frames
        .par_iter()
        .zip(blended)
        .zip(weights)
        .map(|((garment, matrices), w)| {
            let (mut max, mut sum) = (0.0f32, 0.0f64);
            for (v, (p, m)) in garment.iter().zip(matrices).enumerate() {
                let mut local = Point3::from(rest[v]);
                for (t, wk) in targets.iter().zip(w) {
                    local += nalgebra::Vector3::from(t[v]) * *wk;
                }
                let e = (m.transform_point(&local) - Point3::from(*p)).norm();
                max = max.max(e);
                sum += e as f64;
            }
            (1e3 * max as f64, 1e3 * sum / rest.len().max(1) as f64)
        })
        .collect();
    Deviation::of_largest_and_mean(&per_frame)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::grid;
    use crate::rig::JointTransform;
    use nalgebra::{UnitQuaternion, Vector3};

    /// Two joints in a chain, a grid garment weighted half-and-half along x.
    fn rig() -> (Skeleton, TriMesh, Skin) {
        let names = vec!["root".to_string(), "tip".to_string()];
        let world = [Vector3::zeros(), Vector3::new(0.3, 0.0, 0.0)];
        let skeleton = Skeleton::from_world_positions(&names, &[None, Some(0)], &world).unwrap();
        let mesh = grid(6, 4, 0.1);
        let weights: Vec<Vec<f32>> = mesh
            .positions
            .iter()
            .map(|p| {
                let w = (p[0] / 0.6).clamp(0.0, 1.0);
                vec![1.0 - w, w]
            })
            .collect();
        (skeleton, mesh, Skin::from_dense(&weights, 2))
    }

    #[test]
    fn a_sequence_of_two_modes_bakes_to_two_targets_that_replay_it() {
        let (skeleton, mesh, skin) = rig();
        let frames_n = 24;
        let poses: Vec<Vec<JointTransform>> = (0..frames_n)
            .map(|f| {
                let mut pose = skeleton.rest.clone();
                let angle = 0.05 * f as f32;
                pose[1].rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle);
                pose
            })
            .collect();
        let animation = SkelAnimation::from_poses("test", 30.0, &poses);
        // Two rest-space modes (a sway in x, a ripple in y) under the skinning.
        let frames: Vec<Vec<[f32; 3]>> = poses
            .iter()
            .enumerate()
            .map(|(f, pose)| {
                let (a, b) = ((f as f32 * 0.4).sin() * 0.02, (f as f32 * 0.9).cos() * 0.01);
                let moved: Vec<[f32; 3]> = mesh
                    .positions
                    .iter()
                    .map(|p| [p[0] + a * p[1], p[1] + b * (p[0] * 20.0).sin(), p[2]])
                    .collect();
                skin.skin_points(&moved, &skeleton.skinning_matrices(pose))
            })
            .collect();
        let tol = Targets::Tolerance(1e-5);
        for quantize in [false, true] {
            let (asset, report) =
                bake_sequence(&skeleton, &mesh, &skin, &animation, &frames, tol, quantize).unwrap();
            // Un-skinned, the residuals span the two modes only (left in world space, the
            // skinning's rotations would need targets of their own); on the 16-bit grid too.
            assert_eq!(report.targets, 2, "{report:?}");
            assert!(report.error.max_mm < 1e-2, "{report:?}");
            assert_eq!(asset.meshes[0].blend_shapes.len(), 2);
            assert_eq!(asset.meshes[0].quantized_blend_shapes, quantize);
            assert_eq!(
                asset.animations[0].blend_shape_weights[0].1.len(),
                2 * frames_n
            );
            asset.check().unwrap();
        }
        // A count keeps that many whatever they cost, and the report says what they cost.
        let (asset, one) = bake_sequence(
            &skeleton,
            &mesh,
            &skin,
            &animation,
            &frames,
            Targets::Count(1),
            true,
        )
        .unwrap();
        assert_eq!((one.targets, one.max_targets), (1, Some(1)), "{one:?}");
        assert_eq!(asset.meshes[0].blend_shapes.len(), 1);
        assert!(
            one.error.max_mm > 0.1,
            "one target cannot carry two modes: {one:?}"
        );
        let wrong = &frames[..frames_n - 1];
        assert!(bake_sequence(&skeleton, &mesh, &skin, &animation, wrong, tol, true).is_err());
    }
}
