//! Retargeting a motion-capture clip onto the body's skeleton.
//!
//! Both rigs have world-aligned joint frames at rest, but the clip rests in a T-pose and the body
//! in an A-pose, with other proportions. For every mapped body joint we find the rest correction
//! `C` that turns the body's rest bones onto the clip's rest bones (one child: the shortest arc;
//! several children: a least-squares (Kabsch) fit of all of them, which fixes twist too). At each
//! frame the body joint's world rotation is then `G_clip · C · B_rest`. The root translation is
//! scaled by the ratio of hip heights, and a constant vertical offset puts the stance feet on y = 0.

use super::{SkelAnimation, Skeleton};
use crate::io::bvh::Bvh;
use crate::io::joint_map::Resolved;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

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

/// Retargets every frame of `bvh` onto `skeleton` through the resolved joint map.
pub fn retarget(bvh: &Bvh, map: &Resolved, skeleton: &Skeleton, name: &str) -> Retargeted {
    let rig = RestMatch::new(bvh, map, skeleton);
    let root = 0;
    let clip_root = rig.clip_of[root];
    let frames: Vec<_> = (0..bvh.frame_count()).map(|f| bvh.world_pose(f)).collect();
    let mut translations = Vec::with_capacity(frames.len());
    let mut rotations = Vec::with_capacity(frames.len());
    for pose in &frames {
        rotations.push(rig.local_rotations(skeleton, pose));
        let mut t: Vec<Vector3<f32>> = skeleton.rest.iter().map(|r| r.translation).collect();
        if let Some(k) = clip_root {
            t[root] = (pose[k].0 * rig.scale).cast::<f32>();
        }
        translations.push(t);
    }
    let mut animation = SkelAnimation {
        name: name.to_string(),
        fps: (1.0 / bvh.frame_time) as f32,
        translations,
        rotations,
    };
    let floor_offset = floor_offset(&animation, skeleton);
    for t in &mut animation.translations {
        t[root].y += floor_offset;
    }
    Retargeted {
        animation,
        scale: rig.scale as f32,
        floor_offset,
        map_name: map.map_name.clone(),
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
    fn new(bvh: &Bvh, map: &Resolved, skeleton: &Skeleton) -> Self {
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
        let clip_pos = bvh.world_rest_positions();
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
        let scale = hip_height(&body_pos, None) / hip_height(&clip_pos, Some(&clip_of)).max(1e-9);
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

/// Offset that brings the lowest joint back to its rest height in the stance frames: the 10th
/// percentile of the per-frame lowest-joint drop (robust to jumps, which lift the feet).
fn floor_offset(anim: &SkelAnimation, skeleton: &Skeleton) -> f32 {
    let rest_low = lowest_joint(
        &skeleton
            .rest_world()
            .iter()
            .map(|m| m.fixed_view::<3, 1>(0, 3).into_owned())
            .collect::<Vec<_>>(),
    );
    let mut drops: Vec<f32> = (0..anim.frame_count())
        .map(|f| lowest_joint(&anim.joint_positions(skeleton, f)) - rest_low)
        .collect();
    if drops.is_empty() {
        return 0.0;
    }
    drops.sort_by(f32::total_cmp);
    -drops[drops.len() / 10]
}

fn lowest_joint(pos: &[Vector3<f32>]) -> f32 {
    pos.iter().map(|p| p.y).fold(f32::INFINITY, f32::min)
}
