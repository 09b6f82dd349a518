//! A motion-capture clip in world terms, whatever file format it came from, and what retargeting
//! must know about it that files rarely say: which way is up, what unit lengths are in, and where
//! its rest pose is.
//!
//! Up and units are read from the motion itself when not given: up is the axis the head sits
//! above the feet along (over the whole take), units the length unit that makes the performer's
//! leg a human leg. A BVH's zero-rotation pose is a T-pose for CMU exports but not for production
//! rigs (Character Creator bones lie along their own axes: with zero rotations the calf points up),
//! so the rest pose is either that zero pose, when it stands, or the take's most upright frame.

use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;

/// World position and world rotation of one clip joint.
pub type JointWorld = (Vector3<f64>, UnitQuaternion<f64>);

/// A motion-capture clip in world terms (clip units, the file's axes).
#[derive(Clone, Debug)]
pub struct CaptureClip {
    /// World position of every clip joint with all rotations zero (clip units), parents first.
    pub zero_pose: Vec<Vector3<f64>>,
    /// World rotation of every joint in that pose: identity as read, the turn to Y-up after
    /// [`CaptureClip::stood_up`].
    pub zero_pose_rotation: UnitQuaternion<f64>,
    /// Per frame, per clip joint: world position and world rotation.
    pub frames: Vec<Vec<JointWorld>>,
    /// Seconds between frames.
    pub frame_time: f64,
    /// How the root's OFFSET entered its position.
    pub root_offset: RootOffset,
}

/// How a file's root OFFSET relates to its position channels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RootOffset {
    /// The OFFSET is zero (CMU): nothing to decide.
    Zero,
    /// The channels are relative to the OFFSET (iClone, Character Creator): position = OFFSET + channels.
    Added,
    /// The channels already hold the position (they start at the OFFSET): position = channels.
    Replaced,
}

/// The world axis a clip's performer stands along.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum UpAxis {
    #[serde(rename = "x")]
    X,
    #[serde(rename = "y")]
    Y,
    #[serde(rename = "z")]
    Z,
    #[serde(rename = "-x")]
    NegX,
    #[serde(rename = "-y")]
    NegY,
    #[serde(rename = "-z")]
    NegZ,
}

impl UpAxis {
    pub const ALL: [UpAxis; 6] = [
        UpAxis::X,
        UpAxis::Y,
        UpAxis::Z,
        UpAxis::NegX,
        UpAxis::NegY,
        UpAxis::NegZ,
    ];

    pub fn name(self) -> &'static str {
        match self {
            UpAxis::X => "x",
            UpAxis::Y => "y",
            UpAxis::Z => "z",
            UpAxis::NegX => "-x",
            UpAxis::NegY => "-y",
            UpAxis::NegZ => "-z",
        }
    }

    pub fn parse(text: &str) -> Option<UpAxis> {
        let t = text.trim().to_ascii_lowercase();
        let t = t.strip_prefix('+').unwrap_or(&t);
        UpAxis::ALL.into_iter().find(|a| a.name() == t)
    }

    pub fn vector(self) -> Vector3<f64> {
        match self {
            UpAxis::X => Vector3::x(),
            UpAxis::Y => Vector3::y(),
            UpAxis::Z => Vector3::z(),
            UpAxis::NegX => -Vector3::x(),
            UpAxis::NegY => -Vector3::y(),
            UpAxis::NegZ => -Vector3::z(),
        }
    }

    /// The axis closest to a direction.
    fn nearest(v: &Vector3<f64>) -> UpAxis {
        UpAxis::ALL
            .into_iter()
            .max_by(|a, b| a.vector().dot(v).total_cmp(&b.vector().dot(v)))
            .expect("six axes")
    }

    /// The turn that stands this axis up along +Y (a quarter turn about X for Z-up, so a Z-up
    /// file's −Y forward becomes +Z, as Blender and Maya convert).
    pub fn to_y_up(self) -> UnitQuaternion<f64> {
        match self {
            UpAxis::Y => UnitQuaternion::identity(),
            UpAxis::NegY => {
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
            }
            other => UnitQuaternion::rotation_between(&other.vector(), &Vector3::y())
                .expect("not opposite to +Y"),
        }
    }
}

/// A length unit of motion files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Units {
    M,
    Cm,
    Mm,
    In,
    Ft,
    /// CMU's ASF unit (1/0.45 inch), kept by the cgspeed BVH conversions.
    Cmu,
}

impl Units {
    pub const ALL: [Units; 6] = [
        Units::M,
        Units::Cm,
        Units::Mm,
        Units::In,
        Units::Ft,
        Units::Cmu,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Units::M => "m",
            Units::Cm => "cm",
            Units::Mm => "mm",
            Units::In => "in",
            Units::Ft => "ft",
            Units::Cmu => "cmu",
        }
    }

    pub fn parse(text: &str) -> Option<Units> {
        let t = text.trim().to_ascii_lowercase();
        Units::ALL.into_iter().find(|u| u.name() == t)
    }

    /// Metres per unit.
    pub fn metres(self) -> f64 {
        match self {
            Units::M => 1.0,
            Units::Cm => 0.01,
            Units::Mm => 0.001,
            Units::In => 0.0254,
            Units::Ft => 0.3048,
            Units::Cmu => 0.0254 / 0.45,
        }
    }

    /// The unit that makes a leg of `length` units closest (in ratio) to a typical adult's 0.9 m.
    pub fn guess(leg_length: f64) -> Units {
        let off = |u: Units| (leg_length * u.metres() / 0.9).ln().abs();
        Units::ALL
            .into_iter()
            .min_by(|a, b| off(*a).total_cmp(&off(*b)))
            .expect("six units")
    }
}

/// What the user says about a clip where the file is silent (`--up`, `--units`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClipAxes {
    pub up: Option<UpAxis>,
    pub units: Option<Units>,
}

/// A value read from the file or motion, or given by the user.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Found<T> {
    pub value: T,
    /// True when given on the command line, false when detected.
    pub given: bool,
}

impl<T> Found<T> {
    pub fn pick(given: Option<T>, detect: impl FnOnce() -> T) -> Found<T> {
        match given {
            Some(value) => Found { value, given: true },
            None => Found {
                value: detect(),
                given: false,
            },
        }
    }

    pub fn how(&self) -> &'static str {
        if self.given {
            "given"
        } else {
            "detected"
        }
    }
}

/// The up axis of a clip: the axis nearest the head's mean direction from the feet over the take.
/// `head` and `feet` are clip joint indices.
pub fn detect_up(clip: &CaptureClip, head: usize, feet: &[usize]) -> UpAxis {
    let step = (clip.frames.len() / 200).max(1);
    let mut sum = Vector3::zeros();
    for pose in clip.frames.iter().step_by(step) {
        let low = feet.iter().map(|&f| pose[f].0).sum::<Vector3<f64>>() / feet.len().max(1) as f64;
        let v = pose[head].0 - low;
        if v.norm() > 1e-9 {
            sum += v.normalize();
        }
    }
    UpAxis::nearest(&sum)
}

impl CaptureClip {
    /// The clip turned so that `up` points along +Y: positions and rotations of every frame, and
    /// the zero pose.
    pub fn stood_up(&self, up: UpAxis) -> CaptureClip {
        let q = up.to_y_up();
        CaptureClip {
            zero_pose: self.zero_pose.iter().map(|p| q * p).collect(),
            zero_pose_rotation: q * self.zero_pose_rotation,
            frames: self
                .frames
                .iter()
                .map(|pose| pose.iter().map(|(p, r)| (q * p, q * r)).collect())
                .collect(),
            frame_time: self.frame_time,
            root_offset: self.root_offset,
        }
    }
}
