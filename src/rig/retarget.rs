//! Retargeting a motion-capture clip onto the body's skeleton.
//!
//! The clip is first stood up along +Y ([`super::capture`]). Its rest pose is its zero-rotation
//! pose when that stands (CMU's T-pose), else its most upright frame (production rigs, whose zero
//! pose is not a pose). For every driven body joint we find the rest fit `F` that turns the body's
//! rest bones onto the clip's rest bones (one bone: the shortest arc; several: a least-squares
//! (Kabsch) fit of all of them, which fixes twist too); bones run to the nearest *driven* joints
//! below, so joints a map leaves out cost nothing. At each frame the body joint's world rotation
//! is then `G_clip · G_rest⁻¹ · F · B_rest`: the clip joint's turn since its rest, applied to the
//! body's bone as fitted. The root translation is scaled by the ratio of hip heights, and a
//! vertical offset puts the lowest skinned foot vertex on the rest pose's floor ([`super::ground`]).

use super::capture::{
    detect_up, CaptureClip, ClipAxes, Found, JointWorld, RootOffset, Units, UpAxis,
};
use super::ground::{ground, Feet};
use super::{SkelAnimation, Skeleton};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::Serialize;

/// What became of one clip joint under a joint map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "fate")]
pub enum JointFate {
    /// Drives this rig joint.
    Mapped { rig: usize },
    /// Left out with mapped joints below it: its rotation is composed into theirs. `into` is the
    /// nearest mapped ancestor (clip joint), None above the mapped root.
    Folded { into: Option<usize>, explicit: bool },
    /// Left out with no mapped joint below it (face, fingers, toes, twist leaves), or skipped.
    Dropped { explicit: bool },
}

/// Which rig joint each clip joint drives (from a joint map, or by identical names), and what
/// became of the others.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JointMapping {
    /// The map's `name`, or `"identity"`.
    pub map_name: String,
    /// Per clip joint (clip order).
    pub fates: Vec<JointFate>,
}

impl JointMapping {
    /// Per clip joint: the rig joint it drives.
    pub fn clip_to_rig(&self) -> Vec<Option<usize>> {
        self.fates
            .iter()
            .map(|f| match f {
                JointFate::Mapped { rig } => Some(*rig),
                _ => None,
            })
            .collect()
    }

    /// (mapped, folded, dropped) clip joints.
    pub fn counts(&self) -> (usize, usize, usize) {
        let count = |p: fn(&JointFate) -> bool| self.fates.iter().filter(|f| p(f)).count();
        (
            count(|f| matches!(f, JointFate::Mapped { .. })),
            count(|f| matches!(f, JointFate::Folded { .. })),
            count(|f| matches!(f, JointFate::Dropped { .. })),
        )
    }
}

/// Where the clip's rest pose came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "source", content = "frame")]
pub enum RestSource {
    /// All rotations zero: the file's own rest (a T-pose or A-pose).
    ZeroPose,
    /// The take's most upright frame (the zero pose does not stand).
    Frame(usize),
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
    /// How the clip was read: axes, units, rest, joints.
    pub reading: ClipReading,
}

/// How a clip was read before retargeting, for every command's report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ClipReading {
    pub up: Found<UpAxis>,
    pub units: Found<Units>,
    /// The performer's leg (hip height at rest) in metres, by `units`.
    pub leg_m: f64,
    pub rest: RestSource,
    pub root_offset: RootOffset,
    pub joints_mapped: usize,
    pub joints_folded: usize,
    pub joints_dropped: usize,
}

impl ClipReading {
    /// One line: `map cc_base (24 mapped, 3 folded, 72 dropped), up y (detected), cm (detected,
    /// leg 0.93 m), rest: frame 212 (zero pose not standing), root OFFSET added`.
    pub fn describe(&self, map_name: &str) -> String {
        let rest = match self.rest {
            RestSource::ZeroPose => "zero-rotation pose".to_string(),
            RestSource::Frame(f) => format!("frame {f} (the zero-rotation pose does not stand)"),
        };
        let offset = match self.root_offset {
            RootOffset::Zero => "",
            RootOffset::Added => ", root OFFSET + channels",
            RootOffset::Replaced => ", root position = channels",
        };
        format!(
            "map {map_name} ({} mapped, {} folded, {} dropped), up {} ({}), units {} ({}, leg {:.2} m), rest: {rest}{offset}",
            self.joints_mapped,
            self.joints_folded,
            self.joints_dropped,
            self.up.value.name(),
            self.up.how(),
            self.units.value.name(),
            self.units.how(),
            self.leg_m,
        )
    }
}

/// Why a mapping cannot drive the body: one line each.
#[derive(Debug, thiserror::Error)]
pub enum DriveError {
    #[error("no clip joint drives the rig's root '{root}' (a clip needs its hips mapped)")]
    NoRoot { root: String },
    #[error("the map folds the rig's {side} leg away ({undriven} stay at rest); map the clip's thigh, knee and foot joints onto it")]
    LegFolded {
        side: &'static str,
        undriven: String,
    },
}

/// The body's two legs: the path from the root to the lowest joint at rest on each side (+x first).
fn leg_paths(skeleton: &Skeleton) -> Vec<(&'static str, Vec<usize>)> {
    let rest = skeleton.rest_world();
    let pos = |j: usize| Vector3::new(rest[j][(0, 3)], rest[j][(1, 3)], rest[j][(2, 3)]);
    let leaves = (0..skeleton.joint_count()).filter(|&j| skeleton.children(j).next().is_none());
    let mut out = Vec::new();
    for (side, sign) in [("left", 1.0f32), ("right", -1.0)] {
        let lowest = leaves
            .clone()
            .filter(|&j| pos(j).x * sign > 0.0)
            .min_by(|&a, &b| pos(a).y.total_cmp(&pos(b).y));
        if let Some(mut j) = lowest {
            let mut path = vec![j];
            while let Some(p) = skeleton.parents[j] {
                path.push(p);
                j = p;
            }
            path.reverse();
            out.push((side, path));
        }
    }
    out
}

/// Checks that a mapping drives the body: its root, and at least two joints of each leg.
pub fn check_drive(map: &JointMapping, skeleton: &Skeleton) -> Result<(), DriveError> {
    let driven: Vec<usize> = map.clip_to_rig().into_iter().flatten().collect();
    let root = (0..skeleton.joint_count())
        .find(|&j| skeleton.parents[j].is_none())
        .unwrap_or(0);
    if !driven.contains(&root) {
        return Err(DriveError::NoRoot {
            root: skeleton.joint_names[root].clone(),
        });
    }
    for (side, path) in leg_paths(skeleton) {
        let below_root = &path[1..];
        if below_root.iter().filter(|j| driven.contains(j)).count() < 2 {
            let undriven: Vec<&str> = below_root
                .iter()
                .filter(|j| !driven.contains(j))
                .map(|&j| skeleton.joint_names[j].as_str())
                .collect();
            return Err(DriveError::LegFolded {
                side,
                undriven: undriven.join(", "),
            });
        }
    }
    Ok(())
}

/// Retargets every frame of `clip` onto `skeleton` through the joint mapping (checked with
/// [`check_drive`] first), the body's `feet` put on the floor.
pub fn retarget(
    clip: &CaptureClip,
    map: &JointMapping,
    skeleton: &Skeleton,
    feet: &Feet,
    name: &str,
    axes: ClipAxes,
) -> Retargeted {
    let clip_to_rig = map.clip_to_rig();
    let mut clip_of = vec![None; skeleton.joint_count()];
    for (k, rig) in clip_to_rig.iter().enumerate() {
        if let Some(j) = rig {
            clip_of[*j] = Some(k);
        }
    }
    let body = BodyRest::new(skeleton);
    let up = Found::pick(axes.up, || {
        let (head, feet) = body.ends(&clip_of);
        detect_up(clip, head, &feet)
    });
    let clip = clip.stood_up(up.value);
    let rig = RestMatch::new(&clip, &clip_of, skeleton, &body);
    let units = Found::pick(axes.units, || Units::guess(rig.clip_hip_height));
    let root = 0;
    let clip_root = rig.clip_of[root];
    let mut translations = Vec::with_capacity(clip.frames.len());
    let mut rotations = Vec::with_capacity(clip.frames.len());
    for pose in &clip.frames {
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
    let floor_offset = ground(&mut animation, skeleton, feet);
    let (joints_mapped, joints_folded, joints_dropped) = map.counts();
    Retargeted {
        animation,
        scale: rig.scale as f32,
        floor_offset,
        map_name: map.map_name.clone(),
        reading: ClipReading {
            up,
            units,
            leg_m: rig.clip_hip_height * units.value.metres(),
            rest: rig.rest,
            root_offset: clip.root_offset,
            joints_mapped,
            joints_folded,
            joints_dropped,
        },
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

/// The body's rest pose as retargeting reads it.
struct BodyRest {
    pos: Vec<Vector3<f64>>,
    rotation: Vec<UnitQuaternion<f64>>,
    parents: Vec<Option<usize>>,
}

impl BodyRest {
    fn new(skeleton: &Skeleton) -> BodyRest {
        let rest_world = skeleton.rest_world();
        BodyRest {
            pos: rest_world
                .iter()
                .map(|m| m.fixed_view::<3, 1>(0, 3).into_owned().cast::<f64>())
                .collect(),
            rotation: rest_world
                .iter()
                .map(|m| {
                    UnitQuaternion::from_matrix(
                        &m.fixed_view::<3, 3>(0, 0).into_owned().cast::<f64>(),
                    )
                })
                .collect(),
            parents: skeleton.parents.clone(),
        }
    }

    /// The nearest driven body joints below `j` (through undriven ones), in joint order.
    fn driven_below(&self, j: usize, clip_of: &[Option<usize>]) -> Vec<usize> {
        (0..self.pos.len())
            .filter(|&d| clip_of[d].is_some() && self.driven_above(d, clip_of) == Some(j))
            .collect()
    }

    /// The nearest driven body joint above `j`.
    fn driven_above(&self, j: usize, clip_of: &[Option<usize>]) -> Option<usize> {
        let mut at = self.parents[j];
        while let Some(p) = at {
            if clip_of[p].is_some() {
                return Some(p);
            }
            at = self.parents[p];
        }
        None
    }

    /// The highest driven body joint (the head) and the lowest one on each side (the feet), at
    /// rest.
    fn end_joints(&self, clip_of: &[Option<usize>]) -> (usize, Vec<usize>) {
        let driven: Vec<usize> = (0..self.pos.len())
            .filter(|&j| clip_of[j].is_some())
            .collect();
        let by_height = |a: &&usize, b: &&usize| self.pos[**a].y.total_cmp(&self.pos[**b].y);
        let head = driven.iter().max_by(by_height).copied().unwrap_or(0);
        let feet: Vec<usize> = [1.0, -1.0]
            .iter()
            .filter_map(|s| {
                driven
                    .iter()
                    .filter(|&&j| self.pos[j].x * s > 0.0)
                    .min_by(by_height)
                    .copied()
            })
            .collect();
        (head, feet)
    }

    /// The clip joints driving [`BodyRest::end_joints`].
    fn ends(&self, clip_of: &[Option<usize>]) -> (usize, Vec<usize>) {
        let (head, feet) = self.end_joints(clip_of);
        let clip = |j: usize| clip_of[j].expect("driven");
        (clip(head), feet.into_iter().map(clip).collect())
    }

    /// Pairs of driven joints (above, below) along the bones of the legs and the spine that the
    /// body holds near vertical at rest (thighs, shins, the spine to the head): what "standing"
    /// compares. Arms are left out: a T-pose and an A-pose both stand.
    fn upright_bones(&self, clip_of: &[Option<usize>]) -> Vec<(usize, usize, f64)> {
        let (head, feet) = self.end_joints(clip_of);
        let on_paths = |j: usize| {
            feet.iter()
                .chain(std::iter::once(&head))
                .any(|&e| e == j || self.is_above(j, e))
        };
        (0..self.pos.len())
            .filter(|&j| clip_of[j].is_some() && on_paths(j))
            .filter_map(|j| {
                let a = self.driven_above(j, clip_of)?;
                let dir = (self.pos[j] - self.pos[a]).try_normalize(1e-9)?;
                (dir.y.abs() > 0.7).then_some((a, j, dir.y))
            })
            .collect()
    }

    /// The root's frame as two lines of driven joints (from, to): right hip joint to left hip
    /// joint, and root to head.
    fn pelvis_lines(&self, root: usize, clip_of: &[Option<usize>]) -> Vec<(usize, usize)> {
        let (head, feet) = self.end_joints(clip_of);
        let below = self.driven_below(root, clip_of);
        let hip_of = |foot: usize| {
            below
                .iter()
                .copied()
                .find(|&d| d == foot || self.is_above(d, foot))
        };
        let mut lines = Vec::new();
        if let [left, right] = feet.as_slice() {
            if let (Some(l), Some(r)) = (hip_of(*left), hip_of(*right)) {
                lines.push((r, l));
            }
        }
        lines.push((root, head));
        lines
    }

    /// Between the root and the head (the head included).
    fn on_spine(&self, j: usize, clip_of: &[Option<usize>]) -> bool {
        let (head, _) = self.end_joints(clip_of);
        self.parents[j].is_some() && (j == head || self.is_above(j, head))
    }

    fn is_above(&self, a: usize, j: usize) -> bool {
        let mut at = self.parents[j];
        while let Some(p) = at {
            if p == a {
                return true;
            }
            at = self.parents[p];
        }
        false
    }
}

/// Per body joint: the clip joint driving it and the rest fit.
struct RestMatch {
    clip_of: Vec<Option<usize>>,
    /// `G_rest⁻¹ · F` per body joint.
    correction: Vec<UnitQuaternion<f64>>,
    rest_world_rotation: Vec<UnitQuaternion<f64>>,
    scale: f64,
    /// The clip's hip height at rest (clip units).
    clip_hip_height: f64,
    rest: RestSource,
}

impl RestMatch {
    fn new(
        clip: &CaptureClip,
        clip_of: &[Option<usize>],
        skeleton: &Skeleton,
        body: &BodyRest,
    ) -> Self {
        let n = skeleton.joint_count();
        let upright = body.upright_bones(clip_of);
        // Mean departure from the body's rest along its vertical bones: 0 stands like the body.
        // (A clip bone of no length, like CMU's Spine1 → Neck, says nothing.)
        let lean = |pose: &dyn Fn(usize) -> Vector3<f64>| -> f64 {
            let leans: Vec<f64> = upright
                .iter()
                .filter_map(|&(a, b, body_y)| {
                    let d = pose(clip_of[b].expect("driven")) - pose(clip_of[a].expect("driven"));
                    d.try_normalize(1e-9).map(|d| (d.y - body_y).abs())
                })
                .collect();
            if leans.is_empty() {
                return 2.0;
            }
            leans.iter().sum::<f64>() / leans.len() as f64
        };
        // Within about 30° on average of the body's vertical bones: the zero pose stands.
        let zero_stands = lean(&|k| clip.zero_pose[k]) < 0.15;
        let (rest, rest_pose): (RestSource, Vec<JointWorld>) = if zero_stands {
            let r = clip.zero_pose_rotation;
            (
                RestSource::ZeroPose,
                clip.zero_pose.iter().map(|p| (*p, r)).collect(),
            )
        } else {
            let best = (0..clip.frames.len())
                .min_by(|&a, &b| {
                    lean(&|k| clip.frames[a][k].0).total_cmp(&lean(&|k| clip.frames[b][k].0))
                })
                .unwrap_or(0);
            (RestSource::Frame(best), clip.frames[best].clone())
        };
        let mut fit: Vec<UnitQuaternion<f64>> = Vec::with_capacity(n);
        let mut correction: Vec<UnitQuaternion<f64>> = Vec::with_capacity(n);
        for j in 0..n {
            // A zero pose that stands has its root frame aligned with the world, like the body's:
            // the root keeps it. A frame's root is fitted like any joint.
            let fitted = match clip_of[j] {
                Some(_) if skeleton.parents[j].is_none() && zero_stands => None,
                // A frame's root: the hip joints alone pin its pitch poorly (they lie nearly
                // side by side, and rigs place them differently forward or back), so the root
                // is fitted to the line between the hip joints and the line up to the head.
                Some(k) if skeleton.parents[j].is_none() => {
                    let clip_at = |b: usize| rest_pose[clip_of[b].expect("driven")].0;
                    let pairs: Vec<_> = body
                        .pelvis_lines(j, clip_of)
                        .into_iter()
                        .map(|(a, b)| {
                            let clip_a = if a == j { rest_pose[k].0 } else { clip_at(a) };
                            (body.pos[b] - body.pos[a], clip_at(b) - clip_a)
                        })
                        .filter(|(b, c)| b.norm() > 1e-6 && c.norm() > 1e-6)
                        .collect();
                    fit_rotation(&pairs)
                }
                // A frame's spine keeps its rest bend relative to the root: rigs curve the spine
                // differently at rest (Character Creator's waist leans back where the body's
                // stands straight), and the performer stands upright at the rest frame, so its
                // bones' directions there say more about the rig than about the pose.
                Some(_) if !zero_stands && body.on_spine(j, clip_of) => None,
                Some(k) => {
                    let pairs: Vec<_> = body
                        .driven_below(j, clip_of)
                        .into_iter()
                        .map(|d| {
                            let kd = clip_of[d].expect("driven");
                            (body.pos[d] - body.pos[j], rest_pose[kd].0 - rest_pose[k].0)
                        })
                        .filter(|(b, c)| b.norm() > 1e-6 && c.norm() > 1e-6)
                        .collect();
                    fit_rotation(&pairs)
                }
                None => None,
            };
            let inherited = skeleton.parents[j].map_or(UnitQuaternion::identity(), |p| fit[p]);
            let f = fitted.unwrap_or(inherited);
            fit.push(f);
            let g_rest = clip_of[j].map_or(UnitQuaternion::identity(), |k| rest_pose[k].1);
            correction.push(g_rest.inverse() * f);
        }
        let clip_pos: Vec<Vector3<f64>> = rest_pose.iter().map(|(p, _)| *p).collect();
        // A standing zero pose is measured as it stands (CMU clips keep the scale they always had);
        // a frame's bent knees and leaning spine are straightened first.
        let clip_hip_height = match rest {
            RestSource::ZeroPose => hip_height(&clip_pos, Some(clip_of)),
            RestSource::Frame(_) => straightened_hip_height(&clip_pos, clip_of, body),
        };
        let scale = hip_height(&body.pos, None) / clip_hip_height.max(1e-9);
        RestMatch {
            clip_of: clip_of.to_vec(),
            correction,
            rest_world_rotation: body.rotation.clone(),
            scale,
            clip_hip_height,
            rest,
        }
    }

    /// Local rotations of the body for one clip pose (world rotations per clip joint).
    fn local_rotations(
        &self,
        skeleton: &Skeleton,
        pose: &[JointWorld],
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

/// The clip's hip height with its bones laid along the body's rest bones: a frame's bent knees
/// and leaning spine do not shorten it. Bone lengths run between driven joints.
fn straightened_hip_height(
    clip_pos: &[Vector3<f64>],
    clip_of: &[Option<usize>],
    body: &BodyRest,
) -> f64 {
    let n = body.pos.len();
    let mut laid: Vec<Option<Vector3<f64>>> = vec![None; n];
    for j in 0..n {
        let Some(k) = clip_of[j] else { continue };
        laid[j] = Some(match body.driven_above(j, clip_of) {
            None => Vector3::zeros(),
            Some(a) => {
                let length = (clip_pos[k] - clip_pos[clip_of[a].expect("driven")]).norm();
                let dir = (body.pos[j] - body.pos[a])
                    .try_normalize(1e-9)
                    .unwrap_or_else(Vector3::zeros);
                laid[a].unwrap_or_else(Vector3::zeros) + dir * length
            }
        });
    }
    let root_y = laid
        .iter()
        .zip(&body.parents)
        .find_map(|(p, parent)| parent.is_none().then_some(*p).flatten())
        .map_or(0.0, |p| p.y);
    let lowest = laid
        .iter()
        .flatten()
        .map(|p| p.y)
        .fold(f64::INFINITY, f64::min);
    root_y - lowest
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
