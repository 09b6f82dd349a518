//! The training pose set, balanced as PBNS does: walk the clips' frames in order and keep a frame
//! only if it differs from every kept frame by at least a threshold in some joint-rotation
//! component; then split train / validation.
//!
//! Compared are only the joints that move the garment (a joint whose subtree carries part of the
//! garment's skin): with every joint, fingers and thumbs dominate and few poses survive. Global
//! orientation (the root) is never compared; it is applied by skinning.
//!
//! The physical loss needs no ground truth, so any plausible pose can be trained on. Two clips
//! give a few hundred poses, and an unseen clip combines the same joint ranges differently (head
//! bowed while an arm is raised): [`recombined`] adds training poses that take each limb chain
//! (a leg, the spine, the neck and head, an arm) from a different real frame, and
//! [`range_sampled`] adds poses whose garment joints are drawn across the rotation ranges the
//! clips show, widened: hips, knees and spine further than any clip took them together.

use crate::models::coverage::{pose_distance, pose_key, PoseKey};
use crate::rig::{JointTransform, SkelAnimation, Skeleton, Skin};
use nalgebra::{UnitQuaternion, Vector3};
use rayon::prelude::*;
use serde::Serialize;

/// Where a training pose comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PoseKind {
    /// A frame of a clip.
    Clip,
    /// Made by [`recombined`]: limb chains from other frames.
    Recombined,
    /// Made by [`range_sampled`]: garment joints drawn across their widened ranges.
    Sampled,
}

/// One training pose: where it came from and its local joint transforms.
#[derive(Clone, Debug, PartialEq)]
pub struct Pose {
    pub clip: usize,
    pub frame: usize,
    pub local: Vec<JointTransform>,
    pub kind: PoseKind,
}

impl Pose {
    /// The pose as balancing and the coverage report compare it.
    pub fn key(&self, joints: &[usize]) -> PoseKey {
        let rotations: Vec<UnitQuaternion<f32>> = self.local.iter().map(|t| t.rotation).collect();
        pose_key(&rotations, joints)
    }
}

/// How many poses of each kind a set holds.
pub fn count(poses: &[Pose], kind: PoseKind) -> usize {
    poses.iter().filter(|p| p.kind == kind).count()
}

pub struct PoseSet {
    pub train: Vec<Pose>,
    pub validation: Vec<Pose>,
    /// Frames looked at.
    pub frames_seen: usize,
    /// Poses the balancing kept before the budget thinned them (`train` + `validation` when the
    /// budget was not reached).
    pub balanced: usize,
    /// The joints compared.
    pub joints: Vec<usize>,
}

/// Joints (never a root) whose subtree carries at least `min_share` of `skin`'s weight: the
/// joints whose rotation moves those vertices.
pub fn moving_joints(skeleton: &Skeleton, skin: &Skin, min_share: f32) -> Vec<usize> {
    let n = skeleton.joint_count();
    let mut subtree = vec![0.0f64; n];
    for v in 0..skin.vertex_count() {
        for (j, w) in skin.vertex(v) {
            subtree[j] += w as f64;
        }
    }
    // Parents come first, so a reverse sweep accumulates children into parents.
    for j in (0..n).rev() {
        if let Some(p) = skeleton.parents[j] {
            subtree[p] += subtree[j];
        }
    }
    let total = skin.vertex_count().max(1) as f64;
    (0..n)
        .filter(|&j| skeleton.parents[j].is_some() && subtree[j] / total >= min_share as f64)
        .collect()
}

/// Greedy balanced selection over all frames of all clips: `(clip, frame)` pairs, in order.
pub fn balanced(clips: &[SkelAnimation], joints: &[usize], threshold: f32) -> Vec<(usize, usize)> {
    let mut kept: Vec<PoseKey> = Vec::new();
    let mut out = Vec::new();
    for (c, clip) in clips.iter().enumerate() {
        for f in 0..clip.frame_count() {
            let rv = pose_key(&clip.rotations[f], joints);
            let near = kept.iter().any(|k| pose_distance(k, &rv) < threshold);
            if !near {
                kept.push(rv);
                out.push((c, f));
            }
        }
    }
    out
}

/// At most `budget` of the `picked` frames, chosen farthest first: the first frame, then again and
/// again the frame farthest from every one chosen (in [`pose_distance`]). Fifty takes balance to
/// thousands of poses, more than a training run of minutes can visit; thinning them this way
/// keeps the rare poses (a leg raised above the hip) that a random subset would mostly lose, and
/// spends fewer poses on the walk every take repeats. Order of the kept frames is preserved.
pub fn thinned(
    clips: &[SkelAnimation],
    joints: &[usize],
    picked: Vec<(usize, usize)>,
    budget: usize,
) -> Vec<(usize, usize)> {
    if picked.len() <= budget {
        return picked;
    }
    let keys: Vec<PoseKey> = picked
        .iter()
        .map(|&(c, f)| pose_key(&clips[c].rotations[f], joints))
        .collect();
    let mut nearest = vec![f32::INFINITY; keys.len()];
    let mut chosen = vec![false; keys.len()];
    let mut next = 0;
    for _ in 0..budget {
        chosen[next] = true;
        let from = &keys[next];
        nearest
            .par_iter_mut()
            .zip(&keys)
            .for_each(|(d, k)| *d = d.min(pose_distance(from, k)));
        // Ties go to the earliest frame, so the choice does not depend on thread timing.
        next = (0..keys.len())
            .filter(|&i| !chosen[i])
            .fold(None, |best: Option<usize>, i| match best {
                Some(b) if nearest[b] >= nearest[i] => Some(b),
                _ => Some(i),
            })
            .unwrap_or(0);
    }
    picked
        .into_iter()
        .zip(chosen)
        .filter_map(|(p, keep)| keep.then_some(p))
        .collect()
}

/// Balanced set (thinned to at most `budget` poses) split into train and validation
/// (`validation` fraction, shuffled by `seed`).
pub fn pose_set(
    clips: &[SkelAnimation],
    joints: Vec<usize>,
    threshold: f32,
    budget: usize,
    validation: f32,
    seed: u64,
) -> PoseSet {
    let balanced_count;
    let mut picked = {
        let all = balanced(clips, &joints, threshold);
        balanced_count = all.len();
        thinned(clips, &joints, all, budget)
    };
    shuffle(&mut picked, seed);
    let n_val = ((picked.len() as f32 * validation).round() as usize).min(picked.len());
    let pose = |&(c, f): &(usize, usize)| Pose {
        clip: c,
        frame: f,
        local: clips[c].local_pose(f),
        kind: PoseKind::Clip,
    };
    let (val, train) = picked.split_at(n_val);
    PoseSet {
        train: train.iter().map(pose).collect(),
        validation: val.iter().map(pose).collect(),
        frames_seen: clips.iter().map(SkelAnimation::frame_count).sum(),
        balanced: balanced_count,
        joints,
    }
}

/// Contiguous blocks each training clip is cut into for [`held_out_threshold`].
pub const COVERAGE_FOLDS: usize = 5;

/// The share of the training clips' frames that lie within the coverage threshold of the poses
/// taken from elsewhere in the clips ([`held_out_threshold`]).
pub const COVERAGE_PERCENTILE: f64 = 0.95;

/// The pose distance beyond which a frame counts as outside the trained range, learnt from the
/// training clips themselves: each clip is cut into `folds` contiguous blocks, and every frame's
/// held-out distance is its distance to the nearest training pose (real or generated) whose
/// source frame lies in another block; the threshold is the `percentile` of those distances. So
/// a frame farther than this from every training pose is farther from them than nearly all of
/// the training clips' own frames are from the poses of the clips' other parts.
///
/// Blocks rather than single frames: neighbouring frames are near-duplicates, so leaving out one
/// frame would measure the frame rate, not coverage. `None` when no frame has a training pose
/// outside its own block (a single tiny clip).
pub fn held_out_threshold(
    clips: &[SkelAnimation],
    train: &[Pose],
    joints: &[usize],
    folds: usize,
    percentile: f64,
) -> Option<f32> {
    let folds = folds.max(1);
    let block = |clip: usize, frame: usize| {
        let n = clips[clip].frame_count().max(1);
        (clip, frame.min(n - 1) * folds / n)
    };
    let trained: Vec<((usize, usize), PoseKey)> = train
        .iter()
        .map(|p| (block(p.clip, p.frame), p.key(joints)))
        .collect();
    let frames: Vec<(usize, usize)> = clips
        .iter()
        .enumerate()
        .flat_map(|(c, clip)| (0..clip.frame_count()).map(move |f| (c, f)))
        .collect();
    let mut distances: Vec<f32> = frames
        .par_iter()
        .filter_map(|&(c, f)| {
            let own = block(c, f);
            let key = pose_key(&clips[c].rotations[f], joints);
            trained
                .iter()
                .filter(|(b, _)| *b != own)
                .map(|(_, k)| pose_distance(k, &key))
                .min_by(f32::total_cmp)
        })
        .collect();
    if distances.is_empty() {
        return None;
    }
    distances.sort_by(f32::total_cmp);
    Some(crate::metrics::percentile(&distances, percentile) as f32)
}

/// Limb chains: every joint belongs to the chain started by its nearest ancestor-or-self whose
/// parent branches (or is the root); the root is in none (`None`).
pub fn limb_chains(skeleton: &Skeleton) -> Vec<Option<usize>> {
    let n = skeleton.joint_count();
    let mut children = vec![0usize; n];
    for p in skeleton.parents.iter().flatten() {
        children[*p] += 1;
    }
    let mut chain: Vec<Option<usize>> = vec![None; n];
    // Parents come first, so a chain's start is known before its joints.
    for j in 0..n {
        chain[j] = match skeleton.parents[j] {
            None => None,
            Some(p) if skeleton.parents[p].is_none() || children[p] > 1 => Some(j),
            Some(p) => chain[p],
        };
    }
    chain
}

/// How much further than its donor frame a recombined limb chain may bend (uniform in
/// `[0, RECOMBINE_AMPLIFY]`, relative to the rest pose): unseen clips go a little beyond the
/// training clips' ranges (measured: neck 1.67 rad in 131_02 against 1.30 in 01_01 + 131_01).
pub const RECOMBINE_AMPLIFY: f32 = 0.3;

/// `count` synthetic poses: each starts from a random real pose (root and global orientation
/// included) and takes every limb chain's rotations from another random real pose, bent up to
/// `amplify` further from the rest pose.
pub fn recombined(
    real: &[Pose],
    skeleton: &Skeleton,
    count: usize,
    amplify: f32,
    seed: u64,
) -> Vec<Pose> {
    if real.is_empty() {
        return Vec::new();
    }
    let chains = limb_chains(skeleton);
    let starts: Vec<usize> = (0..chains.len())
        .filter(|&j| chains[j] == Some(j))
        .collect();
    let mut rng = Rng::new(seed.wrapping_add(0xA076_1D64_78BD_642F));
    (0..count)
        .map(|_| {
            let base = &real[rng.below(real.len())];
            let mut local = base.local.clone();
            for &start in &starts {
                let donor = &real[rng.below(real.len())].local;
                let gain = 1.0 + amplify * (rng.below(1001) as f32 / 1000.0);
                for j in (0..chains.len()).filter(|&j| chains[j] == Some(start)) {
                    // Scaled about the rest orientation: a larger bend of the same kind.
                    local[j].rotation =
                        amplified(skeleton.rest[j].rotation, donor[j].rotation, gain);
                }
            }
            Pose {
                clip: base.clip,
                frame: base.frame,
                local,
                kind: PoseKind::Recombined,
            }
        })
        .collect()
}

/// How far beyond the clips' range a sampled joint may turn, as a share of that range on each
/// side (the same reach as [`RECOMBINE_AMPLIFY`]: unseen clips go a little further).
pub const RANGE_WIDEN: f32 = 0.3;

/// Share of a sampled pose's garment joints drawn from their ranges (the rest keep the base
/// frame's rotations), so a sample changes a few joints at a time rather than all at once.
const RESAMPLED_SHARE: f64 = 0.5;

/// Per joint, the lowest and highest value of each rotation-vector component over every frame of
/// the clips (the units of [`pose_key`]).
#[derive(Clone, Debug, PartialEq)]
pub struct JointRanges {
    pub lowest: Vec<Vector3<f32>>,
    pub highest: Vec<Vector3<f32>>,
}

impl JointRanges {
    pub fn of(clips: &[SkelAnimation], joint_count: usize) -> JointRanges {
        let mut r = JointRanges {
            lowest: vec![Vector3::repeat(f32::INFINITY); joint_count],
            highest: vec![Vector3::repeat(f32::NEG_INFINITY); joint_count],
        };
        for clip in clips {
            for frame in &clip.rotations {
                for (j, q) in frame.iter().enumerate().take(joint_count) {
                    let v = q.scaled_axis();
                    r.lowest[j] = r.lowest[j].inf(&v);
                    r.highest[j] = r.highest[j].sup(&v);
                }
            }
        }
        r
    }

    /// Each range grown by `share` of its span on both sides.
    pub fn widened(&self, share: f32) -> JointRanges {
        let grow = |j: usize| (self.highest[j] - self.lowest[j]).map(|s| s.max(0.0) * share);
        JointRanges {
            lowest: (0..self.lowest.len())
                .map(|j| self.lowest[j] - grow(j))
                .collect(),
            highest: (0..self.highest.len())
                .map(|j| self.highest[j] + grow(j))
                .collect(),
        }
    }
}

/// `count` synthetic poses: each starts from a random real pose and draws about half of the
/// garment `joints` (hips, knees, spine: what moves the garment) uniformly within `ranges`, so
/// wide stances, raised knees and deep bends appear in combinations no clip has.
pub fn range_sampled(
    real: &[Pose],
    ranges: &JointRanges,
    joints: &[usize],
    count: usize,
    seed: u64,
) -> Vec<Pose> {
    if real.is_empty() {
        return Vec::new();
    }
    let mut rng = Rng::new(seed.wrapping_add(0xE703_7ED1_A0B4_28DB));
    let mut unit = move || rng.next_u64() as f64 / u64::MAX as f64;
    (0..count)
        .map(|_| {
            let base = &real[((unit() * real.len() as f64) as usize).min(real.len() - 1)];
            let mut local = base.local.clone();
            for &j in joints {
                if unit() >= RESAMPLED_SHARE {
                    continue;
                }
                let (lo, hi) = (ranges.lowest[j], ranges.highest[j]);
                let v = Vector3::from_fn(|c, _| lo[c] + (hi[c] - lo[c]) * unit() as f32);
                local[j].rotation = UnitQuaternion::from_scaled_axis(v);
            }
            Pose {
                clip: base.clip,
                frame: base.frame,
                local,
                kind: PoseKind::Sampled,
            }
        })
        .collect()
}

/// `rotation` with its deviation from `rest` scaled by `gain` (1: unchanged, exactly).
fn amplified(
    rest: UnitQuaternion<f32>,
    rotation: UnitQuaternion<f32>,
    gain: f32,
) -> UnitQuaternion<f32> {
    if gain == 1.0 {
        return rotation;
    }
    let delta = rest.inverse() * rotation;
    rest * delta.powf(gain)
}

/// SplitMix64: a tiny deterministic generator (the data order must not depend on platform RNGs).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// Fisher–Yates with [`Rng`].
pub fn shuffle<T>(items: &mut [T], seed: u64) {
    let mut rng = Rng::new(seed);
    for i in (1..items.len()).rev() {
        items.swap(i, rng.below(i + 1));
    }
}
