//! Retargeting a motion-capture clip onto the body's skeleton.
//!
//! Both rigs have world-aligned joint frames at rest, but the clip rests in a T-pose and the body
//! in an A-pose, with other proportions. For every mapped body joint we find the rest correction
//! `C` that turns the body's rest bones onto the clip's rest bones (one child: the shortest arc;
//! several children: a least-squares (Kabsch) fit of all of them, which fixes twist too). At each
//! frame the body joint's world rotation is then `G_clip · C · B_rest`. The root translation is
//! scaled by the ratio of hip heights, and a constant vertical offset puts the stance feet on y = 0.

use super::{SkelAnimation, Skeleton};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// A motion-capture clip in world terms, whatever file format it was read from (BVH today):
/// what retargeting needs and nothing about the file.
#[derive(Clone, Debug)]
pub struct CaptureClip {
    /// World rest position of every clip joint (clip units), parents first.
    pub rest_positions: Vec<Vector3<f64>>,
    /// Per frame, per clip joint: world position and world rotation.
    pub frames: Vec<Vec<(Vector3<f64>, UnitQuaternion<f64>)>>,
    /// Seconds between frames.
    pub frame_time: f64,
}

/// Which rig joint each clip joint drives (from a joint map, or by identical names).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JointMapping {
    /// The map's `name`, or `"identity"`.
    pub map_name: String,
    /// Per clip joint (clip order): the rig joint index it drives.
    pub clip_to_rig: Vec<Option<usize>>,
}

/// The retargeted clip and the numbers worth reporting.
#[derive(Clone, Debug)]
pub struct Retargeted {
    pub animation: SkelAnimation,
    /// Metres per clip unit used for the root translation.
    pub scale: f32,
    /// Vertical offset (m) added so the feet touch the floor during stance.
    pub floor_offset: f32,
    pub map_name: String,
}

/// Retargets every frame of `clip` onto `skeleton` through the joint mapping.
pub fn retarget(
    clip: &CaptureClip,
    map: &JointMapping,
    skeleton: &Skeleton,
    name: &str,
) -> Retargeted {
    let rig = RestMatch::new(clip, map, skeleton);
    let root = 0;
    let clip_root = rig.clip_of[root];
    let frames = &clip.frames;
    let mut translations = Vec::with_capacity(frames.len());
    let mut rotations = Vec::with_capacity(frames.len());
    for pose in frames {
        rotations.push(rig.local_rotations(skeleton, pose));
        let mut t: Vec<Vector3<f32>> = skeleton.rest.iter().map(|r| r.translation).collect();
        if let Some(k) = clip_root {
            t[root] = (pose[k].0 * rig.scale).cast::<f32>();
        }
        translations.push(t);
    }
    let mut animation = SkelAnimation {
        name: name.to_string(),
        fps: snap_rate(1.0 / clip.frame_time),
        translations,
        rotations,
    };
    let floor_offset = ground(&mut animation, skeleton);
    Retargeted {
        animation,
        scale: rig.scale as f32,
        floor_offset,
        map_name: map.map_name.clone(),
    }
}

/// BVH frame times are written rounded (CMU: .0083333 s): a rate within 0.01 % of a whole number
/// is that number, so key times and USD time codes land on whole frames.
fn snap_rate(fps: f64) -> f32 {
    let whole = fps.round();
    if (fps - whole).abs() < 1e-4 * fps {
        whole as f32
    } else {
        fps as f32
    }
}

/// Per body joint: the clip joint driving it and the rest correction.
struct RestMatch {
    clip_of: Vec<Option<usize>>,
    correction: Vec<UnitQuaternion<f64>>,
    rest_world_rotation: Vec<UnitQuaternion<f64>>,
    scale: f64,
}

impl RestMatch {
    fn new(clip: &CaptureClip, map: &JointMapping, skeleton: &Skeleton) -> Self {
        let n = skeleton.joint_count();
        let mut clip_of = vec![None; n];
        for (k, rig) in map.clip_to_rig.iter().enumerate() {
            if let Some(j) = rig {
                clip_of[*j] = Some(k);
            }
        }
        let rest_world = skeleton.rest_world();
        let body_pos: Vec<Vector3<f64>> = rest_world
            .iter()
            .map(|m| m.fixed_view::<3, 1>(0, 3).into_owned().cast::<f64>())
            .collect();
        let rest_world_rotation = rest_world
            .iter()
            .map(|m| {
                UnitQuaternion::from_matrix(&m.fixed_view::<3, 3>(0, 0).into_owned().cast::<f64>())
            })
            .collect();
        let clip_pos = &clip.rest_positions;
        let mut correction: Vec<UnitQuaternion<f64>> = Vec::with_capacity(n);
        for j in 0..n {
            let pairs: Vec<_> = match (skeleton.parents[j], clip_of[j]) {
                (Some(_), Some(k)) => skeleton
                    .children(j)
                    .filter_map(|c| {
                        clip_of[c].map(|kc| (body_pos[c] - body_pos[j], clip_pos[kc] - clip_pos[k]))
                    })
                    .filter(|(b, c)| b.norm() > 1e-6 && c.norm() > 1e-6)
                    .collect(),
                _ => Vec::new(),
            };
            let inherited =
                skeleton.parents[j].map_or(UnitQuaternion::identity(), |p| correction[p]);
            correction.push(fit_rotation(&pairs).unwrap_or(inherited));
        }
        let scale = hip_height(&body_pos, None) / hip_height(clip_pos, Some(&clip_of)).max(1e-9);
        RestMatch {
            clip_of,
            correction,
            rest_world_rotation,
            scale,
        }
    }

    /// Local rotations of the body for one clip pose (world rotations per clip joint).
    fn local_rotations(
        &self,
        skeleton: &Skeleton,
        pose: &[(Vector3<f64>, UnitQuaternion<f64>)],
    ) -> Vec<UnitQuaternion<f32>> {
        let n = skeleton.joint_count();
        let mut world: Vec<UnitQuaternion<f64>> = Vec::with_capacity(n);
        let mut local = Vec::with_capacity(n);
        for j in 0..n {
            let parent = skeleton.parents[j].map(|p| world[p]);
            let g = match self.clip_of[j] {
                Some(k) => pose[k].1 * self.correction[j] * self.rest_world_rotation[j],
                None => {
                    parent.unwrap_or_else(UnitQuaternion::identity)
                        * skeleton.rest[j].rotation.cast::<f64>()
                }
            };
            let l = parent.map_or(g, |p| p.inverse() * g);
            world.push(g);
            local.push(l.cast::<f32>());
        }
        local
    }
}

/// Rotation taking the body's rest bone directions onto the clip's (None if there is no bone).
fn fit_rotation(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Option<UnitQuaternion<f64>> {
    match pairs {
        [] => None,
        [(b, c)] => Some(shortest_arc(&b.normalize(), &c.normalize())),
        _ => {
            // Kabsch: maximise Σ cᵢ·(R bᵢ) over unit directions.
            let h: Matrix3<f64> = pairs
                .iter()
                .map(|(b, c)| c.normalize() * b.normalize().transpose())
                .sum();
            let svd = h.svd(true, true);
            let (u, v_t) = (svd.u?, svd.v_t?);
            let d = (u * v_t).determinant().signum();
            let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t;
            Some(UnitQuaternion::from_rotation_matrix(
                &Rotation3::from_matrix_unchecked(r),
            ))
        }
    }
}

fn shortest_arc(a: &Vector3<f64>, b: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::rotation_between(a, b).unwrap_or_else(|| {
        // Opposite directions: half a turn about any perpendicular axis.
        let axis = if a.x.abs() < 0.9 {
            a.cross(&Vector3::x())
        } else {
            a.cross(&Vector3::y())
        };
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), std::f64::consts::PI)
    })
}

/// Height of the root above the lowest (mapped) joint at rest: the leg length, in each rig's units.
fn hip_height(pos: &[Vector3<f64>], mapped: Option<&[Option<usize>]>) -> f64 {
    let ids: Vec<usize> = match mapped {
        Some(m) => m.iter().flatten().copied().collect(),
        None => (0..pos.len()).collect(),
    };
    let root_y = match mapped {
        Some(m) => m[0].map_or(pos[0].y, |k| pos[k].y),
        None => pos[0].y,
    };
    let lowest = ids.iter().map(|&i| pos[i].y).fold(f64::INFINITY, f64::min);
    root_y - lowest
}

/// Foot contact: per frame, how far the feet sit above (+) or below (−) their rest height, taking
/// for each frame the foot joint closest to its rest height (heel strike: the ankle; tiptoe: the
/// toe). Foot joints are those within 12 cm of the lowest joint at rest.
fn foot_clearance(anim: &SkelAnimation, skeleton: &Skeleton) -> Vec<f32> {
    let rest: Vec<f32> = skeleton.rest_world().iter().map(|m| m[(1, 3)]).collect();
    let lowest = rest.iter().copied().fold(f32::INFINITY, f32::min);
    let feet: Vec<usize> = (0..rest.len())
        .filter(|&j| rest[j] < lowest + 0.12)
        .collect();
    (0..anim.frame_count())
        .map(|f| {
            let pos = anim.joint_positions(skeleton, f);
            feet.iter()
                .map(|&j| pos[j].y - rest[j])
                .fold(f32::INFINITY, f32::min)
        })
        .collect()
}

/// Puts the feet on the floor: a constant offset (10th percentile of the clearance, robust to
/// jumps), then a per-frame correction of what remains while the feet are near the floor (full
/// within 5 cm, fading out by 15 cm so jumps stay jumps), smoothed over ±0.1 s. Other proportions
/// than the performer's (a wide stance lowers their hips less than ours) otherwise float the feet.
fn ground(anim: &mut SkelAnimation, skeleton: &Skeleton) -> f32 {
    let clearance = foot_clearance(anim, skeleton);
    if clearance.is_empty() {
        return 0.0;
    }
    let mut sorted = clearance.clone();
    sorted.sort_by(f32::total_cmp);
    let offset = -sorted[sorted.len() / 10];
    let residual: Vec<f32> = clearance.iter().map(|c| c + offset).collect();
    let correction: Vec<f32> = residual.iter().map(|&r| -r * contact_weight(r)).collect();
    let half = (0.1 * anim.fps).round() as usize;
    for (f, t) in anim.translations.iter_mut().enumerate() {
        let window = &correction[f.saturating_sub(half)..(f + half + 1).min(correction.len())];
        t[0].y += offset + window.iter().sum::<f32>() / window.len() as f32;
    }
    offset
}

fn contact_weight(residual: f32) -> f32 {
    ((0.15 - residual.abs()) / 0.10).clamp(0.0, 1.0)
}
