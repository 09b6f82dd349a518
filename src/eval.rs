//! Evaluation: posing a model over a clip, and the metrics of several garment series (model,
//! plain LBS) over the same frames. This is the reference the exporters are compared with.

use crate::body::{Body, PosedBody};
use crate::geometry::SurfaceIndex;
use crate::metrics::{ClothGeometry, Edges, Inside, InsideFrame, Metrics};
use crate::models::coverage::{pose_key, Coverage, PoseKey};
use crate::models::Pbns;
use crate::rig::{JointTransform, Skeleton, Skin};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tch::Device;

/// The model's garment for every pose (world space), in chunks, without gradients.
pub fn model_frames(
    model: &Pbns,
    skeleton: &Skeleton,
    poses: &[Vec<JointTransform>],
    device: Device,
) -> Vec<Vec<[f32; 3]>> {
    model.predict_points(&model.batch(skeleton, poses, device))
}

/// Plain linear blend skinning of the rest garment (the baseline without PSD).
pub fn lbs_frames(
    skin: &Skin,
    rest: &[[f32; 3]],
    skeleton: &Skeleton,
    poses: &[Vec<JointTransform>],
) -> Vec<Vec<[f32; 3]>> {
    poses
        .par_iter()
        .map(|p| skin.skin_points(rest, &skeleton.skinning_matrices(p)))
        .collect()
}

/// Metrics of several garment series over the same clip, and how much the body overlaps itself.
pub struct Comparison {
    /// Mean metrics, one per series.
    pub metrics: Vec<Metrics>,
    /// Mean edge strain |e − e_T| / e_T (%), one per series.
    pub strain_pct: Vec<f64>,
    /// Mean edge strain (%) of the skinned body under the garment: a garment that does not
    /// slide over the body stretches as much.
    pub body_strain_pct: f64,
    /// Body vertices inside another part of the body (see [`crate::body::PosedBody::overlap`]), per frame.
    pub body_overlap: Vec<usize>,
    /// Vertices inside the body by winding number, and how deep, one per series.
    pub inside: Vec<Inside>,
}

/// One frame's figures of several garment series (e.g. model and plain LBS).
pub struct FrameComparison {
    metrics: Vec<Metrics>,
    strain: Vec<f64>,
    body_strain: f64,
    overlap: usize,
    inside: Vec<InsideFrame>,
}

/// Per-frame figures of several garment series over the same poses (the body posed one frame at
/// a time, so long clips need little memory): [`Comparison::of`] any subset of them.
pub fn compare_frames(
    geometry: &ClothGeometry,
    series: &[&[Vec<[f32; 3]>]],
    body: &Body,
    body_under: &Edges,
    poses: &[Vec<JointTransform>],
) -> Vec<FrameComparison> {
    poses
        .par_iter()
        .enumerate()
        .map(|(f, pose)| {
            let posed = PosedBody::new(body, pose);
            let surface = SurfaceIndex::new(&posed.points, &body.mesh().triangles);
            FrameComparison {
                inside: series
                    .iter()
                    .map(|s| InsideFrame::of(&s[f], &posed, &surface))
                    .collect(),
                metrics: series
                    .iter()
                    .map(|s| geometry.frame(&s[f], &posed))
                    .collect(),
                strain: series
                    .iter()
                    .map(|s| geometry.edges.mean_strain_pct(&s[f]))
                    .collect(),
                body_strain: body_under.mean_strain_pct(&posed.points),
                overlap: posed.overlap.iter().filter(|&&o| o).count(),
            }
        })
        .collect()
}

impl Comparison {
    /// Means over `frames` of `series` series.
    pub fn of(frames: &[&FrameComparison], series: usize) -> Comparison {
        let n = frames.len().max(1) as f64;
        Comparison {
            metrics: (0..series)
                .map(|k| Metrics::mean(&frames.iter().map(|m| m.metrics[k]).collect::<Vec<_>>()))
                .collect(),
            strain_pct: (0..series)
                .map(|k| frames.iter().map(|m| m.strain[k]).sum::<f64>() / n)
                .collect(),
            body_strain_pct: frames.iter().map(|m| m.body_strain).sum::<f64>() / n,
            body_overlap: frames.iter().map(|m| m.overlap).collect(),
            inside: (0..series)
                .map(|k| Inside::of(&frames.iter().map(|m| &m.inside[k]).collect::<Vec<_>>()))
                .collect(),
        }
    }
}

/// Mean figures of several garment series over the same poses ([`compare_frames`], all frames).
pub fn compare(
    geometry: &ClothGeometry,
    series: &[&[Vec<[f32; 3]>]],
    body: &Body,
    body_under: &Edges,
    poses: &[Vec<JointTransform>],
) -> Comparison {
    let frames = compare_frames(geometry, series, body, body_under, poses);
    Comparison::of(&frames.iter().collect::<Vec<_>>(), series.len())
}

/// How far each frame of a clip lies from the poses a model was trained on.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ClipCoverage {
    /// Frames at least this far from every training pose are beyond the trained range (radians;
    /// see [`crate::models::coverage`]).
    pub threshold: f32,
    /// Per frame, the distance to the nearest training pose (radians).
    pub distance: Vec<f32>,
    /// The frames beyond the trained range, in order.
    pub beyond: Vec<usize>,
    pub median: f32,
    pub max: f32,
}

impl ClipCoverage {
    /// The coverage of `poses` (local joint transforms per frame) for a model with these feature
    /// joints.
    pub fn of(
        coverage: &Coverage,
        joints: &[usize],
        poses: &[Vec<JointTransform>],
    ) -> ClipCoverage {
        let keys: Vec<PoseKey> = poses
            .iter()
            .map(|p| {
                let rotations: Vec<_> = p.iter().map(|t| t.rotation).collect();
                pose_key(&rotations, joints)
            })
            .collect();
        let distance = coverage.distances(&keys);
        let mut sorted = distance.clone();
        sorted.sort_by(f32::total_cmp);
        ClipCoverage {
            threshold: coverage.threshold,
            beyond: (0..distance.len())
                .filter(|&f| coverage.beyond(distance[f]))
                .collect(),
            median: crate::metrics::percentile(&sorted, 0.5) as f32,
            max: sorted.last().copied().unwrap_or(0.0),
            distance,
        }
    }

    /// The `n` frames farthest from the training poses, farthest first (the first of equals).
    pub fn farthest(&self, n: usize) -> Vec<usize> {
        let mut frames: Vec<usize> = (0..self.distance.len()).collect();
        frames.sort_by(|&a, &b| {
            self.distance[b]
                .total_cmp(&self.distance[a])
                .then(a.cmp(&b))
        });
        frames.truncate(n);
        frames
    }

    /// The frames within the trained range, in order.
    pub fn within(&self) -> Vec<usize> {
        (0..self.distance.len())
            .filter(|f| self.beyond.binary_search(f).is_err())
            .collect()
    }

    /// What `eval` and `bake` report per clip: the coverage of its frames (`clip`: the clip
    /// played on the model's skeleton) and the [`FARTHEST`] frames farthest from the training
    /// poses, farthest first.
    pub fn of_clip(
        coverage: &Coverage,
        joints: &[usize],
        clip: &crate::rig::SkelAnimation,
    ) -> (ClipCoverage, Vec<usize>) {
        let poses: Vec<_> = (0..clip.frame_count())
            .map(|f| clip.local_pose(f))
            .collect();
        let coverage = ClipCoverage::of(coverage, joints, &poses);
        let farthest = coverage.farthest(FARTHEST);
        (coverage, farthest)
    }

    /// One line on the clip's coverage (`eval` and `bake` print the same).
    pub fn line(&self, farthest: &[usize]) -> String {
        format!(
            "pose distance to the training poses: median {:.3}, max {:.3} rad; {} of {} frames beyond the trained range (≥ {:.3} rad); farthest frames {farthest:?}",
            self.median,
            self.max,
            self.beyond.len(),
            self.distance.len(),
            self.threshold,
        )
    }
}

/// How many of a clip's frames farthest from the training poses `eval` and `bake` name: the
/// ones to look at before shipping.
pub const FARTHEST: usize = 8;

/// The network's blend-shape weights over `poses` that lie outside the training range (before
/// clamping).
pub fn outside_weights(
    network: &Pbns,
    coverage: &Coverage,
    skeleton: &Skeleton,
    poses: &[Vec<JointTransform>],
    device: Device,
) -> crate::models::coverage::OutsideWeights {
    let batch = network.batch(skeleton, poses, device);
    let weights = tch::no_grad(|| network.coefficients(&batch.features));
    coverage.weights_outside(&weights)
}

/// How much the skinned body overlaps itself over the clip (vertices inside another part).
#[derive(Serialize, Deserialize)]
pub struct OverlapSummary {
    pub median: usize,
    pub most: usize,
    pub worst_frame: usize,
}

impl OverlapSummary {
    pub fn of(per_frame: &[usize]) -> OverlapSummary {
        let (worst_frame, most) = per_frame
            .iter()
            .copied()
            .enumerate()
            .max_by_key(|&(f, n)| (n, std::cmp::Reverse(f)))
            .unwrap_or((0, 0));
        let mut sorted = per_frame.to_vec();
        sorted.sort_unstable();
        OverlapSummary {
            median: sorted.get(sorted.len() / 2).copied().unwrap_or(0),
            most,
            worst_frame,
        }
    }
}
